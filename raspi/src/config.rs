//! The service configuration: one TOML file (every key optional), then environment overrides.
//! The `[mqtt]` section and its variables are the dashboard's too (`aer_host::config`).

use crate::store::session::Metadata;
use aer_host::config::{BrokerConfig, apply_car_env, read_or_default};
use anyhow::Result;
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// Everything the service reads from its configuration.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Config {
    pub car_id: String,
    pub can: CanConfig,
    /// Where the car's topics are (shared with the dashboard).
    pub mqtt: BrokerConfig,
    /// How the service publishes: its embedded broker, or the one in `[mqtt]`.
    pub broker: BrokerOptions,
    pub store: StoreConfig,
    pub raw_log: RawLogConfig,
    /// The compact stream for the pit on `aer-pit/<car>/stream`.
    pub pit_stream: PitStreamConfig,
    pub retention: RetentionConfig,
    pub tdengine: TdengineConfig,
    /// The pit's XCP gateway to the CCM's calibration slave.
    pub xcp_gateway: XcpGatewayConfig,
    /// Who drives, where, which run: stored with the session's data and carried into every
    /// export (the command line's `--driver` etc. override it).
    pub session: Metadata,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CanConfig {
    pub interfaces: Vec<String>,
    pub telemetry_interface: String,
    pub isotp: IsoTpMode,
}

/// Who reassembles the CCM's ISO-TP telemetry in `run`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum IsoTpMode {
    /// The kernel's ISO-TP socket (module can-isotp), which also answers with flow control.
    Kernel,
    /// The service's own receiver (aer-isotp) on the raw CAN socket.
    Userspace,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BrokerOptions {
    /// Start the embedded rumqttd broker and publish into it in process; otherwise publish
    /// over TCP to the broker in `[mqtt]`.
    pub embedded: bool,
    /// The embedded broker's configuration (default: the bundled `config/rumqttd.toml`).
    pub config: Option<PathBuf>,
    /// Messages that may wait for the broker before new ones are dropped (and counted).
    pub queue: usize,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StoreConfig {
    pub path: PathBuf,
    /// The most the store may take on disk; the oldest rows (forwarded ones first) go beyond.
    pub max_bytes: u64,
    /// Closed sessions are compacted into compressed blocks (about 3 bytes a row instead of
    /// 87); false keeps every row as a plain SQL row.
    pub compact: bool,
}

/// The black-box raw log: every frame, before decoding.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RawLogConfig {
    pub enabled: bool,
    pub dir: PathBuf,
    /// A new segment starts at this size ...
    pub segment_bytes: u64,
    /// ... or this age.
    pub segment_minutes: u64,
    /// How often written frames are synced to disk (what a power cut can lose at most).
    pub sync_ms: u64,
    /// The most the segments may take together; the oldest go beyond.
    pub max_bytes: u64,
}

/// Limits shared by the store and the raw log.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RetentionConfig {
    /// Data older than this goes (0: kept until a size budget needs the room).
    pub max_age_days: u64,
    /// Below this much free space on their file system, the oldest data goes.
    pub min_free_bytes: u64,
    /// How often the store's budget is checked.
    pub check_seconds: u64,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TdengineConfig {
    pub enabled: bool,
    pub dsn: String,
    /// The database the car's tables live in (letters, digits and `_`).
    pub database: String,
    /// Options of `CREATE DATABASE` after `PRECISION 'us'` (which the timestamps need):
    /// sized for a Raspberry Pi by default.
    pub database_options: String,
    pub batch_rows: usize,
    pub workers: usize,
}

impl Default for Config {
    fn default() -> Self {
        Self {
            car_id: "car1".into(),
            can: CanConfig::default(),
            mqtt: BrokerConfig::default(),
            broker: BrokerOptions::default(),
            store: StoreConfig::default(),
            raw_log: RawLogConfig::default(),
            pit_stream: PitStreamConfig::default(),
            retention: RetentionConfig::default(),
            tdengine: TdengineConfig::default(),
            xcp_gateway: XcpGatewayConfig::default(),
            session: Metadata::default(),
        }
    }
}

