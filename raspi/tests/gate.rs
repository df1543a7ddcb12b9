//! The broker's gate against clients that misbehave: spoofing the car's topics, taking the
//! service's client id, subscribing and never reading or reading too slowly, TLS on a network
//! listener; and MQTT 5 clients served with the same rules as 3.1.1.

use aer_host::reports::counters::Counters;
use aer_raspi::broker::{self, packet};
use aer_raspi::health::Health;
use aer_raspi::sink::mqtt as publish;
use rumqttc::{AsyncClient, ConnectReturnCode, ConnectionError, Event, MqttOptions, Packet, QoS};
use std::sync::Arc;
use std::time::Duration;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;
use tokio::sync::mpsc;
use tokio_util::sync::CancellationToken;

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("a free port")
}

struct Service {
    port: u16,
    counters: Arc<Counters>,
    health: Arc<Health>,
    publisher: publish::Publisher,
    broker_address: std::net::SocketAddr,
    broker_password: String,
    service_id: String,
    clients: Arc<broker::gate::Clients>,
}

/// The service's broker (the shipped configuration on a free port, `edit`ed) with its
/// publisher connected.
async fn service(edit: impl FnOnce(&mut broker::BrokerConfig)) -> Service {
    let port = free_port();
    let text = broker::DEFAULT_CONFIG.replace("127.0.0.1:1883", &format!("127.0.0.1:{port}"));
    let mut config = broker::parse(&text).expect("broker config");
    edit(&mut config);
    let counters = Arc::new(Counters::default());
    let health = Arc::new(Health::default());
    let broker = broker::start(config, counters.clone(), CancellationToken::new())
        .await
        .expect("broker");
    let (broker_address, broker_password) =
        (broker.gate.broker, broker.gate.broker_password.clone());
    let service_id = broker.service_id.clone();
    let clients = broker.clients.clone().expect("the gate started");
    let (publisher, driver) = publish::embedded(
        broker.link,
        broker.spares,
        10_000,
        "aer/car1".into(),
        counters.clone(),
        health.clone(),
    );
    let (up_tx, mut up) = tokio::sync::watch::channel(false);
    tokio::spawn(publish::drive(driver, up_tx));
    let _ = tokio::time::timeout(Duration::from_secs(10), up.wait_for(|u| *u)).await;
    Service {
        port,
        counters,
        health,
        publisher,
        broker_address,
        broker_password,
        service_id,
        clients,
    }
}

/// A rumqttc client subscribed to `filter`; every publish it receives (topic, payload) goes
/// to the channel. Returns once the subscription is acknowledged.
async fn subscriber(
    port: u16,
    id: &str,
    filter: &str,
) -> (AsyncClient, mpsc::UnboundedReceiver<(String, Vec<u8>)>) {
    let (client, mut events) = AsyncClient::new(MqttOptions::new(id, "127.0.0.1", port), 100);
    client
        .subscribe(filter, QoS::AtMostOnce)
        .await
        .expect("subscribe");
    let (tx, rx) = mpsc::unbounded_channel();
    let (subscribed_tx, subscribed) = tokio::sync::oneshot::channel();
    tokio::spawn(async move {
        let mut subscribed_tx = Some(subscribed_tx);
        while let Ok(event) = events.poll().await {
            match event {
                Event::Incoming(Packet::SubAck(_)) => {
                    if let Some(done) = subscribed_tx.take() {
                        let _ = done.send(());
                    }
                }
                Event::Incoming(Packet::Publish(p)) => {
                    let _ = tx.send((p.topic.to_string(), p.payload.to_vec()));
                }
                _ => {}
            }
        }
    });
    tokio::time::timeout(Duration::from_secs(10), subscribed)
        .await
        .expect("subscribed in time")
        .expect("alive");
    (client, rx)
}

