//! End to end, with the service's own pipeline (`Pipeline`, as `serve` runs it): the bundled
//! session log -> ingest -> the embedded rumqttd broker -> a rumqttc subscriber and
//! `mosquitto_sub`; the local store and the raw log. Every packet must arrive at both
//! subscribers with the values the generated decoder reads from the log, and the store must
//! hold every row.

use aer::mqtt::{Sample, TELEMETRY, TelemetryRecord};
use aer_host::decode::decode_log;
use aer_host::reports::status::STATUS;
use aer_raspi::broker;
use aer_raspi::config::Config;
use aer_raspi::service::{Job, Pipeline};
use aer_raspi::source::replay::{ReplayOptions, replay};
use rumqttc::{AsyncClient, Event, MqttOptions, Packet, QoS};
use std::collections::HashMap;
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;
use tokio_util::sync::CancellationToken;

const SESSION: &str = include_str!("../data/session.log");

/// What the `mosquitto_sub -v` lines showed.
#[derive(Debug, Default)]
struct MosquittoSeen {
    vehicle_state_names: std::collections::BTreeSet<String>,
    pcc_state_names: std::collections::BTreeSet<String>,
    ccm_status_buses: std::collections::BTreeSet<String>,
    /// The first line with a number of more than 9 decimals.
    noisy: Option<String>,
}

impl MosquittoSeen {
    fn read(&mut self, line: &str) {
        let Some((topic, payload)) = line.split_once(' ') else {
            return;
        };
        let Ok(json) = serde_json::from_str::<serde_json::Value>(payload) else {
            return;
        };
        let text = |key: &str| json[key].as_str().map(str::to_owned);
        match topic {
            "aer/car1/telemetry" => self.vehicle_state_names.extend(text("vehicle_state_label")),
            "aer/car1/can/pcc_status" => self.pcc_state_names.extend(text("pcc_state_label")),
            "aer/car1/can/ccm_status" => self.ccm_status_buses.extend(text("bus")),
            _ => {}
        }
        // Signal values are written to their scaling's resolution; the status topic's
        // measured rates are plain floats and not judged here.
        let signals = topic == "aer/car1/telemetry" || topic.starts_with("aer/car1/can/");
        let noisy = signals
            && payload
                .split(|c: char| !c.is_ascii_digit() && c != '.')
                .any(|number| {
                    number
                        .split_once('.')
                        .is_some_and(|(_, decimals)| decimals.len() > 9)
                });
        if noisy && self.noisy.is_none() {
            self.noisy = Some(line.to_owned());
        }
    }
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("a free port")
}

/// The service's configuration in `dir`: the repository's broker config on `port`, with
/// segments large enough to hold a replay run flat out for a subscriber on a busy machine
/// (the Pi's config is sized for 100 packets/s); the store and the raw log in `dir`.
fn config(dir: &Path, port: u16) -> Config {
    let broker_config = dir.join("rumqttd.toml");
    let text = broker::DEFAULT_CONFIG
        .replace("127.0.0.1:1883", &format!("127.0.0.1:{port}"))
        .replace("max_segment_size = 262144", "max_segment_size = 67108864");
    std::fs::write(&broker_config, text).expect("broker config");
    let mut config = Config::default();
    config.broker.config = Some(broker_config);
    // The replay runs flat out, hundreds of times the car's rate: a publish queue that holds
    // the whole session, so no message is dropped for want of room (at the car's rate the
    // shipped 10,000 holds seconds; a full queue drops and counts, as publish_dropped).
    config.broker.queue = 100_000;
    config.store.path = dir.join("store.sqlite");
    config.raw_log.dir = dir.join("raw");
    config
}

/// The regular DBC frames in the log: every frame but the telemetry's ISO-TP and flow control.
fn can_frames() -> u64 {
    decode_log(SESSION).counters.snapshot().messages
}

