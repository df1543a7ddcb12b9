//! aer-raspi: the Pi's ingest service. CAN (or a recorded log, or a synthetic car) -> ISO-TP
//! and DBC decoding -> typed MQTT topics on an embedded broker + a durable local store ->
//! TDengine.

use aer_raspi::config::{self, Config};
use aer_raspi::metrics::Counters;
use aer_raspi::pipeline::Pipeline;
use aer_raspi::source::{self, ReplayOptions};
use aer_raspi::{broker, forward, publish, store};
use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use std::io::BufReader;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;
use tracing::info;

/// The session the demo replays: recorded from the project's own CCM logic, telemetry packer
/// and ISO-TP sender (`cargo xtask session-log`).
const DEMO_LOG: &str = include_str!("../data/session.log");

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
    /// Replay a candump log (`candump -l` / `-L` format) through the pipeline.
    Replay {
        /// The log file.
        file: PathBuf,
        /// As fast as possible instead of at recorded speed.
        #[arg(long)]
        fast: bool,
    },
    /// Generate telemetry from a small vehicle model (laps: throttle, braking, speed, falling
    /// SOC, rising temperatures).
    Synthetic {
        /// Packets per second.
        #[arg(long, default_value_t = 100.0)]
        rate: f64,
        /// Stop after this many packets (default: until Ctrl-C).
        #[arg(long)]
        packets: Option<u64>,
    },
    /// Replay the bundled session at recorded speed, looping until Ctrl-C, with the embedded
    /// broker on 127.0.0.1:1883 and the local store aer-demo.sqlite.
    Demo,
}

fn main() -> Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                // rumqttd logs every client disconnect as an error inside its `remote_link`
                // span; keep its other warnings (a listener that cannot bind, for one).
                .unwrap_or_else(|_| {
                    "info,rumqttd=warn,rumqttd::server::broker[remote_link]=off".into()
                }),
        )
        .init();
    let cli = Cli::parse();
    let mut config = Config::load(cli.config.as_deref(), |key| std::env::var(key).ok())?;
    if matches!(cli.command, Command::Demo)
        && std::env::var_os("AER_STORE_PATH").is_none()
        && cli.config.is_none()
    {
        config.store.path = "aer-demo.sqlite".into();
    }
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    runtime.block_on(serve(config, cli.command))
}

