//! aer-raspi: the Pi's ingest service. CAN (or a recorded log, or a synthetic car) -> ISO-TP
//! and DBC decoding -> typed MQTT topics on an embedded broker + a durable local store ->
//! TDengine.

use aer_raspi::config::Config;
use aer_raspi::service::{Job, serve};
use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use std::path::PathBuf;

#[derive(Parser)]
#[command(
    name = "aer-raspi",
    version,
    about = "Raspberry Pi ingest: CAN/ISO-TP -> typed MQTT (embedded broker) + local store + TDengine",
    long_about = "Decodes the car's CAN traffic and the CCM's ISO-TP telemetry with the code generated \
from schema/, publishes every packet and frame as JSON on aer/<car>/telemetry and aer/<car>/can/<message>, \
appends it to a local SQLite store and (optionally) forwards the store to TDengine.\n\n\
Watch it: mosquitto_sub -h 127.0.0.1 -t 'aer/#' -v"
)]
struct Cli {
    /// Configuration file (TOML; every key optional, see raspi/config/aer-raspi.toml).
    #[arg(long, short, global = true, env = "AER_CONFIG")]
    config: Option<PathBuf>,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Live: read the configured SocketCAN interfaces (ISO-TP telemetry and every DBC frame).
    Run,
    /// Replay a candump log (`candump -l` / `-L` format) or a raw log segment through the
    /// pipeline.
    Replay {
        /// The log file, or a segment of the raw log (`raw-*.aerraw`).
        file: PathBuf,
        /// As fast as possible instead of at recorded speed.
        #[arg(long)]
        fast: bool,
    },
    /// Run the closed-loop car model (the CCM's own logic driving a simulated car round an
    /// autocross course) as a live source: every frame on both buses.
    Synthetic {
        /// Packets per second.
        #[arg(long, default_value_t = 100.0)]
        rate: f64,
        /// Stop after this many packets (default: until Ctrl-C).
        #[arg(long)]
        packets: Option<u64>,
    },
    /// Replay the bundled session at recorded speed, looping until Ctrl-C, with the embedded
    /// broker on 127.0.0.1:1883, the local store aer-demo.sqlite and the raw log in
    /// aer-demo-raw/.
    Demo,
    /// Print raw log segments as candump -l text (every frame, losslessly), oldest first; a
    /// folder means every segment in it.
    RawExport {
        /// Segment files or raw log folders.
        #[arg(required = true)]
        paths: Vec<PathBuf>,
    },
}

/// What rumqttd logs as errors when a client simply leaves. Every client reaches the broker
/// through the service's gate, which logs clients coming and going (at debug) and reports
/// the ones it refuses or disconnects itself.
const BROKER_ROUTINE: &[aer_host::logging::Routine] = &[
    aer_host::logging::Routine {
        target: "rumqttd::server::broker",
        messages: &["router-drop", "disconnected", "connection-stop"],
    },
    aer_host::logging::Routine {
        target: "rumqttd::router",
        messages: &["no-connection id", "Connection is already disconnected"],
    },
];

fn main() -> Result<()> {
    aer_host::logging::init("info,rumqttd=warn", BROKER_ROUTINE);
    let cli = Cli::parse();
    if let Command::RawExport { paths } = &cli.command {
        return aer_raspi::rawlog::export::candump(paths, std::io::stdout().lock());
    }
    let mut config = Config::load(cli.config.as_deref(), |key| std::env::var(key).ok())?;
    if matches!(cli.command, Command::Demo) && cli.config.is_none() {
        if std::env::var_os("AER_STORE_PATH").is_none() {
            config.store.path = "aer-demo.sqlite".into();
        }
        if std::env::var_os("AER_RAW_LOG_DIR").is_none() {
            config.raw_log.dir = "aer-demo-raw".into();
        }
    }
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    let job = match cli.command {
        Command::Run => Job::Live,
        Command::Replay { file, fast } => Job::Replay { file, fast },
        Command::Synthetic { rate, packets } => Job::Synthetic { rate, packets },
        Command::Demo => Job::Demo,
        Command::RawExport { .. } => return Ok(()),
    };
    runtime.block_on(serve(config, job))
}