/// The pit's XCP gateway (`crate::xcp_gateway`): XCP on TCP from the pit to the CCM's slave on
/// CAN. It runs with the live service (`aer-raspi run`), not with replays or the demo.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct XcpGatewayConfig {
    pub enabled: bool,
    /// Where masters connect (the A2L's XCP_ON_TCP_IP names port 5555). The default, the
    /// loopback address, serves a pit through `ssh -L 5555:127.0.0.1:5555 pi@car`; the pit
    /// radio's address serves it directly.
    pub listen: std::net::SocketAddr,
    /// The addresses masters may connect from (`10.9.0.2`, `10.9.0.0/24`); anyone else is
    /// refused and counted.
    pub allow: Vec<String>,
    /// The CAN interface the CCM's slave is on; empty: the second of `[can] interfaces`, the
    /// inverter bus (the schema's XCP bus), or the only one.
    pub interface: String,
    /// A master that sends nothing for this long (s) is taken as gone, and its session with
    /// the CCM ended.
    pub idle_s: u64,
}

impl Default for XcpGatewayConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            listen: std::net::SocketAddr::from(([127, 0, 0, 1], 5555)),
            allow: vec!["127.0.0.1/32".into(), "::1/128".into()],
            interface: String::new(),
            idle_s: 300,
        }
    }
}

impl XcpGatewayConfig {
    /// The gateway's settings; an allow-list entry that is not a network is an error (the
    /// service then runs without the gateway and its status says why).
    pub fn settings(&self, can: &CanConfig) -> Result<crate::xcp_gateway::Settings> {
        let allow = self
            .allow
            .iter()
            .map(|entry| entry.parse())
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| anyhow::anyhow!("[xcp_gateway] allow: {e}"))?;
        let interface = if self.interface.is_empty() {
            let interfaces = &can.interfaces;
            interfaces
                .get(1)
                .or(interfaces.first())
                .cloned()
                .unwrap_or_default()
        } else {
            self.interface.clone()
        };
        Ok(crate::xcp_gateway::Settings {
            listen: self.listen,
            allow,
            interface,
            idle: std::time::Duration::from_secs(self.idle_s.max(1)),
        })
    }
}

/// The compact stream for the pit (`aer_host::formats::pit_stream`): what ingest takes in, batched
/// and compressed, beside the JSON topics.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PitStreamConfig {
    /// Publish it (the JSON topics are published either way).
    pub enabled: bool,
    /// How long a batch collects (ms, 10-1000): the latency it adds. Shorter costs bandwidth:
    /// the bundled session needs about 79 kbit/s at 50 ms, 58 at 100, 41 at 250.
    pub window_ms: u64,
    /// Memory kept of what the stream published, for pits that missed it (MiB, 0-1024; 0:
    /// no history). The bundled session's stream is about 7 KiB/s: 64 MiB hold 2.5 hours.
    pub history_mib: u64,
    /// The pace of history answers (kbit/s, 8-100000): with the live stream, within the
    /// radio's rate (about 60 kbit/s live + 100 history within a 250 kbit/s link).
    pub history_kbit_s: u64,
}

impl PitStreamConfig {
    /// True when pits may ask for what they missed.
    pub fn keeps_history(&self) -> bool {
        self.enabled && self.history_mib > 0
    }

    /// The history ring's budget.
    pub fn history_bytes(&self) -> usize {
        usize::try_from(self.history_mib.saturating_mul(1 << 20)).unwrap_or(usize::MAX)
    }
}

impl Default for PitStreamConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            window_ms: 100,
            history_mib: 64,
            history_kbit_s: 100,
        }
    }
}

impl Default for CanConfig {
    fn default() -> Self {
        Self {
            interfaces: vec!["can0".into(), "can1".into()],
            telemetry_interface: "can0".into(),
            isotp: IsoTpMode::Kernel,
        }
    }
}

