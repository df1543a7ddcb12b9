//! Configuration files (TOML, every key optional) and the broker settings the Pi service and
//! the dashboard share: the same `[mqtt]` section and the same environment variables, so one
//! environment points the Pi and its dashboards at the same broker and car.

use serde::Deserialize;
use serde::de::DeserializeOwned;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// Why a configuration was refused.
#[derive(Debug, Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("reading the configuration {path}: {source}")]
    Read {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The file is not valid TOML for this configuration (an unknown key, a wrong type).
    #[error("in the configuration {path}: {source}")]
    Parse {
        path: PathBuf,
        #[source]
        source: toml::de::Error,
    },
    /// An environment variable does not hold what its key needs.
    #[error("{variable}={value}: {expected}")]
    Environment {
        variable: &'static str,
        value: String,
        expected: &'static str,
    },
}

/// Reads a TOML configuration file (every key optional), or gives the defaults without one.
pub fn read_or_default<T: DeserializeOwned + Default>(
    path: Option<&Path>,
) -> Result<T, ConfigError> {
    let Some(path) = path else {
        return Ok(T::default());
    };
    let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
        path: path.to_owned(),
        source,
    })?;
    toml::from_str(&text).map_err(|source| ConfigError::Parse {
        path: path.to_owned(),
        source,
    })
}

/// Where the car's topics are: the broker and the topic root. The `[mqtt]` section of both
/// configurations.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BrokerConfig {
    pub host: String,
    pub port: u16,
    pub username: Option<String>,
    pub password: Option<String>,
    /// Set: the connection speaks TLS and the broker's certificate must chain to a
    /// certificate in this PEM file (the team's CA, or the Pi's own certificate pinned). The
    /// Pi's pit listener is TLS-only.
    pub tls_ca: Option<PathBuf>,
    /// The root of every topic: `<topic_prefix>/<car_id>/...`.
    pub topic_prefix: String,
}

impl Default for BrokerConfig {
    fn default() -> Self {
        Self {
            host: "127.0.0.1".into(),
            port: 1883,
            username: None,
            password: None,
            tls_ca: None,
            topic_prefix: "aer".into(),
        }
    }
}

impl BrokerConfig {
    /// Applies `AER_MQTT_HOST`, `AER_MQTT_PORT`, `AER_MQTT_USERNAME`, `AER_MQTT_PASSWORD`,
    /// `AER_MQTT_TLS_CA` and `AER_MQTT_PREFIX` from `env`.
    pub fn apply_env(&mut self, env: &impl Fn(&str) -> Option<String>) -> Result<(), ConfigError> {
        if let Some(v) = env("AER_MQTT_HOST") {
            self.host = v;
        }
        if let Some(v) = env("AER_MQTT_PORT") {
            self.port = v.parse().map_err(|_| ConfigError::Environment {
                variable: "AER_MQTT_PORT",
                value: v.clone(),
                expected: "a port number",
            })?;
        }
        if let Some(v) = env("AER_MQTT_USERNAME") {
            self.username = Some(v);
        }
        if let Some(v) = env("AER_MQTT_PASSWORD") {
            self.password = Some(v);
        }
        if let Some(v) = env("AER_MQTT_TLS_CA") {
            self.tls_ca = Some(PathBuf::from(v));
        }
        if let Some(v) = env("AER_MQTT_PREFIX") {
            self.topic_prefix = v;
        }
        Ok(())
    }

    /// The prefix of `car_id`'s topics: `<topic_prefix>/<car_id>`.
    pub fn car_prefix(&self, car_id: &str) -> String {
        aer::mqtt::car_prefix(&self.topic_prefix, car_id)
    }
}

/// Applies `AER_CAR_ID` from `env` to `car_id`.
pub fn apply_car_env(car_id: &mut String, env: &impl Fn(&str) -> Option<String>) {
    if let Some(v) = env("AER_CAR_ID") {
        *car_id = v;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_environment_overrides_the_broker_and_the_car() {
        let env = |key: &str| match key {
            "AER_CAR_ID" => Some("car7".into()),
            "AER_MQTT_PORT" => Some("1999".into()),
            "AER_MQTT_PREFIX" => Some("team/".into()),
            _ => None,
        };
        let mut broker = BrokerConfig::default();
        let mut car = "car1".to_owned();
        broker.apply_env(&env).unwrap();
        apply_car_env(&mut car, &env);
        assert_eq!(broker.port, 1999);
        assert_eq!(broker.car_prefix(&car), "team/car7", "no doubled slash");
        let bad = broker.apply_env(&|key: &str| (key == "AER_MQTT_PORT").then(|| "x".into()));
        assert!(matches!(bad, Err(ConfigError::Environment { .. })));
    }

    #[test]
    fn a_file_with_an_unknown_key_is_refused_with_its_name() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.toml");
        std::fs::write(&path, "hots = \"x\"\n").unwrap();
        let error = read_or_default::<BrokerConfig>(Some(&path)).unwrap_err();
        let text = error.to_string();
        assert!(text.contains("bad.toml") && text.contains("hots"), "{text}");
        assert_eq!(
            read_or_default::<BrokerConfig>(None).unwrap(),
            BrokerConfig::default()
        );
    }
}