/// The service publishes a marker on its metrics topic; waits (bounded) until `rx` has it.
async fn service_still_publishes(
    service: &Service,
    rx: &mut mpsc::UnboundedReceiver<(String, Vec<u8>)>,
    marker: &str,
) -> bool {
    let topic = "aer/car1/probe";
    tokio::time::timeout(Duration::from_secs(10), async {
        loop {
            service
                .publisher
                .publish_json(topic.trim_start_matches("aer/car1/"), &marker, false);
            service.publisher.flush();
            let deadline = tokio::time::Instant::now() + Duration::from_millis(200);
            while let Ok(Some((t, payload))) = tokio::time::timeout_at(deadline, rx.recv()).await {
                if t == topic && payload == format!("{marker:?}").into_bytes() {
                    return;
                }
            }
        }
    })
    .await
    .is_ok()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn no_client_can_publish_under_the_cars_topics() {
    let service = service(|_| {}).await;
    let (_watcher, mut seen) = subscriber(service.port, "watcher", "aer/#").await;
    // A spoofer publishes fake telemetry, a retained status, and a forged pit stream batch.
    for (topic, retain) in [
        ("aer/car1/telemetry", false),
        ("aer/car1/status", true),
        ("aer-pit/car1/stream", false),
    ] {
        let (spoofer, mut events) = AsyncClient::new(
            MqttOptions::new(
                format!("spoofer-{}", topic.replace('/', "-")),
                "127.0.0.1",
                service.port,
            ),
            10,
        );
        spoofer
            .publish(topic, QoS::AtLeastOnce, retain, b"{\"soc\": 100}".to_vec())
            .await
            .expect("queued");
        // The gate cuts the connection at the publish (MQTT 3.1.1 has no per-message refusal).
        let cut = tokio::time::timeout(Duration::from_secs(10), async {
            loop {
                match events.poll().await {
                    Err(_) => return true,
                    Ok(Event::Incoming(Packet::PubAck(_))) => return false,
                    Ok(_) => {}
                }
            }
        })
        .await
        .expect("answered in time");
        assert!(cut, "{topic}: the publish was not refused");
    }
    assert!(service.counters.snapshot().mqtt_refused >= 3);
    // Publishing elsewhere is fine (the pit crew's own topics).
    let (pit, mut events) =
        AsyncClient::new(MqttOptions::new("pit-notes", "127.0.0.1", service.port), 10);
    pit.publish("pit/notes", QoS::AtLeastOnce, false, b"tyres".to_vec())
        .await
        .expect("queued");
    let acked = tokio::time::timeout(Duration::from_secs(10), async {
        loop {
            if let Ok(Event::Incoming(Packet::PubAck(_))) = events.poll().await {
                return;
            }
        }
    })
    .await;
    assert!(acked.is_ok());
    // The watcher saw only the service: the service's probe arrives, the spoofs never did.
    assert!(service_still_publishes(&service, &mut seen, "after-spoof").await);
    while let Ok((topic, payload)) = seen.try_recv() {
        assert!(
            !payload.windows(11).any(|w| w == b"{\"soc\": 100"),
            "a spoofed message reached a subscriber on {topic}"
        );
    }
    // A new subscriber gets no spoofed retained status either.
    let (_late, mut late) = subscriber(service.port, "late", "aer/car1/status").await;
    assert!(
        tokio::time::timeout(Duration::from_millis(500), late.recv())
            .await
            .is_err(),
        "no retained status from a spoofer"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_services_client_ids_are_refused_and_its_link_survives_a_takeover() {
    let service = service(|_| {}).await;
    let (_watcher, mut seen) = subscriber(service.port, "watcher", "aer/#").await;
    // Through the gate: the service's ids are refused outright.
    let (_thief, mut events) = AsyncClient::new(
        MqttOptions::new(service.service_id.clone(), "127.0.0.1", service.port),
        10,
    );
    let refused = tokio::time::timeout(Duration::from_secs(10), events.poll())
        .await
        .expect("answered");
    assert!(
        matches!(
            refused,
            Err(ConnectionError::ConnectionRefused(
                ConnectReturnCode::BadClientId
            ))
        ),
        "{refused:?}"
    );
    assert!(service_still_publishes(&service, &mut seen, "after-refusal").await);
    // Straight at the broker (only possible with the gate's own password): the broker drops
    // the service's link for the newcomer, and the service carries on on a spare.
    let mut options = MqttOptions::new(
        service.service_id.clone(),
        service.broker_address.ip().to_string(),
        service.broker_address.port(),
    );
    options.set_credentials("aer-gate", service.broker_password.clone());
    let (_direct, mut direct_events) = AsyncClient::new(options, 10);
    tokio::spawn(async move { while direct_events.poll().await.is_ok() {} });
    // Wait (bounded) until the service has noticed and moved to a spare: under load the
    // broker may take a while to hand the id over.
    let problem = tokio::time::timeout(Duration::from_secs(60), async {
        loop {
            if let Some(problem) = service.health.mqtt.error() {
                return problem;
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    })
    .await
    .expect("the takeover is reported");
    assert!(problem.contains("spare"), "{problem}");
    assert!(service_still_publishes(&service, &mut seen, "after-takeover").await);
}

/// Connects to the gate as `id` with a raw CONNECT; the CONNACK's return code.
async fn connack_code(port: u16, id: &str) -> u8 {
    let mut stream = TcpStream::connect(("127.0.0.1", port)).await.expect("gate");
    let connect = packet::Connect {
        version: packet::Version::V311,
        client_id: id.into(),
        clean_session: true,
        keep_alive_s: 30,
        will: None,
        username: None,
        password: None,
    };
    stream.write_all(&connect.encode()).await.expect("CONNECT");
    let mut connack = [0u8; 4];
    tokio::time::timeout(Duration::from_secs(30), stream.read_exact(&mut connack))
        .await
        .expect("answered")
        .expect("CONNACK");
    assert_eq!(connack[0] >> 4, 2, "a CONNACK: {connack:?}");
    connack[3]
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_id_the_broker_did_not_acknowledge_is_never_offered_to_it_again() {
    // rumqttd 0.20 leaves a connection's will handler behind when the connection fails before
    // its CONNACK, and the next connection with that id poisons its lock: nobody could connect
    // any more. A stand-in broker that leaves the first CONNECT unanswered and acknowledges
    // the others, recording the client ids the gate offers it.
    let fake = tokio::net::TcpListener::bind("127.0.0.1:0")
        .await
        .expect("bind");
    let broker = fake.local_addr().expect("address");
    let (offered_tx, mut offered) = mpsc::unbounded_channel::<String>();
    tokio::spawn(async move {
        let mut open = Vec::new();
        for answer in [false, true, true] {
            let Ok((mut stream, _)) = fake.accept().await else {
                return;
            };
            let mut bytes = Vec::new();
            let connect = loop {
                let mut chunk = [0u8; 1024];
                match stream.read(&mut chunk).await {
                    Ok(n) if n > 0 => bytes.extend_from_slice(&chunk[..n]),
                    _ => return,
                }
                if let Ok(connect) = packet::Connect::parse(&bytes) {
                    break connect;
                }
            };
            let _ = offered_tx.send(connect.client_id);
            if answer {
                let _ = stream.write_all(&packet::connack(0)).await;
            }
            open.push(stream);
        }
        std::future::pending::<()>().await;
    });
    let port = free_port();
    let counters = Arc::new(Counters::default());
    let cancel = CancellationToken::new();
    broker::gate::start(
        broker::gate::Settings {
            listeners: vec![broker::gate::Listener {
                name: "test".into(),
                listen: ([127, 0, 0, 1], port).into(),
                auth: None,
                tls: None,
                newest_first: true,
            }],
            broker,
            broker_user: "aer-gate".into(),
            broker_password: "a-long-password".into(),
            protected: vec!["aer/".into(), "aer-pit/".into()],
            open: Vec::new(),
            reserved_ids: "aer-raspi".into(),
            max_clients: 8,
            stall_limit: Duration::from_secs(5),
            max_lag: Duration::from_secs(2),
            max_queue_bytes: 1 << 20,
            max_keep_alive_s: 60,
            connack_timeout: Duration::from_millis(300),
        },
        counters.clone(),
        cancel.clone(),
    )
    .await
    .expect("gate");
    // Unanswered: the client is told the server is unavailable, and the refusal is counted.
    assert_eq!(connack_code(port, "pit-laptop").await, 3);
    assert_eq!(offered.recv().await.as_deref(), Some("pit-laptop"));
    assert_eq!(counters.snapshot().mqtt_refused, 1);
    // The same client again: the broker is offered a fresh id, and the client gets in.
    assert_eq!(connack_code(port, "pit-laptop").await, 0);
    assert_eq!(offered.recv().await.as_deref(), Some("pit-laptop-gate0"));
    // Any other id is offered as it is.
    assert_eq!(connack_code(port, "dashboard").await, 0);
    assert_eq!(offered.recv().await.as_deref(), Some("dashboard"));
    cancel.cancel();
}

/// A client that connects, subscribes to everything and never reads again.
async fn idle_subscriber(port: u16, index: usize) -> Option<TcpStream> {
    subscribe_raw(port, &format!("idle-{index}"), 0, "aer/#").await
}

/// A 3.1.1 client with a 4 KiB receive buffer that connects, is accepted, and sends
/// SUBSCRIBE for `filter` (packet id 1, QoS 0) without waiting for the SUBACK: it reads only
/// what its caller reads.
async fn subscribe_raw(
    port: u16,
    client_id: &str,
    keep_alive_s: u16,
    filter: &str,
) -> Option<TcpStream> {
    let socket = tokio::net::TcpSocket::new_v4().ok()?;
    socket.set_recv_buffer_size(4096).ok()?;
    let mut stream = socket
        .connect(std::net::SocketAddr::from(([127, 0, 0, 1], port)))
        .await
        .ok()?;
    let connect = packet::Connect {
        version: packet::Version::V311,
        client_id: client_id.to_owned(),
        clean_session: true,
        keep_alive_s,
        will: None,
        username: None,
        password: None,
    };
    stream.write_all(&connect.encode()).await.ok()?;
    let mut connack = [0u8; 4];
    stream.read_exact(&mut connack).await.ok()?;
    if connack[3] != 0 {
        return None;
    }
    let mut body = vec![0u8, 1];
    body.extend_from_slice(&u16::try_from(filter.len()).ok()?.to_be_bytes());
    body.extend_from_slice(filter.as_bytes());
    body.push(0);
    stream
        .write_all(&packet::with_header(0x82, &body))
        .await
        .ok()?;
    Some(stream)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn subscribers_that_never_read_cannot_crowd_out_the_dashboards() {
    // Room for 8 clients (12 connections less the service's links), stalls noticed in 1 s.
    let service = service(|config| {
        config.broker.router.max_connections = 12;
        config.stall_limit = Duration::from_secs(1);
    })
    .await;
    let (flood_stop, flood) = tokio::sync::watch::channel(false);
    // The service keeps publishing (about 100 kB/s), as a car does.
    let publisher = service.publisher.clone();
    tokio::spawn(async move {
        let payload = "x".repeat(1_000);
        while !*flood.borrow() {
            for _ in 0..10 {
                publisher.publish_json("telemetry_flood", &payload, false);
            }
            publisher.flush();
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
    });
    let mut idle = Vec::new();
    for index in 0..20 {
        if let Some(stream) = idle_subscriber(service.port, index).await {
            idle.push(stream);
        }
    }
    assert!(!idle.is_empty());
    // A dashboard that reads: it gets in (a stalled client makes room) and gets data.
    let got_data = tokio::time::timeout(Duration::from_secs(30), async {
        loop {
            let (client, mut events) = AsyncClient::new(
                MqttOptions::new("dashboard", "127.0.0.1", service.port),
                100,
            );
            let _ = client.subscribe("aer/#", QoS::AtMostOnce).await;
            loop {
                match events.poll().await {
                    Ok(Event::Incoming(Packet::Publish(_))) => return,
                    Ok(_) => {}
                    Err(_) => break,
                }
            }
        }
    })
    .await;
    let _ = flood_stop.send(true);
    assert!(got_data.is_ok(), "the dashboard never got data");
    let counters = service.counters.snapshot();
    assert!(counters.mqtt_slow_clients > 0, "{counters:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn network_listeners_speak_tls() {
    let dir = tempfile::tempdir().expect("temp dir");
    let certified = rcgen::generate_simple_self_signed(vec!["localhost".into()]).expect("cert");
    let (cert, key) = (dir.path().join("cert.pem"), dir.path().join("key.pem"));
    std::fs::write(&cert, certified.cert.pem()).expect("cert");
    std::fs::write(&key, certified.signing_key.serialize_pem()).expect("key");
    let (cert_path, key_path) = (cert.clone(), key.clone());
    let service = service(move |config| {
        for listener in &mut config.listeners {
            listener.tls = Some(broker::tls::Files {
                cert: cert_path.clone(),
                key: key_path.clone(),
            });
        }
    })
    .await;
    // A TLS client that trusts the certificate is served.
    let mut roots = rustls::RootCertStore::empty();
    roots.add(certified.cert.der().clone()).expect("root");
    let config = rustls::ClientConfig::builder_with_provider(Arc::new(
        rustls::crypto::ring::default_provider(),
    ))
    .with_safe_default_protocol_versions()
    .expect("versions")
    .with_root_certificates(roots)
    .with_no_client_auth();
    let connector = tokio_rustls::TlsConnector::from(Arc::new(config));
    let tcp = TcpStream::connect(("127.0.0.1", service.port))
        .await
        .expect("tcp");
    let name = rustls::pki_types::ServerName::try_from("localhost").expect("name");
    let mut tls = connector.connect(name, tcp).await.expect("TLS handshake");
    let connect = packet::Connect {
        version: packet::Version::V311,
        client_id: "pit-laptop".into(),
        clean_session: true,
        keep_alive_s: 30,
        will: None,
        username: None,
        password: None,
    };
    tls.write_all(&connect.encode()).await.expect("connect");
    let mut connack = [0u8; 4];
    tls.read_exact(&mut connack).await.expect("connack");
    assert_eq!(connack, packet::connack(0), "accepted over TLS");
    // A plaintext client on the TLS listener is refused with "not authorised" (in the clear,
    // so it can say why), and never served.
    let mut plain = TcpStream::connect(("127.0.0.1", service.port))
        .await
        .expect("tcp");
    plain.write_all(&connect.encode()).await.expect("write");
    let mut answer = [0u8; 4];
    plain.read_exact(&mut answer).await.expect("an answer");
    assert_eq!(
        answer,
        packet::connack(5),
        "plaintext refused on a TLS listener"
    );
    let mut rest = [0u8; 1];
    assert_eq!(
        plain.read(&mut rest).await.expect("closed"),
        0,
        "then closed"
    );
}

/// Runs `command` to its end off the async workers (the broker runs on them).
async fn blocking_output(command: &mut std::process::Command) -> std::process::Output {
    let mut command = std::mem::replace(command, std::process::Command::new("true"));
    tokio::task::spawn_blocking(move || command.output().expect("the command runs"))
        .await
        .expect("join")
}

/// The venv's Python when it has paho-mqtt (`.ci/run` installs it; `AER_REQUIRE_PYTHON`
/// makes its absence a failure).
fn paho_python() -> Option<std::path::PathBuf> {
    let python = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../.venv/bin/python");
    let usable = std::process::Command::new(&python)
        .args(["-c", "import paho.mqtt"])
        .output()
        .is_ok_and(|o| o.status.success());
    if usable {
        return Some(python);
    }
    assert!(
        std::env::var_os("AER_REQUIRE_PYTHON").is_none(),
        "AER_REQUIRE_PYTHON is set but {} cannot import paho.mqtt",
        python.display()
    );
    eprintln!("SKIPPED: the paho-mqtt checks need .venv with tools/requirements.txt");
    None
}

/// A client of a version the gate does not serve (MQTT 5, MQTT 3.1) gets its protocol's
/// refusal at once, so it stops and says why instead of reconnecting for ever: mosquitto_sub
/// and paho-mqtt, as people use them. An MQTT 3.1.1 client of either make is served.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn mqtt_5_is_served_as_3_1_1_is_and_older_versions_are_told_so() {
    let service = service(|_| {}).await;
    let port = service.port.to_string();
    // MQTT 3.1: refused at CONNECT with the code its protocol defines, not by the timeout.
    let output = blocking_output(
        std::process::Command::new("mosquitto_sub")
            .args(["-h", "127.0.0.1", "-p", &port, "-V", "mqttv31"])
            .args(["-t", "aer/car1/status", "-C", "1", "-W", "20"]),
    )
    .await;
    let said = String::from_utf8_lossy(&output.stderr).to_lowercase();
    assert!(!output.status.success(), "3.1 served?");
    assert!(said.contains("protocol version"), "{said}");
    assert!(!said.contains("timed out"), "{said}");
    let refused = service.counters.snapshot().mqtt_refused;
    assert!(refused >= 1);

    // A retained message, which a served client gets at once: both versions get it.
    service
        .publisher
        .publish_json("probe", &serde_json::json!({"served": true}), true);
    service.publisher.flush();
    for version in ["mqttv5", "mqttv311"] {
        let output = blocking_output(
            std::process::Command::new("mosquitto_sub")
                .args(["-h", "127.0.0.1", "-p", &port, "-V", version])
                .args(["-t", "aer/car1/probe", "-C", "1", "-W", "20"]),
        )
        .await;
        assert!(output.status.success(), "{version} is served: {output:?}");
        assert!(String::from_utf8_lossy(&output.stdout).contains("served"));
    }
    // An MQTT 5 client's publish reaches a 3.1.1 subscriber (user properties dropped) ...
    let output = blocking_output(
        std::process::Command::new("mosquitto_pub")
            .args([
                "-h",
                "127.0.0.1",
                "-p",
                &port,
                "-V",
                "mqttv5",
                "-q",
                "1",
                "-r",
            ])
            .args(["-D", "publish", "user-property", "lap", "3"])
            .args(["-t", "pit/notes", "-m", "tyres cold"]),
    )
    .await;
    assert!(output.status.success(), "MQTT 5 publish: {output:?}");
    let output = blocking_output(
        std::process::Command::new("mosquitto_sub")
            .args(["-h", "127.0.0.1", "-p", &port, "-V", "mqttv311"])
            .args(["-t", "pit/notes", "-C", "1", "-W", "20"]),
    )
    .await;
    assert_eq!(String::from_utf8_lossy(&output.stdout).trim(), "tyres cold");
    // ... and under the car's topics it is refused as a 3.1.1 client's is.
    let _ = blocking_output(
        std::process::Command::new("mosquitto_pub")
            .args(["-h", "127.0.0.1", "-p", &port, "-V", "mqttv5"])
            .args(["-t", "aer/car1/telemetry", "-m", "{\"spoofed\":true}"]),
    )
    .await;
    // mosquitto_pub sends QoS 0 and leaves before the gate has read it: wait (bounded) for the
    // gate to refuse it and for every client to be gone.
    tokio::time::timeout(Duration::from_secs(20), async {
        while service.counters.snapshot().mqtt_refused < refused + 1
            || !service.clients.snapshot().is_empty()
        {
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
    })
    .await
    .expect("the spoofed publish refused, every client gone");
    assert_eq!(service.counters.snapshot().mqtt_refused, refused + 1);

    let Some(python) = paho_python() else {
        return;
    };
    // paho in each version: connects, subscribes (MQTT 5 with options the gate drops) and
    // gets the retained message.
    let script = r#"
import sys, threading
import paho.mqtt.client as mqtt
port, protocol = int(sys.argv[1]), {"5": mqtt.MQTTv5, "311": mqtt.MQTTv311}[sys.argv[2]]
got = threading.Event()
result = {}
def on_connect(client, userdata, flags, reason, properties=None):
    result["reason"] = str(reason)
    if protocol == mqtt.MQTTv5:
        client.subscribe("aer/car1/probe", options=mqtt.SubscribeOptions(qos=1, noLocal=True))
    else:
        client.subscribe("aer/car1/probe", qos=1)
def on_message(client, userdata, message):
    result["payload"] = message.payload.decode()
    got.set()
client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, protocol=protocol)
client.on_connect = on_connect
client.on_message = on_message
client.connect("127.0.0.1", port)
client.loop_start()
answered = got.wait(20)
client.disconnect()
client.loop_stop()
print("received" if answered else "silence", result.get("reason"), result.get("payload"))
"#;
    for protocol in ["5", "311"] {
        let output = blocking_output(
            std::process::Command::new(&python).args(["-c", script, &port, protocol]),
        )
        .await;
        let said = String::from_utf8_lossy(&output.stdout);
        assert!(
            said.starts_with("received Success"),
            "paho MQTT {protocol}: {said} {output:?}"
        );
        assert!(said.contains("served"), "paho MQTT {protocol}: {said}");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_that_cannot_keep_up_gets_the_newest_data_and_is_reported() {
    let service = network_service().await;
    let mut slow = raw_subscriber(service.port, "pit-slow", "aer/car1/lap/#").await;
    // 2,000 messages of 1 kB (2 MB) while the client reads nothing: more than its queue and
    // every buffer between the gate and it hold.
    let filler = "x".repeat(1000);
    let published = 2000u32;
    for seq in 0..published {
        service.publisher.publish_json(
            "lap/beacon",
            &serde_json::json!({"seq": seq, "pad": filler}),
            false,
        );
        if seq % 50 == 49 {
            service.publisher.flush();
        }
    }
    service.publisher.flush();
    // Wait (bounded) until the gate has read everything from the broker: the client's
    // backlog is then what it will get, the rest dropped.
    let dropped = tokio::time::timeout(Duration::from_secs(20), async {
        loop {
            let snapshot = service.clients.snapshot();
            if let Some((client, _)) = snapshot.iter().find(|(c, _)| c.client_id == "pit-slow")
                && client.dropped > 0
                && service.counters.snapshot().published >= u64::from(published)
            {
                return (client.clone(), snapshot);
            }
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
    })
    .await
    .expect("the gate drops for the slow client");
    let (client, snapshot) = dropped;
    assert_eq!(
        (client.listener.as_str(), client.protocol.as_str()),
        ("v4-loopback", "3.1.1")
    );
    assert!(client.queued_bytes <= 32 * 1024 + 1100, "{client:?}");
    let problem = aer_host::reports::status::clients_behind(&snapshot).expect("reported");
    assert!(problem.contains("`pit-slow` (v4-loopback)"), "{problem}");
    assert!(service.counters.snapshot().mqtt_client_dropped >= client.dropped);

    // Now it reads: what it gets is in order, ends with the newest, and misses what was
    // dropped (no ever-growing queue).
    let mut seqs = Vec::new();
    let mut buffer = Vec::new();
    while seqs.last() != Some(&(published - 1)) {
        let mut chunk = [0u8; 8192];
        let n = tokio::time::timeout(Duration::from_secs(20), slow.read(&mut chunk))
            .await
            .expect("data in time")
            .expect("read");
        assert!(n > 0, "the gate closed the slow client");
        buffer.extend_from_slice(&chunk[..n]);
        while let Ok(Some((kind, len))) = packet::frame(&buffer) {
            let body: Vec<u8> = buffer.drain(..len).collect();
            if kind == 3 {
                let text = String::from_utf8_lossy(&body);
                let seq = text
                    .split("\"seq\":")
                    .nth(1)
                    .map(|rest| {
                        rest.chars()
                            .take_while(char::is_ascii_digit)
                            .collect::<String>()
                    })
                    .and_then(|n| n.parse::<u32>().ok())
                    .expect("a beacon");
                seqs.push(seq);
            }
        }
    }
    assert!(seqs.windows(2).all(|w| w[0] < w[1]), "in order");
    assert!(
        (seqs.len() as u64) < u64::from(published),
        "{} of {published} arrived: nothing was dropped?",
        seqs.len()
    );
    assert!(
        seqs.len() as u64 + client.dropped <= u64::from(published),
        "what arrived and what was dropped are apart"
    );
}

/// The service with its loopback listener served as a network one is (newest data first for
/// a client behind), and a small backlog bound, so a client that reads nothing for a moment
/// is over it.
async fn network_service() -> Service {
    service(|config| {
        config.max_queue_bytes = 32 * 1024;
        config.listeners[0].newest_first = true;
    })
    .await
}

/// A 3.1.1 client with a small receive buffer, subscribed to `filter` (SUBACK read).
async fn raw_subscriber(port: u16, id: &str, filter: &str) -> TcpStream {
    let mut stream = subscribe_raw(port, id, 60, filter)
        .await
        .expect("connected, accepted and subscribed");
    let mut suback = [0u8; 5];
    stream.read_exact(&mut suback).await.expect("SUBACK");
    assert_eq!(suback[0] >> 4, 9, "SUBACK");
    stream
}

/// A pit whose link is full gets no more history until it drains: history takes only what
/// the radio has spare, and the gate never drops it as stale live data. Without that, a pit
/// that cannot take the history as fast as the Pi sends it would lose most of it here (the
/// gate holds 32 KiB for it, the history is 200 kB sent at 10 MB/s).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn history_waits_for_a_pit_whose_link_is_full_and_none_of_it_is_dropped() {
    use aer_host::link::pit_history::{Answer, Request, reply_topic};
    use aer_raspi::pit::history::{Ring, Settings, serve};

    let service = network_service().await;
    let batches = 200u32;
    let mut ring = Ring::new(1 << 20);
    for number in 0..batches {
        let mut message = vec![0u8; 1000];
        message[..4].copy_from_slice(&number.to_be_bytes());
        ring.push(number, u64::from(number) * 100_000, message.into());
    }
    let mut pit = raw_subscriber(
        service.port,
        "pit-hist",
        &reply_topic("aer/car1", "pit-hist"),
    )
    .await;
    let (requests, intake) = mpsc::channel(4);
    tokio::spawn(serve(
        service.publisher.clone(),
        Arc::new(std::sync::Mutex::new(ring)),
        service.counters.clone(),
        Settings {
            car_prefix: "aer/car1".into(),
            bytes_per_s: 10_000_000,
            clients: Some(service.clients.clone()),
        },
        intake,
        CancellationToken::new(),
    ));
    let request = Request {
        reply: "pit-hist".into(),
        from: 0,
        to: batches,
        since_us: 0,
    };
    requests
        .send(request.to_json())
        .await
        .expect("the history task");
    // The pit reads nothing until its link is full (the gate holds more than the history's
    // room for it), and nothing for half a second more: time for the whole history to go out
    // were it not held back (it takes 20 ms at this pace). Then it takes everything.
    tokio::time::timeout(Duration::from_secs(20), async {
        while service
            .clients
            .queued_for("pit-hist")
            .is_none_or(|queued| queued <= aer_raspi::pit::history::REQUESTER_ROOM)
        {
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
    })
    .await
    .expect("the pit's link fills");
    tokio::time::sleep(Duration::from_millis(500)).await;
    assert!(
        service.counters.snapshot().history_batches < u64::from(batches),
        "the history went on while the pit's link was full"
    );
    let (mut numbers, mut buffer) = (Vec::new(), Vec::new());
    let answer = loop {
        let mut chunk = [0u8; 8192];
        let n = tokio::time::timeout(Duration::from_secs(20), pit.read(&mut chunk))
            .await
            .expect("history in time")
            .expect("read");
        assert!(n > 0, "the gate closed the pit");
        buffer.extend_from_slice(&chunk[..n]);
        let mut answer = None;
        while let Ok(Some((kind, len))) = packet::frame(&buffer) {
            let publish: Vec<u8> = buffer.drain(..len).collect();
            if kind != 3 {
                continue;
            }
            // Fixed header (the type, then the length's bytes), topic, payload.
            let header = 2 + publish[1..].iter().take_while(|b| **b & 0x80 != 0).count();
            let topic_len = usize::from(u16::from_be_bytes([publish[header], publish[header + 1]]));
            let payload = &publish[header + 2 + topic_len..];
            match Answer::parse(payload) {
                Ok(done) => answer = Some(done),
                Err(_) => numbers.push(u32::from_be_bytes(payload[..4].try_into().expect("4"))),
            }
        }
        if let Some(answer) = answer {
            break answer;
        }
    };
    assert_eq!(answer.sent, batches);
    assert_eq!(
        numbers,
        (0..batches).collect::<Vec<_>>(),
        "every batch, in order"
    );
    let dropped = service
        .clients
        .snapshot()
        .into_iter()
        .find(|(client, _)| client.client_id == "pit-hist")
        .map(|(client, _)| client.dropped);
    assert_eq!(dropped, Some(0), "the gate dropped none of the history");
}
