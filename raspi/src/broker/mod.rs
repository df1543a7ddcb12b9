//! The embedded MQTT broker (rumqttd), on its own thread, behind the [`gate`]: the broker
//! listens only on loopback, on a port and with a password only the gate knows; the
//! listeners of the configuration file are the gate's.

mod client_queue;
pub mod gate;
mod mqtt5;
pub mod packet;
pub mod tls;

use anyhow::{Context, Result, bail};
use rumqttd::{ConnectionSettings, ServerSettings, TlsConfig};
use std::collections::HashMap;
use std::net::{Ipv4Addr, SocketAddr};
use std::path::Path;
use std::time::Duration;

/// The broker configuration shipped in the repository.
pub const DEFAULT_CONFIG: &str = include_str!("../../config/rumqttd.toml");

/// The password of the shipped configuration's commented-out network listeners.
const PLACEHOLDER_PASSWORD: &str = "change-me";
/// The shortest password a listener may have.
const MIN_PASSWORD: usize = 10;

/// A checked broker configuration: the broker's settings and the gate's listeners.
pub struct BrokerConfig {
    pub broker: rumqttd::Config,
    pub listeners: Vec<gate::Listener>,
    /// A client that takes nothing for this long is disconnected (5 s).
    pub stall_limit: Duration,
    /// Live messages that waited longer than this for a client are dropped (2 s).
    pub max_lag: Duration,
    /// The most the gate holds for one client (2 MiB).
    pub max_queue_bytes: usize,
}

/// Reads a broker configuration (the shipped one when `path` is `None`) and checks it.
pub fn load(path: Option<&Path>) -> Result<BrokerConfig> {
    let text = match path {
        Some(path) => std::fs::read_to_string(path)
            .with_context(|| format!("reading the broker configuration {}", path.display()))?,
        None => DEFAULT_CONFIG.to_owned(),
    };
    parse(&text)
}

/// Parses and checks a broker configuration's text.
pub fn parse(text: &str) -> Result<BrokerConfig> {
    let raw: toml::Table = toml::from_str(text).context("in the broker configuration")?;
    check_sections(&raw)?;
    let broker: rumqttd::Config = toml::from_str(text).context("in the broker configuration")?;
    let listeners = broker
        .v4
        .iter()
        .flat_map(|servers| servers.values())
        .map(listener)
        .collect::<Result<Vec<_>>>()?;
    if listeners.is_empty() {
        bail!("the broker configuration has no [v4.x] listener");
    }
    Ok(BrokerConfig {
        broker,
        listeners,
        stall_limit: Duration::from_secs(5),
        max_lag: CLIENT_MAX_LAG,
        max_queue_bytes: CLIENT_MAX_QUEUE,
    })
}

/// Sections the gate cannot guard are refused: rumqttd's own MQTT 5 and websocket listeners
/// (the gate serves MQTT 3.1.1 and 5 over TCP on the [v4.x] listeners), bridges and clusters (outside connections), and a console or
/// Prometheus endpoint off loopback (neither has credentials).
fn check_sections(raw: &toml::Table) -> Result<()> {
    for section in ["v5", "ws", "bridge", "cluster"] {
        if raw.contains_key(section) {
            bail!(
                "broker configuration: [{section}] is not supported: clients reach the broker \
                 through the service's gate, which serves MQTT 3.1.1 and 5 on the [v4.x] \
                 listeners"
            );
        }
    }
    let loopback = |value: Option<&toml::Value>| {
        value
            .and_then(toml::Value::as_str)
            .and_then(|listen| listen.parse::<SocketAddr>().ok())
            .is_some_and(|address| address.ip().is_loopback())
    };
    if let Some(console) = raw.get("console").and_then(toml::Value::as_table)
        && !loopback(console.get("listen"))
    {
        bail!("broker configuration: [console] must listen on 127.0.0.1: it has no credentials");
    }
    if let Some(prometheus) = raw.get("prometheus").and_then(toml::Value::as_table)
        && (prometheus.contains_key("port") || !loopback(prometheus.get("listen")))
    {
        bail!(
            "broker configuration: [prometheus] must set `listen` to a 127.0.0.1 address: \
                 it has no credentials"
        );
    }
    Ok(())
}