impl Default for BrokerOptions {
    fn default() -> Self {
        Self {
            embedded: true,
            config: None,
            queue: 10_000,
        }
    }
}

impl Default for StoreConfig {
    fn default() -> Self {
        Self {
            path: "aer-local.sqlite".into(),
            max_bytes: 4 << 30,
            compact: true,
        }
    }
}

impl Default for RawLogConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            dir: "aer-raw".into(),
            segment_bytes: 16 << 20,
            segment_minutes: 60,
            sync_ms: 1_000,
            max_bytes: 4 << 30,
        }
    }
}

impl Default for RetentionConfig {
    fn default() -> Self {
        Self {
            max_age_days: 30,
            min_free_bytes: 1 << 30,
            check_seconds: 60,
        }
    }
}

impl Default for TdengineConfig {
    fn default() -> Self {
        Self {
            enabled: false,
            dsn: "taos+ws://localhost:6041".into(),
            database: "aer".into(),
            // One vgroup, a 16 MB write buffer, the last row cached, ten years kept.
            database_options:
                "VGROUPS 1 REPLICA 1 BUFFER 16 PAGES 64 CACHEMODEL 'last_row' KEEP 3650".into(),
            batch_rows: 5_000,
            workers: 2,
        }
    }
}

/// The installed service's configuration (package aer-raspi).
pub const INSTALLED: &str = "/etc/aer/aer-raspi.toml";

/// Which configuration a store command (`session`, `export`, `compact`) reads: the one given
/// (`-c`, or `AER_CONFIG`), else the installed service's when there is one, so a command typed
/// on the car finds the service's store, else the built-in defaults (a store in the current
/// folder). The service's own jobs (`run`, `replay`, `demo`) read only what they are given.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Origin {
    /// `-c` or `AER_CONFIG`.
    Given(PathBuf),
    /// [`INSTALLED`], found.
    Installed(PathBuf),
    /// No file: the defaults.
    Defaults,
    /// `--demo`: the defaults, recording into (or reading) the demo's store and raw log.
    Demo,
}

/// Where the demo records (unless AER_STORE_PATH or AER_RAW_LOG_DIR say otherwise, whatever
/// configuration it is given) and what every store command reads with `--demo`.
pub const DEMO_STORE: &str = "aer-demo.sqlite";
/// The demo's raw log folder.
pub const DEMO_RAW_LOG: &str = "aer-demo-raw";

impl Origin {
    /// The choice for a store command, given `-c`/`AER_CONFIG` and where the installed
    /// configuration would be.
    pub fn for_store_command(given: Option<&Path>, installed: &Path) -> Self {
        match given {
            Some(path) => Self::Given(path.to_owned()),
            None if installed.is_file() => Self::Installed(installed.to_owned()),
            None => Self::Defaults,
        }
    }

    /// The file to read, if any.
    pub fn path(&self) -> Option<&Path> {
        match self {
            Self::Given(path) | Self::Installed(path) => Some(path),
            Self::Defaults | Self::Demo => None,
        }
    }
}

impl std::fmt::Display for Origin {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Given(path) => write!(f, "configuration {}", path.display()),
            Self::Installed(path) => {
                write!(f, "configuration {}, the installed service's", path.display())
            }
            Self::Defaults => f.write_str(
                "no configuration file (no -c, no AER_CONFIG, no /etc/aer/aer-raspi.toml): the built-in defaults",
            ),
            Self::Demo => write!(f, "--demo: the demo's store and raw log, {DEMO_RAW_LOG}/"),
        }
    }
}

impl Config {
    /// This configuration recording into the demo's store and raw log, unless the environment
    /// (`env`) moves them: so `demo` and every store command's `--demo` meet.
    pub fn in_demo_store(mut self, env: impl Fn(&str) -> Option<String>) -> Self {
        if env("AER_STORE_PATH").is_none() {
            self.store.path = DEMO_STORE.into();
        }
        if env("AER_RAW_LOG_DIR").is_none() {
            self.raw_log.dir = DEMO_RAW_LOG.into();
        }
        self
    }

