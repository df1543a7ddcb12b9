//! The dashboard's configuration: one TOML file (every key optional), then environment
//! overrides. The `[mqtt]` section and its variables are the Pi service's ([`BrokerConfig`]),
//! so one environment serves both.

use aer_host::config::{BrokerConfig, apply_car_env, read_or_default};
use anyhow::{Result, bail};
use serde::Deserialize;
use std::path::Path;
use std::time::Duration;

/// Everything the dashboard reads from its configuration.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Config {
    /// The car whose topics are shown: `<topic_prefix>/<car_id>/...`.
    pub car_id: String,
    /// Where the telemetry comes from (the Pi service's `[mqtt]` section).
    pub mqtt: BrokerConfig,
    pub link: LinkConfig,
    pub display: DisplayConfig,
    pub tune: TuneConfig,
}

/// How the Tune page reaches the CCM's calibration.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TuneConfig {
    /// The Pi's XCP gateway (`host:port`).
    pub gateway: String,
    /// The team's XCP secret (64 hex digits); without it calibration stays locked.
    pub secret_file: Option<std::path::PathBuf>,
    /// How long one command may wait for its answer (ms).
    pub timeout_ms: u64,
}

impl Default for TuneConfig {
    fn default() -> Self {
        Self {
            gateway: "127.0.0.1:5555".into(),
            secret_file: None,
            timeout_ms: 2000,
        }
    }
}

/// How the dashboard reads the car.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LinkConfig {
    /// What it subscribes to for telemetry and CAN.
    pub stream: StreamFormat,
    /// With the compact stream, how far back a pit that joins mid-session asks the Pi for
    /// what it missed (s; 0: nothing). Gaps after a dropout are always asked for.
    pub join_history_s: u64,
}

/// The form telemetry and CAN arrive in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum StreamFormat {
    /// The Pi's compact stream (`aer-pit/<car>/stream`): every frame and packet, batched and
    /// compressed, about 58 kbit/s for the bundled session. Fits a long-range radio.
    #[default]
    Compact,
    /// The JSON topics, one message per packet and frame (about 3.9 Mbit/s with every CAN
    /// topic): fine on loopback and Wi-Fi, or against a broker without the stream.
    Json,
}

impl Default for LinkConfig {
    fn default() -> Self {
        Self {
            stream: StreamFormat::Compact,
            join_history_s: 1800,
        }
    }
}

/// What the screens show and how.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DisplayConfig {
    /// The view at start-up.
    pub view: View,
    /// Fill the screen (the car's display) instead of opening a window.
    pub fullscreen: bool,
    /// Telemetry older than this is marked stale (ms); by default the schema's
    /// `Telemetry::TIMEOUT_MS`. (CAN messages go stale after their own generated limits.)
    pub stale_after_ms: Option<u64>,
    /// Length of the lap; when set, a lap ends every time the car has covered it (distance
    /// from the motor speed). Laps can always be marked by hand (key `L`).
    pub lap_length_m: Option<f64>,
    /// Telemetry fields plotted in the pit view at start-up (click a field to add or remove it).
    pub plots: Vec<String>,
    /// Seconds of history the pit view's plots show (30-60 s).
    pub plot_window_s: f64,
    /// CAN messages (DBC names) the pit view shows at start-up, straight from the Pi's CAN
    /// topics (click a message's name to show or hide it).
    pub can_messages: Vec<String>,
}

/// The two screens.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum View {
    /// Full screen on the car's display: what the driver needs at a glance.
    Driver,
    /// A laptop on the Pi's network: every field, plots, fault history, link health.
    Pit,
    /// The pit's calibration page: every parameter of the CCM through the Pi's XCP gateway.
    Tune,
}

impl Default for Config {
    fn default() -> Self {
        Self {
            car_id: "car1".into(),
            mqtt: BrokerConfig::default(),
            link: LinkConfig::default(),
            display: DisplayConfig::default(),
            tune: TuneConfig::default(),
        }
    }
}

impl Default for DisplayConfig {
    fn default() -> Self {
        Self {
            view: View::Driver,
            fullscreen: false,
            stale_after_ms: None,
            lap_length_m: None,
            plots: vec![
                "motor_speed".into(),
                "pack_current".into(),
                "apps_travel".into(),
            ],
            plot_window_s: 60.0,
            can_messages: Vec::new(),
        }
    }
}

impl Config {
    /// Reads `path` (if given), applies the environment overrides from `env`, and checks the
    /// result.
    pub fn load(path: Option<&Path>, env: impl Fn(&str) -> Option<String>) -> Result<Self> {
        let mut config: Self = read_or_default(path)?;
        apply_car_env(&mut config.car_id, &env);
        config.mqtt.apply_env(&env)?;
        config.check()?;
        Ok(config)
    }