/// A listener of the file as the gate serves it; refused if it is reachable from the network
/// without credentials, or with a weak or placeholder password.
fn listener(server: &ServerSettings) -> Result<gate::Listener> {
    let auth = server
        .connections
        .auth
        .clone()
        .filter(|auth| !auth.is_empty());
    if !server.listen.ip().is_loopback() && auth.is_none() {
        bail!(
            "broker listener `{}` on {} is reachable from the network without credentials; \
             add `connections.auth = {{ user = \"password\" }}` or listen on 127.0.0.1",
            server.name,
            server.listen
        );
    }
    for (user, password) in auth.iter().flatten() {
        if password == PLACEHOLDER_PASSWORD {
            bail!(
                "broker listener `{}`: user `{user}` still has the placeholder password \
                 `{PLACEHOLDER_PASSWORD}`; choose one",
                server.name
            );
        }
        if password.chars().count() < MIN_PASSWORD {
            bail!(
                "broker listener `{}`: user `{user}`'s password is shorter than {MIN_PASSWORD} \
                 characters",
                server.name
            );
        }
    }
    let tls = match &server.tls {
        None => None,
        Some(TlsConfig::Rustls {
            capath: None,
            certpath,
            keypath,
        }) => Some(tls::Files {
            cert: certpath.into(),
            key: keypath.into(),
        }),
        Some(_) => bail!(
            "broker listener `{}`: TLS takes `certpath` and `keypath` (PEM) only; client \
             certificates (`capath`) and PKCS#12 are not supported",
            server.name
        ),
    };
    Ok(gate::Listener {
        name: server.name.clone(),
        listen: server.listen,
        auth,
        tls,
        newest_first: !server.listen.ip().is_loopback(),
    })
}

/// An in-process connection to the embedded broker: what the service publishes goes straight
/// into the broker's router, with no TCP connection and no system call per message.
pub struct Link {
    pub tx: rumqttd::local::LinkTx,
    pub rx: rumqttd::local::LinkRx,
}

/// The running broker.
pub struct Broker {
    /// The service's link, under an id nobody can guess.
    pub link: Link,
    /// That id.
    pub service_id: String,
    /// Links to switch to should the broker drop the service's.
    pub spares: Vec<Link>,
    /// The gate's view: the file's listeners and the broker's own.
    pub gate: gate::Settings,
    /// The clients the gate serves, once it is started.
    pub clients: Option<std::sync::Arc<gate::Clients>>,
}

/// Client ids the service uses; the gate refuses them to clients.
pub(crate) const SERVICE_IDS: &str = "aer-raspi";

/// The broker and its gate as the service runs them, with the topic roots `aer/` and
/// `aer-pit/` protected (tests and benchmarks; the service derives them from its
/// configuration).
pub async fn start(
    config: BrokerConfig,
    counters: std::sync::Arc<aer_host::reports::counters::Counters>,
    cancel: tokio_util::sync::CancellationToken,
) -> Result<Broker> {
    let protected = ["aer/".to_owned(), "aer-pit/".to_owned()];
    let open = [
        aer_host::link::pit_history::request_topic("aer/car1"),
        aer_host::link::marks::topic("aer/car1"),
    ];
    let mut broker = spawn(config, SERVICE_IDS, &protected, &open)?;
    broker.clients = Some(gate::start(broker.gate.clone(), counters, cancel).await?);
    Ok(broker)
}

/// Live messages older than this are dropped for a client that cannot keep up: it gets the
/// newest data (a pit fetches the rest from history) instead of an ever-growing delay.
const CLIENT_MAX_LAG: Duration = Duration::from_secs(2);

/// The most the gate holds for one client: 2 s of everything under `aer/car1/#` (about
/// 490 kB/s of JSON), beyond which its oldest live messages go.
const CLIENT_MAX_QUEUE: usize = 2 << 20;

/// Links kept in reserve for the service.
const SPARE_LINKS: usize = 2;