    /// Reads `path` (if given) and applies the environment overrides from `env`.
    pub fn load(path: Option<&Path>, env: impl Fn(&str) -> Option<String>) -> Result<Self> {
        let mut config: Self = read_or_default(path)?;
        config.apply_env(env)?;
        config.check_tags()?;
        if !(10..=1000).contains(&config.pit_stream.window_ms) {
            anyhow::bail!(
                "[pit_stream] window_ms = {}: use 10 to 1000",
                config.pit_stream.window_ms
            );
        }
        if config.pit_stream.history_mib > 1024 {
            anyhow::bail!(
                "[pit_stream] history_mib = {}: use 0 to 1024",
                config.pit_stream.history_mib
            );
        }
        if !(8..=100_000).contains(&config.pit_stream.history_kbit_s) {
            anyhow::bail!(
                "[pit_stream] history_kbit_s = {}: use 8 to 100000",
                config.pit_stream.history_kbit_s
            );
        }
        let database = &config.tdengine.database;
        if database.is_empty()
            || !database
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_')
        {
            anyhow::bail!(
                "[tdengine] database = {database:?}: use letters, digits and underscores"
            );
        }
        Ok(config)
    }

    fn apply_env(&mut self, env: impl Fn(&str) -> Option<String>) -> Result<()> {
        apply_car_env(&mut self.car_id, &env);
        self.mqtt.apply_env(&env)?;
        if let Some(v) = env("AER_CAN_INTERFACES") {
            self.can.interfaces = v.split(',').map(|s| s.trim().to_owned()).collect();
        }
        if let Some(v) = env("AER_TELEMETRY_INTERFACE") {
            self.can.telemetry_interface = v;
        }
        if let Some(v) = env("AER_ISOTP") {
            self.can.isotp = match v.as_str() {
                "kernel" => IsoTpMode::Kernel,
                "userspace" => IsoTpMode::Userspace,
                other => anyhow::bail!("AER_ISOTP={other}: use kernel or userspace"),
            };
        }
        if let Some(v) = env("AER_STORE_PATH") {
            self.store.path = v.into();
        }
        if let Some(v) = env("AER_RAW_LOG_DIR") {
            self.raw_log.dir = v.into();
        }
        if let Some(v) = env("AER_TDENGINE_DSN") {
            self.tdengine.dsn = v;
            self.tdengine.enabled = true;
        }
        Ok(())
    }

    /// The car id and the interface names become TDengine tags of fixed width: one that does
    /// not fit would have every row refused, so it is refused here, at start-up.
    fn check_tags(&self) -> Result<()> {
        let limit = |tag: &str| {
            aer::tables::TABLES
                .iter()
                .flat_map(|table| table.tags)
                .find(|column| column.name == tag)
                .and_then(|column| match column.ty {
                    aer::tables::ColumnType::VarChar(n) => Some(usize::from(n)),
                    _ => None,
                })
        };
        let too_long = |value: &str, tag: &str| limit(tag).filter(|max| value.len() > *max);
        if let Some(max) = too_long(&self.car_id, "car_id") {
            anyhow::bail!(
                "car_id {:?} is longer than its {max}-byte database tag",
                self.car_id
            );
        }
        for interface in self
            .can
            .interfaces
            .iter()
            .chain([&self.can.telemetry_interface])
        {
            if let Some(max) = too_long(interface, "bus") {
                anyhow::bail!(
                    "interface name {interface:?} is longer than its {max}-byte database tag"
                );
            }
        }
        Ok(())
    }

