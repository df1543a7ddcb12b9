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

/// Every listener that is reachable from outside the Pi must require a username/password.
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
    }
    Ok(())
}

/// Starts the broker on a thread of its own (rumqttd's `start` blocks).
pub fn spawn(config: rumqttd::Config) -> Result<std::thread::JoinHandle<()>> {
    std::thread::Builder::new()
        .name("mqtt-broker".into())
        .spawn(move || {
            let mut broker = rumqttd::Broker::new(config);
            if let Err(error) = broker.start() {
                tracing::error!(%error, "embedded MQTT broker stopped");
            }
        })
        .context("starting the broker thread")
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

    #[test]
    fn a_network_listener_without_credentials_is_refused() {
        let open = DEFAULT_CONFIG.replace("127.0.0.1:1883", "0.0.0.0:1883");
        let config: rumqttd::Config = toml::from_str(&open).unwrap();
        let error = check(&config).unwrap_err().to_string();
        assert!(
            error.contains("0.0.0.0:1883") && error.contains("credentials"),
            "{error}"
        );
        let with_auth = open.replace(
            "dynamic_filters = true",
            "dynamic_filters = true\n    auth = { pit = \"secret\" }",
        );
        let config: rumqttd::Config = toml::from_str(&with_auth).unwrap();
        assert!(check(&config).is_ok());
    }
}
