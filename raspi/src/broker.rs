//! The embedded MQTT broker (rumqttd), on its own thread.

use anyhow::{Context, Result, bail};
use std::path::Path;

/// The broker configuration shipped in the repository.
pub const DEFAULT_CONFIG: &str = include_str!("../config/rumqttd.toml");

/// Reads a broker configuration (the shipped one when `path` is `None`) and checks it.
pub fn load(path: Option<&Path>) -> Result<rumqttd::Config> {
    let text = match path {
        Some(path) => std::fs::read_to_string(path)
            .with_context(|| format!("reading the broker configuration {}", path.display()))?,
        None => DEFAULT_CONFIG.to_owned(),
    };
    let config: rumqttd::Config = toml::from_str(&text).context("in the broker configuration")?;
    check(&config)?;
    Ok(config)
}

/// The password of the shipped configuration's commented-out network listeners.
const PLACEHOLDER_PASSWORD: &str = "change-me";

/// Every listener that is reachable from outside the Pi must require a username/password, and
/// not the shipped placeholder.
pub fn check(config: &rumqttd::Config) -> Result<()> {
    let listeners = [&config.v4, &config.v5, &config.ws]
        .into_iter()
        .flatten()
        .flat_map(|servers| servers.values());
    for server in listeners {
        let open = server
            .connections
            .auth
            .as_ref()
            .is_none_or(|auth| auth.is_empty());
        if !server.listen.ip().is_loopback() && open {
            bail!(
                "broker listener `{}` on {} is reachable from the network without credentials; \
                 add `connections.auth = {{ user = \"password\" }}` or listen on 127.0.0.1",
                server.name,
                server.listen
            );
        }
        let placeholder = server
            .connections
            .auth
            .iter()
            .flatten()
            .find(|(_, password)| password.as_str() == PLACEHOLDER_PASSWORD);
        if let Some((user, _)) = placeholder {
            bail!(
                "broker listener `{}`: user `{user}` still has the placeholder password \
                 `{PLACEHOLDER_PASSWORD}`; choose one",
                server.name
            );
        }
    }
    Ok(())
}

/// An in-process connection to the embedded broker: what the service publishes goes straight
/// into the broker's router, with no TCP connection and no system call per message.
pub struct Link {
    pub tx: rumqttd::local::LinkTx,
    pub rx: rumqttd::local::LinkRx,
}

/// Starts the broker on a thread of its own (rumqttd's `start` blocks), waits (up to 2 s) until
/// its listeners are bound and turns Nagle's algorithm off on them (see [`nodelay`]). Returns
/// an in-process link called `client_id` for the service's own publishes.
pub fn spawn(config: rumqttd::Config, client_id: &str) -> Result<Link> {
    let listeners = listeners(&config);
    let mut broker = rumqttd::Broker::new(config);
    let (tx, rx) = broker
        .link(client_id)
        .context("connecting to the embedded broker's router")?;
    std::thread::Builder::new()
        .name("mqtt-broker".into())
        .spawn(move || {
            if let Err(error) = broker.start() {
                tracing::error!(%error, "embedded MQTT broker stopped");
            }
        })
        .context("starting the broker thread")?;
    nodelay::wait_and_set(&listeners, std::time::Duration::from_secs(2));
    Ok(Link { tx, rx })
}