    fn check(&self) -> Result<()> {
        for name in &self.display.plots {
            if !aer::telemetry::Telemetry::FIELDS
                .iter()
                .any(|f| f.name == name)
            {
                bail!(
                    "display.plots: `{name}` is not a telemetry field (see schema/telemetry.yaml)"
                );
            }
        }
        for name in &self.display.can_messages {
            if !aer::can::MESSAGES.iter().any(|m| m.name == name) {
                bail!(
                    "display.can_messages: `{name}` is not a message of the CAN database (see \
                     schema/aer.dbc)"
                );
            }
        }
        if self.display.stale_after_ms == Some(0) {
            bail!("display.stale_after_ms must be at least 1 ms");
        }
        if !(1.0..=600.0).contains(&self.display.plot_window_s) {
            bail!("display.plot_window_s must be between 1 and 600 s");
        }
        if self
            .display
            .lap_length_m
            .is_some_and(|m| !(m > 0.0 && m.is_finite()))
        {
            bail!("display.lap_length_m must be a positive distance");
        }
        if self.tune.gateway.parse::<std::net::SocketAddr>().is_err() {
            bail!(
                "tune.gateway `{}` is not an address and port (such as 127.0.0.1:5555)",
                self.tune.gateway
            );
        }
        if self.tune.timeout_ms == 0 {
            bail!("tune.timeout_ms must be at least 1 ms");
        }
        if self.mqtt.username.is_some() != self.mqtt.password.is_some() {
            bail!("mqtt.username and mqtt.password go together");
        }
        Ok(())
    }

    /// Topic prefix of this car: `<prefix>/<car_id>`.
    pub fn topic_prefix(&self) -> String {
        aer::mqtt::car_prefix(&self.mqtt.topic_prefix, &self.car_id)
    }

    /// How old telemetry may be before it is marked stale.
    pub fn stale_after(&self) -> Duration {
        Duration::from_millis(
            self.display
                .stale_after_ms
                .unwrap_or(u64::from(aer::telemetry::Telemetry::TIMEOUT_MS)),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shipped_file_equals_the_defaults() {
        let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/aer-dashboard.toml");
        let config = Config::load(Some(&shipped), |_| None).unwrap();
        assert_eq!(config, Config::default());
    }

    #[test]
    fn environment_overrides_the_file() {
        let config = Config::load(None, |key| match key {
            "AER_CAR_ID" => Some("car7".into()),
            "AER_MQTT_HOST" => Some("10.0.0.2".into()),
            "AER_MQTT_PORT" => Some("1999".into()),
            "AER_MQTT_USERNAME" => Some("pit".into()),
            "AER_MQTT_PASSWORD" => Some("secret".into()),
            "AER_MQTT_TLS_CA" => Some("/etc/aer/team-ca.pem".into()),
            _ => None,
        })
        .unwrap();
        assert_eq!(config.topic_prefix(), "aer/car7");
        let slash = Config::load(None, |k| (k == "AER_MQTT_PREFIX").then(|| "team/".into()));
        assert_eq!(slash.unwrap().topic_prefix(), "team/car1");
        assert_eq!(config.mqtt.host, "10.0.0.2");
        assert_eq!(config.mqtt.port, 1999);
        assert_eq!(config.mqtt.username.as_deref(), Some("pit"));
        assert_eq!(
            config.mqtt.tls_ca.as_deref(),
            Some(std::path::Path::new("/etc/aer/team-ca.pem"))
        );
        assert!(Config::load(None, |k| (k == "AER_MQTT_PORT").then(|| "x".into())).is_err());
    }

    #[test]
    fn bad_values_are_refused_with_the_reason() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.toml");
        std::fs::write(&path, "[display]\nplots = [\"shocktravel9\"]\n").unwrap();
        let error = format!("{:#}", Config::load(Some(&path), |_| None).unwrap_err());
        assert!(error.contains("shocktravel9"), "{error}");
        std::fs::write(&path, "[display]\ncan_messages = [\"MCU9\"]\n").unwrap();
        let error = format!("{:#}", Config::load(Some(&path), |_| None).unwrap_err());
        assert!(error.contains("MCU9"), "{error}");
        std::fs::write(&path, "car_idd = \"x\"\n").unwrap();
        let error = format!("{:#}", Config::load(Some(&path), |_| None).unwrap_err());
        assert!(
            error.contains("bad.toml") && error.contains("car_idd"),
            "{error}"
        );
        let only_user = Config::load(None, |k| (k == "AER_MQTT_USERNAME").then(|| "pit".into()));
        assert!(only_user.is_err());
    }
}