/// What the generated decoder reads from the log, by sequence number.
fn expected_packets() -> HashMap<u16, (u64, aer::telemetry::Telemetry)> {
    let decoded = decode_log(SESSION);
    assert_eq!(
        decoded.counters.snapshot().bad_lines,
        0,
        "the bundled log is clean"
    );
    decoded
        .packets
        .into_iter()
        .map(|(ts_us, header, telemetry)| (header.sequence, (ts_us, telemetry)))
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_packet_reaches_both_subscribers_and_the_store() {
    let expected = expected_packets();
    assert_eq!(expected.len(), 4_500, "45 s at 100 Hz");

    // The pipeline up, its source not yet started: the broker listens, the topics'
    // descriptions are retained.
    let dir = tempfile::tempdir().expect("temp dir");
    let port = free_port();
    let mut pipeline = Pipeline::start(config(dir.path(), port), Job::Fed)
        .await
        .expect("the pipeline starts");
    assert_eq!(pipeline.mqtt_address(), format!("127.0.0.1:{port}"));
    let counters = pipeline.counters();
    let input = pipeline.input().expect("a fed pipeline's input");

    // rumqttc subscriber, subscribed (SubAck seen) before anything is sent.
    let mut options = MqttOptions::new("e2e-subscriber", "127.0.0.1", port);
    options.set_max_packet_size(64 * 1024, 64 * 1024);
    let (subscriber, mut events) = AsyncClient::new(options, 100);
    subscriber
        .subscribe("aer/#", QoS::AtMostOnce)
        .await
        .expect("subscribe");
    loop {
        match tokio::time::timeout(Duration::from_secs(10), events.poll()).await {
            Ok(Ok(Event::Incoming(Packet::SubAck(_)))) => break,
            Ok(Ok(_)) => {}
            Ok(Err(_)) => {} // broker still starting: the client retries
            Err(_) => panic!("no SubAck from the embedded broker"),
        }
    }
    // Every packet and CAN frame, and a status published after the traffic (it names the
    // schema the firmware sends).
    let collector = tokio::spawn(async move {
        let mut telemetry = Vec::new();
        let mut can = 0usize;
        let mut status_after_traffic = false;
        while telemetry.len() < 4_500 || (can as u64) < can_frames() || !status_after_traffic {
            match tokio::time::timeout(Duration::from_secs(20), events.poll()).await {
                Ok(Ok(Event::Incoming(Packet::Publish(p)))) => {
                    if p.topic == "aer/car1/telemetry" {
                        telemetry.push(p.payload.to_vec());
                    } else if p.topic.starts_with("aer/car1/can/") {
                        can += 1;
                    } else if p.topic == "aer/car1/status" && telemetry.len() == 4_500 {
                        status_after_traffic |= STATUS
                            .decode(&p.payload)
                            .is_ok_and(|s| s.fingerprint_match == Some(true));
                    }
                }
                Ok(_) => {}
                Err(_) => break,
            }
        }
        (telemetry, can)
    });

    // mosquitto_sub, confirmed subscribed by its first message (a retained topic description
    // or status, or the metrics): nothing has been sent yet.
    let mut mosquitto = Command::new("mosquitto_sub")
        .args([
            "-h",
            "127.0.0.1",
            "-p",
            &port.to_string(),
            "-t",
            "aer/#",
            "-v",
        ])
        .stdout(Stdio::piped())
        .spawn()
        .expect("mosquitto_sub (Debian package mosquitto-clients; .ci/run installs it)");
    let mut lines = BufReader::new(mosquitto.stdout.take().expect("stdout")).lines();
    let (first, lines) = tokio::task::spawn_blocking(move || (lines.next(), lines))
        .await
        .expect("reader");
    let first = first.expect("mosquitto_sub ended").expect("a line");
    assert!(first.starts_with("aer/car1/"), "{first}");
    let mosquitto_reader = std::thread::spawn(move || {
        let mut telemetry = 0usize;
        let mut seen = MosquittoSeen::default();
        for line in lines {
            let Ok(line) = line else { break };
            seen.read(&line);
            if line.starts_with("aer/car1/telemetry ") {
                telemetry += 1;
                if telemetry == 4_500 {
                    break;
                }
            }
        }
        (telemetry, seen)
    });

    // The session, flat out, through the service's own replay source; the input stays open
    // (the pipeline running) until the checks below are done.
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let running = tokio::spawn(pipeline.run(async {
        let _ = stopped.await;
    }));
    let stats = replay(
        SESSION.as_bytes(),
        input.clone(),
        &counters,
        ReplayOptions::FAST,
        &CancellationToken::new(),
    )
    .await;
    assert_eq!(stats.frames, SESSION.lines().count() as u64);

    let (telemetry, can) = collector.await.expect("collector");
    assert_eq!(telemetry.len(), 4_500, "rumqttc subscriber: every packet");
    assert_eq!(
        can as u64,
        can_frames(),
        "rumqttc subscriber: every CAN frame"
    );
    // The status is retained: a subscriber that comes later still gets it.
    let late = Command::new("mosquitto_sub")
        .args(["-h", "127.0.0.1", "-p", &port.to_string()])
        .args(["-t", "aer/car1/status", "-C", "1", "-W", "10"])
        .output()
        .expect("mosquitto_sub");
    let status = STATUS.decode(&late.stdout).expect("a retained status");
    assert_eq!(status.fingerprint_match, Some(true));
    assert_eq!(status.car_id, "car1");

    // The source ends: the pipeline writes what it holds and stops.
    drop(input);
    let snapshot = running
        .await
        .expect("the pipeline's task")
        .expect("the pipeline stops cleanly");
    drop(stop);
    assert_eq!(snapshot.packets, 4_500);
    assert_eq!(snapshot.messages, can_frames());
    assert_eq!(snapshot.publish_dropped, 0, "{snapshot:?}");
    assert_eq!(snapshot.stored, 4_500 + can_frames());
    assert_eq!(
        snapshot.raw_frames, stats.frames,
        "the raw log keeps every frame"
    );
    assert_eq!(snapshot.raw_dropped, 0);

    for payload in &telemetry {
        let sample: Sample<TelemetryRecord> = TELEMETRY.decode(payload).expect("typed payload");
        let (ts_us, values) = expected
            .get(&sample.value.header.sequence)
            .expect("known sequence");
        assert_eq!(
            sample.value.telemetry, *values,
            "packet {}",
            sample.value.header.sequence
        );
        assert!((sample.ts - *ts_us as f64 / 1e6).abs() < 1e-6);
    }
    let (seen, what) =
        tokio::task::spawn_blocking(move || mosquitto_reader.join().expect("reader"))
            .await
            .expect("join");
    let _ = mosquitto.kill();
    let _ = mosquitto.wait();
    assert_eq!(seen, 4_500, "mosquitto_sub: every packet");
    // What people read with mosquitto_sub: names, not only numbers; no float noise; the bus.
    assert_eq!(what.noisy, None, "a number written past its resolution");
    assert!(what.vehicle_state_names.contains("DRIVING"), "{what:?}");
    assert!(what.pcc_state_names.contains("ONLINE"), "{what:?}");
    assert_eq!(
        what.ccm_status_buses,
        ["can0".to_owned(), "can1".to_owned()].into(),
        "CCM_Status on both buses, told apart"
    );

    // The store holds every row, with the decoded values, and the session it ran as.
    let path = dir.path().join("store.sqlite");
    let db = rusqlite::Connection::open(&path).expect("reopen");
    let rows: i64 = db
        .query_row("SELECT count(*) FROM telemetry", [], |r| r.get(0))
        .expect("count");
    assert_eq!(rows, 4_500);
    let (soc, speed): (f64, f64) = db
        .query_row(
            "SELECT soc, motor_speed FROM telemetry WHERE sequence = 4000",
            [],
            |r| Ok((r.get(0)?, r.get(1)?)),
        )
        .expect("row");
    let (_, at_4000) = expected.get(&4000).expect("packet 4000");
    assert_eq!(soc as f32, at_4000.soc);
    assert_eq!(speed as f32, at_4000.motor_speed);
    let can_rows: i64 = aer::tables::TABLES[1..]
        .iter()
        .map(|t| {
            db.query_row(&format!("SELECT count(*) FROM \"{}\"", t.name), [], |r| {
                r.get::<_, i64>(0)
            })
            .expect("count")
        })
        .sum();
    assert_eq!(can_rows as u64, can_frames());
    let source: String = db
        .query_row("SELECT source FROM sessions", [], |r| r.get(0))
        .expect("one session");
    assert_eq!(source, "fed");
}