/// Starts the broker on a thread of its own (rumqttd's `start` blocks) with one listener, on
/// loopback, for the gate; waits (up to 2 s) until it is bound and turns Nagle's algorithm
/// off on it (see [`nodelay`]). `reserved_ids` prefixes the service's link ids, which the
/// gate refuses to clients; `protected` are the topic roots only the service publishes under,
/// but for the `open` topics.
pub fn spawn(
    config: BrokerConfig,
    reserved_ids: &str,
    protected: &[String],
    open: &[String],
) -> Result<Broker> {
    let BrokerConfig {
        mut broker,
        listeners,
        stall_limit,
        max_lag,
        max_queue_bytes,
    } = config;
    let internal = SocketAddr::from((Ipv4Addr::LOCALHOST, free_port()?));
    let (user, password) = ("aer-gate".to_owned(), secret()?);
    let template = broker
        .v4
        .iter()
        .flat_map(|servers| servers.values())
        .next()
        .map(|server| server.connections.clone());
    let connections = ConnectionSettings {
        auth: Some(HashMap::from([(user.clone(), password.clone())])),
        external_auth: None,
        ..template.context("no [v4.x] listener")?
    };
    broker.v4 = Some(HashMap::from([(
        "gate".to_owned(),
        ServerSettings {
            name: "v4-gate".into(),
            listen: internal,
            tls: None,
            next_connection_delay_ms: 1,
            connections,
        },
    )]));
    broker.console = None;
    let max_clients = broker
        .router
        .max_connections
        .saturating_sub(1 + SPARE_LINKS)
        .max(1);
    let mut rumqttd = rumqttd::Broker::new(broker);
    let link = |id: &str| -> Result<Link> {
        let (tx, rx) = rumqttd
            .link(id)
            .context("connecting to the embedded broker's router")?;
        Ok(Link { tx, rx })
    };
    let service_id = format!("{reserved_ids}-{}", secret()?);
    let service = link(&service_id)?;
    let spares = (0..SPARE_LINKS)
        .map(|_| link(&format!("{reserved_ids}-{}", secret()?)))
        .collect::<Result<Vec<_>>>()?;
    std::thread::Builder::new()
        .name("mqtt-broker".into())
        .spawn(move || {
            if let Err(error) = rumqttd.start() {
                tracing::error!(%error, "embedded MQTT broker stopped");
            }
        })
        .context("starting the broker thread")?;
    nodelay::wait_and_set(&[internal], Duration::from_secs(2));
    Ok(Broker {
        link: service,
        service_id,
        spares,
        gate: gate::Settings {
            listeners,
            broker: internal,
            broker_user: user,
            broker_password: password,
            protected: protected.to_vec(),
            open: open.to_vec(),
            reserved_ids: reserved_ids.to_owned(),
            max_clients,
            stall_limit,
            max_lag,
            max_queue_bytes,
            max_keep_alive_s: 60,
            connack_timeout: Duration::from_secs(10),
        },
        clients: None,
    })
}

/// A port free on loopback now (the broker binds it a moment later).
fn free_port() -> Result<u16> {
    let socket = std::net::TcpListener::bind((Ipv4Addr::LOCALHOST, 0))
        .context("finding a free port for the broker")?;
    Ok(socket.local_addr()?.port())
}

/// 128 random bits as hex, from the operating system.
fn secret() -> Result<String> {
    let mut bytes = [0u8; 16];
    getrandom::fill(&mut bytes).map_err(|e| anyhow::anyhow!("no randomness: {e}"))?;
    Ok(bytes.iter().map(|b| format!("{b:02x}")).collect())
}

/// The addresses clients connect to.
pub fn listeners(config: &BrokerConfig) -> Vec<SocketAddr> {
    config.listeners.iter().map(|l| l.listen).collect()
}

/// rumqttd never sets TCP_NODELAY on the connections it accepts, so Nagle's algorithm holds a
/// small publish back until the subscriber has acknowledged the previous one, which it delays
/// by up to 40 ms: the p99 latency to a subscriber was 35 ms. Linux copies TCP_NODELAY from a
/// listening socket to every socket it accepts, so setting it on the broker's listeners fixes
/// every connection. The listeners are found among this process's open files by their address.
pub mod nodelay {
    use std::net::SocketAddr;
    use std::time::{Duration, Instant};

