//! The service assembled: a source -> the ingest stage -> the MQTT and store sinks, with the
//! reporter, the forwarder, and an orderly shutdown (Ctrl-C cancels the source; the stage
//! drains; the store writes its last rows; MQTT sends what is queued).

use crate::config::{self, Config};
use crate::ingest::Stage;
use crate::sink::Sink;
use crate::sink::mqtt::{self, Publisher};
use crate::sink::store::{self, StoreSink, StoreWriter};
use crate::source::replay::{ReplayOptions, replay};
use crate::source::{self, Replies};
use crate::{broker, forward, report};
use aer_host::counters::Counters;
use anyhow::{Context, Result};
use std::io::BufReader;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;
use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;
use tracing::{info, warn};

/// The session the demo replays: recorded from the closed-loop car model with the CCM's own
/// logic, telemetry packer and ISO-TP sender (`cargo xtask session-log`).
pub const DEMO_LOG: &str = include_str!("../data/session.log");

/// Where the frames come from.
#[derive(Debug, Clone, PartialEq)]
pub enum Job {
    /// The configured SocketCAN interfaces.
    Live,
    /// A candump log, at recorded speed or flat out.
    Replay { file: PathBuf, fast: bool },
    /// The car model at `rate` packets per second, `packets` of them or until stopped.
    Synthetic { rate: f64, packets: Option<u64> },
    /// The bundled session, looping until stopped.
    Demo,
}

/// The MQTT side: the publisher, the task keeping its connection, and the address
/// subscribers use.
struct Mqtt {
    publisher: Publisher,
    connection: JoinHandle<()>,
    address: String,
}

/// Runs `job` until its source ends or Ctrl-C.
pub async fn serve(config: Config, job: Job) -> Result<()> {
    let counters = Arc::new(Counters::default());
    let cancel = CancellationToken::new();
    // The store first: a bad path must stop the service before anything else starts.
    let writer = StoreWriter::start(store::open(&config.store.path)?, counters.clone());
    info!(path = %config.store.path.display(), "local store open");
    let mqtt = start_mqtt(&config, &counters).await?;
    let reporter = tokio::spawn(report::run(
        mqtt.publisher.clone(),
        config.car_id.clone(),
        counters.clone(),
        cancel.clone(),
        job == Job::Demo,
    ));
    let forwarder = config.tdengine.enabled.then(|| {
        tokio::spawn(forward::run(
            config.tdengine.clone(),
            config.store.path.clone(),
            counters.clone(),
            cancel.clone(),
        ))
    });
    stop_on_ctrl_c(cancel.clone());

    let (inputs, batches) = source::channel();
    let replies = start_source(&config, &job, inputs, &counters, &cancel, &mqtt.address)?;
    let mut sinks: Vec<Box<dyn Sink>> = vec![Box::new(mqtt.publisher.clone())];
    if let Some(rows) = writer.sender() {
        sinks.push(Box::new(StoreSink::new(rows, &config.car_id)));
    }
    let mut stage = Stage::new(counters.clone(), sinks, replies);
    if job == Job::Live && config.can.isotp == config::IsoTpMode::Kernel {
        stage = stage.with_kernel_isotp();
    }
    drop(stage.run(batches).await);

    // The source is done (or stopped): stop the rest, writing and sending what is left.
    cancel.cancel();
    tokio::task::spawn_blocking(move || writer.finish())
        .await
        .ok();
    let _ = tokio::time::timeout(Duration::from_secs(2), reporter).await;
    if let Some(forwarder) = forwarder {
        let _ = tokio::time::timeout(Duration::from_secs(5), forwarder).await;
    }
    mqtt.publisher.disconnect().await;
    if tokio::time::timeout(Duration::from_secs(2), mqtt.connection)
        .await
        .is_err()
    {
        warn!("MQTT queue not drained within 2 s");
    }
    info!(snapshot = ?counters.snapshot(), "stopped");
    Ok(())
}