    /// Topic prefix of this car: `<prefix>/<car_id>`.
    pub fn topic_prefix(&self) -> String {
        self.mqtt.car_prefix(&self.car_id)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shipped_file_equals_the_defaults() {
        let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/aer-raspi.toml");
        let config = Config::load(Some(&shipped), |_| None).unwrap();
        assert_eq!(config, Config::default());
    }

    #[test]
    fn the_xcp_gateway_serves_the_inverter_bus_and_names_an_allow_list_it_cannot_read() {
        let config = Config::default();
        let settings = config.xcp_gateway.settings(&config.can).unwrap();
        assert_eq!(settings.interface, "can1");
        assert!(
            settings
                .allow
                .iter()
                .any(|n| n.contains([127, 0, 0, 1].into()))
        );
        assert!(
            !settings
                .allow
                .iter()
                .any(|n| n.contains([10, 9, 0, 2].into()))
        );
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("aer-raspi.toml");
        std::fs::write(&path, "[xcp_gateway]\nallow = [\"10.9.0.0/33\"]\n").unwrap();
        // The service starts (ingest must not wait on a gateway setting); the gateway does
        // not, and the status names why.
        let config = Config::load(Some(&path), |_| None).unwrap();
        let error = config
            .xcp_gateway
            .settings(&config.can)
            .unwrap_err()
            .to_string();
        assert!(
            error.contains("[xcp_gateway] allow") && error.contains("10.9.0.0/33"),
            "{error}"
        );
    }

    #[test]
    fn environment_overrides_the_file() {
        let config = Config::load(None, |key| match key {
            "AER_CAR_ID" => Some("car7".into()),
            "AER_MQTT_PORT" => Some("1999".into()),
            "AER_CAN_INTERFACES" => Some("vcan0, vcan1".into()),
            "AER_TDENGINE_DSN" => Some("taos+ws://pit:6041".into()),
            _ => None,
        })
        .unwrap();
        assert_eq!(config.car_id, "car7");
        assert_eq!(config.mqtt.port, 1999);
        assert_eq!(config.can.interfaces, ["vcan0", "vcan1"]);
        assert!(config.tdengine.enabled);
        assert_eq!(config.topic_prefix(), "aer/car7");
        assert!(Config::load(None, |k| (k == "AER_MQTT_PORT").then(|| "x".into())).is_err());
        // What the dashboard subscribes to with the same setting (its config test).
        let slash = Config::load(None, |k| (k == "AER_MQTT_PREFIX").then(|| "team/".into()));
        assert_eq!(slash.unwrap().topic_prefix(), "team/car1");
    }

    #[test]
    fn names_longer_than_their_database_tags_are_refused_at_start_up() {
        let long = "x".repeat(33);
        let error = Config::load(None, |k| (k == "AER_CAR_ID").then(|| long.clone()))
            .expect_err("a 33-byte car id does not fit VARCHAR(32)");
        assert!(format!("{error:#}").contains("car_id"), "{error:#}");
        assert!(Config::load(None, |k| (k == "AER_CAR_ID").then(|| "x".repeat(32))).is_ok());
        let error = Config::load(None, |k| {
            (k == "AER_CAN_INTERFACES").then(|| "can0,a-very-long-ifname".into())
        })
        .expect_err("a 17-byte interface name does not fit VARCHAR(16)");
        assert!(format!("{error:#}").contains("interface"), "{error:#}");
    }

    #[test]
    fn store_commands_find_the_installed_configuration_unless_given_one() {
        let dir = tempfile::tempdir().unwrap();
        let installed = dir.path().join("aer-raspi.toml");
        let given = dir.path().join("mine.toml");
        assert_eq!(
            Origin::for_store_command(None, &installed),
            Origin::Defaults
        );
        std::fs::write(&installed, "").unwrap();
        assert_eq!(
            Origin::for_store_command(None, &installed),
            Origin::Installed(installed.clone())
        );
        assert_eq!(
            Origin::for_store_command(Some(&given), &installed),
            Origin::Given(given.clone())
        );
        assert_eq!(Origin::Defaults.path(), None);
    }

    #[test]
    fn unknown_keys_are_refused_with_the_file_name() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.toml");
        std::fs::write(&path, "car_idd = \"x\"\n").unwrap();
        let error = format!("{:#}", Config::load(Some(&path), |_| None).unwrap_err());
        assert!(
            error.contains("bad.toml") && error.contains("car_idd"),
            "{error}"
        );
    }
}