/// The TCP addresses the broker listens on.
pub fn listeners(config: &rumqttd::Config) -> Vec<std::net::SocketAddr> {
    [&config.v4, &config.v5, &config.ws]
        .into_iter()
        .flatten()
        .flat_map(|servers| servers.values())
        .map(|server| server.listen)
        .collect()
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
    pub fn wait_and_set(addresses: &[SocketAddr], patience: Duration) -> usize {
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
    pub fn set_on_listeners(addresses: &[SocketAddr]) -> usize {
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
    pub fn set_on_listeners(_: &[SocketAddr]) -> usize {
        0
    }

    /// The local address of `fd` if it is a listening TCP socket. An fd closed (or reused)
    /// since the directory was read fails these calls or is some other socket of this process,
    /// for which TCP_NODELAY is harmless.
    #[cfg(target_os = "linux")]
    fn listening_on(fd: i32) -> Option<SocketAddr> {
        let mut accepting: libc::c_int = 0;
        let mut len = std::mem::size_of::<libc::c_int>() as libc::socklen_t;
        // SAFETY: the pointers are to live locals of the sizes given.
        let listening = unsafe {
            libc::getsockopt(
                fd,
                libc::SOL_SOCKET,
                libc::SO_ACCEPTCONN,
                std::ptr::from_mut(&mut accepting).cast(),
                &mut len,
            )
        } == 0
            && accepting == 1;
        if !listening {
            return None;
        }
        // SAFETY: an all-zero sockaddr_storage is a valid value.
        let mut storage: libc::sockaddr_storage = unsafe { std::mem::zeroed() };
        let mut len = std::mem::size_of::<libc::sockaddr_storage>() as libc::socklen_t;
        // SAFETY: storage is large enough for any address and len says so.
        let named =
            unsafe { libc::getsockname(fd, std::ptr::from_mut(&mut storage).cast(), &mut len) }
                == 0;
        if !named {
            return None;
        }
        match libc::c_int::from(storage.ss_family) {
            libc::AF_INET => {
                // SAFETY: the family says the storage holds a sockaddr_in.
                let v4: libc::sockaddr_in = unsafe {
                    std::ptr::from_ref(&storage)
                        .cast::<libc::sockaddr_in>()
                        .read()
                };
                Some(SocketAddr::from((
                    v4.sin_addr.s_addr.to_ne_bytes(),
                    u16::from_be(v4.sin_port),
                )))
            }
            libc::AF_INET6 => {
                // SAFETY: the family says the storage holds a sockaddr_in6.
                let v6: libc::sockaddr_in6 = unsafe {
                    std::ptr::from_ref(&storage)
                        .cast::<libc::sockaddr_in6>()
                        .read()
                };
                Some(SocketAddr::from((
                    v6.sin6_addr.s6_addr,
                    u16::from_be(v6.sin6_port),
                )))
            }
            _ => None,
        }
    }

    #[cfg(target_os = "linux")]
    fn set_nodelay(fd: i32) -> bool {
        let on: libc::c_int = 1;
        // SAFETY: the pointer is to a live local of the size given.
        unsafe {
            libc::setsockopt(
                fd,
                libc::IPPROTO_TCP,
                libc::TCP_NODELAY,
                std::ptr::from_ref(&on).cast(),
                std::mem::size_of::<libc::c_int>() as libc::socklen_t,
            ) == 0
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shipped_broker_config_is_loopback_only_with_small_segments() {
        let config = load(None).unwrap();
        assert!(config.router.max_segment_size * config.router.max_segment_count <= 1 << 20);
        let v4 = config.v4.as_ref().unwrap();
        assert!(v4.values().all(|s| s.listen.ip().is_loopback()));
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
        let config: rumqttd::Config = toml::from_str(&open).unwrap();
        let error = check(&config).unwrap_err().to_string();
        assert!(
            error.contains("0.0.0.0:1883") && error.contains("credentials"),
            "{error}"
        );
        let with_auth = open.replacen(
            "    dynamic_filters = true",
            "    dynamic_filters = true\n    auth = { pit = \"secret\" }",
            1,
        );
        let config: rumqttd::Config = toml::from_str(&with_auth).unwrap();
        assert!(check(&config).is_ok());
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
    fn the_shipped_network_listeners_work_once_their_password_is_chosen() {
        for header in ["# [v4.2]", "# [ws.1]"] {
            let text = uncommented(header);
            let config: rumqttd::Config = toml::from_str(&text).unwrap();
            assert_eq!(listeners(&config).len(), 2, "{header}");
            let error = check(&config).unwrap_err().to_string();
            assert!(error.contains("placeholder"), "{error}");
            let chosen = text.replace("\"change-me\"", "\"Xq7-fast-laps\"");
            let config: rumqttd::Config = toml::from_str(&chosen).unwrap();
            assert!(check(&config).is_ok(), "{header}");
        }
    }
}