/// Starts the embedded broker and publishes into it, or connects to the configured broker.
async fn start_mqtt(config: &Config, counters: &Arc<Counters>) -> Result<Mqtt> {
    let client_id = format!("aer-raspi-{}", config.car_id);
    let mut address = format!("{}:{}", config.mqtt.host, config.mqtt.port);
    let (publisher, driver) = if config.broker.embedded {
        let broker_config = broker::load(config.broker.config.as_deref())?;
        if let Some(listener) = broker::listeners(&broker_config).first() {
            address = listener.to_string();
        }
        let link = broker::spawn(broker_config, &client_id)?;
        mqtt::embedded(
            link,
            config.broker.queue,
            config.topic_prefix(),
            counters.clone(),
        )
    } else {
        mqtt::connect(
            &config.mqtt,
            config.broker.queue,
            &client_id,
            config.topic_prefix(),
            counters.clone(),
        )
    };
    let (connected_tx, mut connected) = tokio::sync::watch::channel(false);
    let connection = tokio::spawn(mqtt::drive(driver, connected_tx));
    // Give the broker a moment so the first packets are not dropped for want of a connection;
    // without one the service runs anyway (MQTT drops are counted, the store keeps everything).
    if tokio::time::timeout(Duration::from_secs(5), connected.wait_for(|up| *up))
        .await
        .is_err()
    {
        warn!(broker = %address, "no MQTT broker yet; publishing once it is reachable");
    }
    Ok(Mqtt {
        publisher,
        connection,
        address,
    })
}

fn stop_on_ctrl_c(cancel: CancellationToken) {
    tokio::spawn(async move {
        if tokio::signal::ctrl_c().await.is_ok() {
            info!("Ctrl-C: flushing and stopping");
            cancel.cancel();
        }
    });
}

/// Starts `job`'s source on its own task, sending to `inputs`; returns where flow control goes.
fn start_source(
    config: &Config,
    job: &Job,
    inputs: source::Sender,
    counters: &Arc<Counters>,
    cancel: &CancellationToken,
    broker_address: &str,
) -> Result<Replies> {
    let (counters, cancel) = (counters.clone(), cancel.clone());
    match job.clone() {
        Job::Live => return start_live(config, inputs, &cancel),
        Job::Replay { file, fast } => {
            let log = std::fs::File::open(&file)
                .with_context(|| format!("opening {}", file.display()))?;
            let options = ReplayOptions {
                fast,
                restamp: false,
            };
            tokio::spawn(async move {
                let stats = replay(BufReader::new(log), inputs, &counters, options, &cancel).await;
                info!(
                    lines = stats.lines,
                    frames = stats.frames,
                    bad_lines = stats.bad_lines,
                    "replay finished"
                );
            });
        }
        Job::Synthetic { rate, packets } => {
            tokio::spawn(async move {
                source::synthetic::synthetic(rate, inputs, &cancel, packets).await;
            });
        }
        Job::Demo => {
            announce_demo(config, broker_address);
            let options = ReplayOptions {
                fast: false,
                restamp: true,
            };
            tokio::spawn(async move {
                while !cancel.is_cancelled() && !inputs.is_closed() {
                    replay(
                        DEMO_LOG.as_bytes(),
                        inputs.clone(),
                        &counters,
                        options,
                        &cancel,
                    )
                    .await;
                }
            });
        }
    }
    Ok(Replies::default())
}

#[cfg(target_os = "linux")]
fn start_live(
    config: &Config,
    inputs: source::Sender,
    cancel: &CancellationToken,
) -> Result<Replies> {
    Ok(source::socketcan::start(
        &config.can.interfaces,
        &config.can.telemetry_interface,
        config.can.isotp,
        inputs,
        cancel,
    ))
}

#[cfg(not(target_os = "linux"))]
fn start_live(_: &Config, _: source::Sender, _: &CancellationToken) -> Result<Replies> {
    anyhow::bail!("SocketCAN needs Linux; use `replay` or `synthetic` here")
}

fn announce_demo(config: &Config, broker_address: &str) {
    let (host, port) = broker_address
        .rsplit_once(':')
        .unwrap_or((broker_address, "1883"));
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
}