async fn serve(config: Config, command: Command) -> Result<()> {
    let counters = Arc::new(Counters::default());
    let stop = Arc::new(AtomicBool::new(false));

    // The store first: a bad path must stop the service before anything else starts.
    let db = store::open(&config.store.path)?;
    let writer = store::StoreWriter::start(db, counters.clone());
    info!(path = %config.store.path.display(), "local store open");

    let client_id = format!("aer-raspi-{}", config.car_id);
    // Where subscribers find the data: the embedded broker's first listener, or the broker
    // the service publishes to.
    let mut broker_address = format!("{}:{}", config.mqtt.host, config.mqtt.port);
    let (publisher, driver) = if config.mqtt.embedded_broker {
        let broker_config = broker::load(config.mqtt.broker_config.as_deref())?;
        if let Some(listener) = broker::listeners(&broker_config).first() {
            broker_address = listener.to_string();
        }
        let link = broker::spawn(broker_config, &client_id)?;
        publish::embedded(
            link,
            config.mqtt.queue,
            config.topic_prefix(),
            counters.clone(),
        )
    } else {
        publish::connect(
            &config.mqtt,
            &client_id,
            config.topic_prefix(),
            counters.clone(),
        )
    };
    let (connected_tx, mut connected) = tokio::sync::watch::channel(false);
    let mqtt = tokio::spawn(publish::drive(driver, connected_tx));
    // Give the broker a moment so the first packets are not dropped for want of a connection;
    // without one the service runs anyway (MQTT drops are counted, the store keeps everything).
    if tokio::time::timeout(Duration::from_secs(5), connected.wait_for(|up| *up))
        .await
        .is_err()
    {
        tracing::warn!(broker = %broker_address, "no MQTT broker yet; publishing once it is reachable");
    }
    let demo = matches!(command, Command::Demo);
    let reporter = tokio::spawn(report(
        publisher.clone(),
        config.car_id.clone(),
        counters.clone(),
        stop.clone(),
        demo,
    ));
    let forwarder = config.tdengine.enabled.then(|| {
        tokio::spawn(forward::run(
            config.tdengine.clone(),
            config.store.path.clone(),
            counters.clone(),
            stop.clone(),
        ))
    });
    {
        let stop = stop.clone();
        tokio::spawn(async move {
            if tokio::signal::ctrl_c().await.is_ok() {
                info!("Ctrl-C: flushing and stopping");
                stop.store(true, Ordering::Relaxed);
            }
        });
    }

    let mut pipeline = Pipeline::new(
        counters.clone(),
        config.car_id.clone(),
        Vec::new(),
        Some(publisher.clone()),
        writer.sender(),
    );
    if matches!(command, Command::Run) && config.can.isotp == config::IsoTpMode::Kernel {
        pipeline = pipeline.with_kernel_isotp();
    }
    match command {
        Command::Run => run_live(&config, &mut pipeline, stop.clone()).await,
        Command::Replay { file, fast } => {
            let log = std::fs::File::open(&file)
                .with_context(|| format!("opening {}", file.display()))?;
            let options = ReplayOptions {
                fast,
                restamp: false,
            };
            let stats = source::replay(
                BufReader::new(log),
                &mut pipeline,
                &counters,
                options,
                &stop,
            )
            .await;
            info!(
                lines = stats.lines,
                frames = stats.frames,
                bad_lines = stats.bad_lines,
                "replay finished"
            );
        }
        Command::Synthetic { rate, packets } => {
            source::synthetic(rate, &mut pipeline, &stop, packets).await;
        }
        Command::Demo => {
            let (host, port) = broker_address
                .rsplit_once(':')
                .unwrap_or((broker_address.as_str(), "1883"));
            println!(
                "aer-raspi demo: replaying the bundled session at recorded speed, looping until Ctrl-C.\n\
                 Watch it:   mosquitto_sub -h {host} -p {port} -t 'aer/#' -v\n\
                 Dashboard:  cargo run --release -p aer-dashboard (Tab: pit view)\n\
                 Plot it:    PlotJuggler > Streaming > MQTT, broker {host}:{port}, topic aer/{car}/telemetry (JSON, timestamp field `ts`)\n\
                 Data file:  {file} (SQLite, tables from schema/)",
                car = config.car_id,
                file = std::fs::canonicalize(&config.store.path)
                    .unwrap_or_else(|_| config.store.path.clone())
                    .display()
            );
            while !stop.load(Ordering::Relaxed) {
                let options = ReplayOptions {
                    fast: false,
                    restamp: true,
                };
                source::replay(
                    DEMO_LOG.as_bytes(),
                    &mut pipeline,
                    &counters,
                    options,
                    &stop,
                )
                .await;
            }
        }
    }

    // Shut down: stop the reporters, flush the store, let MQTT send what is queued.
    stop.store(true, Ordering::Relaxed);
    drop(pipeline);
    tokio::task::spawn_blocking(move || writer.finish())
        .await
        .ok();
    let _ = tokio::time::timeout(Duration::from_secs(2), reporter).await;
    if let Some(forwarder) = forwarder {
        let _ = tokio::time::timeout(Duration::from_secs(5), forwarder).await;
    }
    publisher.disconnect().await;
    if tokio::time::timeout(Duration::from_secs(2), mqtt)
        .await
        .is_err()
    {
        tracing::warn!("MQTT queue not drained within 2 s");
    }
    let snapshot = counters.snapshot();
    info!(?snapshot, "stopped");
    Ok(())
}

#[cfg(target_os = "linux")]
async fn run_live(config: &Config, pipeline: &mut Pipeline, stop: Arc<AtomicBool>) {
    source::socketcan(
        config.can.interfaces.clone(),
        &config.can.telemetry_interface,
        config.can.isotp,
        pipeline,
        stop,
    )
    .await;
}

#[cfg(not(target_os = "linux"))]
async fn run_live(_: &Config, _: &mut Pipeline, _: Arc<AtomicBool>) {
    tracing::error!("SocketCAN needs Linux; use `replay` or `synthetic` here");
}

/// Every second: the retained status topic, the metrics topic, and (demo) a console line.
async fn report(
    publisher: publish::Publisher,
    car_id: String,
    counters: Arc<Counters>,
    stop: Arc<AtomicBool>,
    console: bool,
) {
    let mut previous = counters.snapshot();
    let mut tick = tokio::time::interval(Duration::from_secs(1));
    while !stop.load(Ordering::Relaxed) {
        tick.tick().await;
        let now = counters.snapshot();
        let metrics = publish::metrics(now, previous);
        publish::report(&publisher, &car_id, &counters, &metrics);
        if console {
            println!(
                "packets {:>7} ({:>4}/s)  frames {:>8}  stored {:>8}  published {:>8}  dropped {}  errors isotp {} decode {} unknown {} bad-lines {}",
                now.packets,
                metrics.packets_per_s,
                now.frames,
                now.stored,
                now.published,
                now.publish_dropped,
                now.isotp_errors,
                now.decode_errors,
                now.unknown_ids,
                now.bad_lines
            );
        }
        previous = now;
    }
}