    /// Sets TCP_NODELAY on the listening sockets of this process bound to `addresses`, retrying
    /// until all are found or `patience` runs out (the broker binds on its own thread). Returns
    /// how many were set.
    pub(crate) fn wait_and_set(addresses: &[SocketAddr], patience: Duration) -> usize {
        let deadline = Instant::now() + patience;
        loop {
            let set = set_on_listeners(addresses);
            if set >= addresses.len() || Instant::now() >= deadline {
                if set < addresses.len() {
                    tracing::warn!(
                        ?addresses,
                        set,
                        "not every broker listener is bound yet: subscribers there may see \
                         Nagle delays of up to 40 ms"
                    );
                }
                return set;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// One pass over this process's open files.
    #[cfg(target_os = "linux")]
    pub(crate) fn set_on_listeners(addresses: &[SocketAddr]) -> usize {
        let Ok(entries) = std::fs::read_dir("/proc/self/fd") else {
            return 0;
        };
        entries
            .filter_map(|entry| entry.ok()?.file_name().to_str()?.parse::<i32>().ok())
            .filter(|&fd| listening_on(fd).is_some_and(|local| addresses.contains(&local)))
            .filter(|&fd| set_nodelay(fd))
            .count()
    }

    /// Elsewhere the listeners keep the system's default.
    #[cfg(not(target_os = "linux"))]
    pub(crate) fn set_on_listeners(_: &[SocketAddr]) -> usize {
        0
    }

    /// Runs `f` on the socket `fd`. An fd closed (or reused) since the directory was read
    /// fails the calls `f` makes or is some other socket of this process, for which reading
    /// its state or setting TCP_NODELAY is harmless.
    #[cfg(target_os = "linux")]
    fn on_socket<T>(fd: i32, f: impl FnOnce(socket2::SockRef<'_>) -> Option<T>) -> Option<T> {
        if fd < 0 {
            return None;
        }
        // SAFETY: `fd` is not -1, and the borrow ends with this call; an fd no longer open
        // makes the socket calls fail with EBADF, which `f` turns into `None`.
        let fd = unsafe { std::os::fd::BorrowedFd::borrow_raw(fd) };
        f(socket2::SockRef::from(&fd))
    }

    /// The local address of `fd` if it is a listening TCP socket.
    #[cfg(target_os = "linux")]
    fn listening_on(fd: i32) -> Option<SocketAddr> {
        on_socket(fd, |socket| {
            if !socket.is_listener().ok()? {
                return None;
            }
            socket.local_addr().ok()?.as_socket()
        })
    }

    #[cfg(target_os = "linux")]
    fn set_nodelay(fd: i32) -> bool {
        on_socket(fd, |socket| socket.set_tcp_nodelay(true).ok()).is_some()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shipped_broker_config_is_loopback_only_with_small_segments() {
        let config = load(None).unwrap();
        let router = &config.broker.router;
        assert!(router.max_segment_size * router.max_segment_count <= 1 << 20);
        assert!(config.listeners.iter().all(|l| l.listen.ip().is_loopback()));
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn accepted_connections_have_nagle_off() {
        use std::net::{TcpListener, TcpStream};
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let other = TcpListener::bind("127.0.0.1:0").unwrap();
        let address = listener.local_addr().unwrap();
        assert_eq!(nodelay::set_on_listeners(&[address]), 1);
        let _client = TcpStream::connect(address).unwrap();
        let (accepted, _) = listener.accept().unwrap();
        assert!(accepted.nodelay().unwrap(), "inherited from the listener");
        // Only the listeners asked for.
        let _client = TcpStream::connect(other.local_addr().unwrap()).unwrap();
        let (accepted, _) = other.accept().unwrap();
        assert!(!accepted.nodelay().unwrap());
    }

    #[test]
    fn a_network_listener_without_credentials_is_refused() {
        let open = DEFAULT_CONFIG.replace("127.0.0.1:1883", "0.0.0.0:1883");
        let error = parse(&open).err().unwrap().to_string();
        assert!(
            error.contains("0.0.0.0:1883") && error.contains("credentials"),
            "{error}"
        );
        let with_auth = |password: &str| {
            open.replacen(
                "    dynamic_filters = true",
                &format!("    dynamic_filters = true\n    auth = {{ pit = \"{password}\" }}"),
                1,
            )
        };
        assert!(parse(&with_auth("Xq7-fast-laps")).is_ok());
        let weak = parse(&with_auth("x")).err().unwrap().to_string();
        assert!(weak.contains("shorter than"), "{weak}");
    }

    #[test]
    fn sections_the_gate_cannot_guard_are_refused() {
        let refused = |extra: &str| {
            parse(&format!("{DEFAULT_CONFIG}\n{extra}"))
                .err()
                .map(|e| e.to_string())
        };
        let console = refused("[console]\nlisten = \"0.0.0.0:3030\"\n").unwrap();
        assert!(console.contains("[console]"), "{console}");
        assert!(refused("[console]\nlisten = \"127.0.0.1:3030\"\n").is_none());
        let prometheus =
            refused("[prometheus]\nlisten = \"0.0.0.0:9042\"\ninterval = 1\n").unwrap();
        assert!(prometheus.contains("[prometheus]"), "{prometheus}");
        let ws =
            "[ws.1]\nname = \"ws\"\nlisten = \"127.0.0.1:8083\"\nnext_connection_delay_ms = 1\n";
        assert!(refused(ws).unwrap().contains("[ws]"));
        let bridge = "[bridge]\nname = \"b\"\naddr = \"example.org:1883\"\n";
        assert!(refused(bridge).unwrap().contains("[bridge]"));
    }

    /// The shipped file with the commented-out block that starts at `header` uncommented.
    fn uncommented(header: &str) -> String {
        let mut inside = false;
        let mut text = String::new();
        for line in DEFAULT_CONFIG.lines() {
            inside = (inside || line == header) && line.starts_with('#');
            let line = if inside {
                line.strip_prefix("# ").unwrap_or(line)
            } else {
                line
            };
            text.push_str(line);
            text.push('\n');
        }
        text
    }

    #[test]
    fn the_shipped_network_listener_works_once_its_password_is_chosen() {
        let text = uncommented("# [v4.2]");
        let error = parse(&text).err().unwrap().to_string();
        assert!(error.contains("placeholder"), "{error}");
        let chosen = text.replace("\"change-me\"", "\"Xq7-fast-laps\"");
        let config = parse(&chosen).unwrap();
        assert_eq!(listeners(&config).len(), 2);
        let pit = config
            .listeners
            .iter()
            .find(|l| l.name == "v4-pit")
            .unwrap();
        assert!(pit.tls.is_some(), "the pit listener speaks TLS");
    }
}
