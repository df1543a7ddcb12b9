//! The service assembled: a source -> the ingest stage (raw log first) -> the MQTT and store
//! sinks, with the reporter, the forwarder, and an orderly shutdown bounded in time: SIGINT
//! or SIGTERM cancels the source; the stage drains; the raw log and the store write what they
//! hold (a failing store is given a few seconds); MQTT sends what is queued.

use crate::broker::SERVICE_IDS;
use crate::config::{self, Config};
use crate::health::Health;
use crate::ingest::Stage;
use crate::rawlog::writer::{RawWriter, Settings};
use crate::rawlog::{RawTap, segments};
use crate::sink::Sink;
use crate::sink::mqtt::{self, Publisher};
use crate::sink::store::StoreSink;
use crate::source::replay::{ReplayOptions, replay, replay_segment};
use crate::source::{self, Replies};
use crate::store::{
    self, Budget, Compaction, Retention, StoreWriter, WhenFull, WriterOptions, session,
};
use crate::{broker, forward, report};
use aer_host::clock;
use aer_host::counters::Counters;
use aer_host::rawlog::SegmentReader;
use anyhow::{Context, Result};
use std::io::BufReader;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;
use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;
use tracing::{info, warn};

/// The session the demo replays: recorded from the closed-loop car model with the CCM's own
/// logic, telemetry packer and ISO-TP sender (`cargo xtask session-log`). This copy is compiled
/// in, for an installed service; `demo_log` prefers the repository's file.
pub const DEMO_LOG: &str = include_str!("../data/session.log");

/// Where the demo records (without a config file or AER_STORE_PATH), and `export --demo`
/// reads.
pub const DEMO_STORE: &str = "aer-demo.sqlite";

/// The repository's session log, as `cargo xtask session-log` rewrites it.
pub(crate) const DEMO_LOG_PATH: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/data/session.log");

/// The session the demo replays and where it came from: the repository's file, read now, so a
/// log just re-recorded with `cargo xtask session-log` plays without rebuilding; the compiled-in
/// copy where there is no repository (an installed service).
pub(crate) fn demo_log() -> (String, String) {
    match std::fs::read_to_string(DEMO_LOG_PATH) {
        Ok(text) => (text, DEMO_LOG_PATH.to_owned()),
        Err(_) => (
            DEMO_LOG.to_owned(),
            "the session compiled into this binary".to_owned(),
        ),
    }
}

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

impl Job {
    /// What the session records as its source.
    pub(crate) fn source_name(&self) -> &'static str {
        match self {
            Self::Live => "live",
            Self::Replay { .. } => "replay",
            Self::Synthetic { .. } => "synthetic",
            Self::Demo => "demo",
        }
    }
}

/// The MQTT side: the publisher, the task keeping its connection, and the address
/// subscribers use.
struct Mqtt {
    publisher: Publisher,
    connection: JoinHandle<()>,
    address: String,
}

/// How long each part may take to finish at shutdown before the service exits anyway.
const STOP_WAIT: Duration = Duration::from_secs(5);

/// Runs `job` until its source ends, SIGINT (Ctrl-C) or SIGTERM (systemd).
pub async fn serve(config: Config, job: Job) -> Result<()> {
    let counters = Arc::new(Counters::default());
    let health = Arc::new(Health::default());
    let cancel = CancellationToken::new();
    // The store first: a bad path must stop the service before anything else starts (a
    // damaged file is moved aside and reported instead).
    let (writer, session) = start_store(&config, &job, &counters, &health)?;
    let raw_log = start_raw_log(&config, &job, &counters, &health)?;
    let mqtt = start_mqtt(&config, &counters, &health, &cancel).await?;
    // What every key of every topic means (label, unit, value names), retained, once.
    for (suffix, schema) in crate::describe::topic_schemas() {
        mqtt.publisher
            .publish_json(&format!("schema/{suffix}"), &schema, true);
    }
    let reporter = tokio::spawn(report::run(
        mqtt.publisher.clone(),
        config.car_id.clone(),
        counters.clone(),
        health.clone(),
        cancel.clone(),
        job == Job::Demo,
    ));
    let forwarder = config.tdengine.enabled.then(|| {
        tokio::spawn(forward::run(
            config.tdengine.clone(),
            config.store.path.clone(),
            counters.clone(),
            health.clone(),
            cancel.clone(),
        ))
    });
    stop_on_signals(cancel.clone())?;

    let (inputs, batches) = source::channel();
    let replies = start_source(
        &config,
        &job,
        inputs,
        &counters,
        &health,
        &cancel,
        &mqtt.address,
    )?;
    let mut sinks: Vec<Box<dyn Sink>> = vec![Box::new(mqtt.publisher.clone())];
    if let Some(rows) = writer.sender() {
        sinks.push(Box::new(StoreSink::new(rows, &config.car_id)));
    }
    let mut stage = Stage::new(counters.clone(), sinks, replies);
    if job == Job::Live && config.can.isotp == config::IsoTpMode::Kernel {
        stage = stage.with_kernel_isotp();
    }
    let mut raw_writer = None;
    if let Some((writer, blocks)) = raw_log {
        stage = stage.with_raw_log(RawTap::new(blocks, counters.clone()));
        raw_writer = Some(writer);
    }
    // Dropping the stage hands the raw log its last block and lets the store's queue close.
    drop(stage.run(batches).await);

    // The source is done (or stopped): stop the rest, writing and sending what is left, each
    // part within its time.
    cancel.cancel();
    let store_path = config.store.path.clone();
    finish_blocking("local store", move || {
        writer.finish();
        end_session(&store_path, session);
    })
    .await;
    if let Some(raw_writer) = raw_writer {
        finish_blocking("raw log", move || raw_writer.finish()).await;
    }
    let _ = tokio::time::timeout(Duration::from_secs(2), reporter).await;
    if let Some(forwarder) = forwarder {
        let _ = tokio::time::timeout(STOP_WAIT, forwarder).await;
    }
    // An unreachable broker with a full queue would make this wait for ever.
    if tokio::time::timeout(Duration::from_secs(2), mqtt.publisher.disconnect())
        .await
        .is_err()
        || tokio::time::timeout(Duration::from_secs(2), mqtt.connection)
            .await
            .is_err()
    {
        warn!("MQTT queue not drained within 2 s");
    }
    info!(snapshot = ?counters.snapshot(), "stopped");
    Ok(())
}

/// Runs `finish` off the runtime, waiting at most [`STOP_WAIT`] for it.
async fn finish_blocking(part: &str, finish: impl FnOnce() + Send + 'static) {
    let task = tokio::task::spawn_blocking(finish);
    if tokio::time::timeout(STOP_WAIT, task).await.is_err() {
        warn!(
            part,
            "did not finish within {} s; stopping anyway",
            STOP_WAIT.as_secs()
        );
    }
}

/// Opens (or recovers) the store, opens this run's session in it and starts its writer with
/// the retention budget.
fn start_store(
    config: &Config,
    job: &Job,
    counters: &Arc<Counters>,
    health: &Arc<Health>,
) -> Result<(StoreWriter, Option<i64>)> {
    let (db, recovered) = store::open_or_recover(&config.store.path)?;
    if let Some(report) = recovered {
        health.store_recovered.failed(&report);
    }
    info!(path = %config.store.path.display(), "local store open");
    // The data matters more than its label: a session that cannot be recorded is logged and
    // the service runs on.
    let session = session::begin(&db, &config.session, job.source_name(), now_us())
        .inspect_err(|error| warn!(%error, "cannot record the session"))
        .ok();
    if let Some(id) = session {
        let m = &config.session;
        info!(id, driver = m.driver, track = m.track, run = ?m.run, "session open");
    }
    let retention = &config.retention;
    let budget = Budget {
        max_bytes: config.store.max_bytes,
        max_age: max_age(retention.max_age_days),
        min_free_bytes: retention.min_free_bytes,
        interval: Duration::from_secs(retention.check_seconds.max(1)),
    };
    let writer = StoreWriter::with_options(
        db,
        counters.clone(),
        WriterOptions {
            retention: Some(Retention::new(config.store.path.clone(), budget)),
            compaction: config.store.compact.then(Compaction::default),
            health: health.clone(),
            queue_rows: None,
            // A replay is not live: it waits for the store rather than dropping rows.
            when_full: if matches!(job, Job::Replay { .. }) {
                WhenFull::Wait
            } else {
                WhenFull::Drop
            },
        },
    );
    Ok((writer, session))
}

fn now_us() -> i64 {
    i64::try_from(clock::now_us()).unwrap_or(i64::MAX)
}

/// Closes the session once the writer has committed its last rows.
fn end_session(path: &std::path::Path, session: Option<i64>) {
    let Some(id) = session else { return };
    let ended = rusqlite::Connection::open(path).and_then(|db| session::end(&db, now_us()));
    if let Err(error) = ended {
        warn!(%error, id, "cannot close the session");
    }
}

fn max_age(days: u64) -> Option<Duration> {
    (days > 0).then(|| Duration::from_secs(days.saturating_mul(86_400)))
}

/// Starts the raw log's writer, unless it is off or the job replays a log (which is its own
/// record).
fn start_raw_log(
    config: &Config,
    job: &Job,
    counters: &Arc<Counters>,
    health: &Arc<Health>,
) -> Result<Option<(RawWriter, std::sync::mpsc::SyncSender<crate::rawlog::Block>)>> {
    let raw = &config.raw_log;
    if !raw.enabled || matches!(job, Job::Replay { .. }) {
        return Ok(None);
    }
    let settings = Settings {
        dir: raw.dir.clone(),
        segment_bytes: raw.segment_bytes.max(64 * 1024),
        segment_age: Duration::from_secs(raw.segment_minutes.max(1) * 60),
        sync_every: Duration::from_millis(raw.sync_ms.clamp(10, 60_000)),
        budget: segments::Budget {
            max_bytes: raw.max_bytes,
            max_age: max_age(config.retention.max_age_days),
            min_free_bytes: config.retention.min_free_bytes,
        },
    };
    let started = RawWriter::start(settings, counters.clone(), health.clone())
        .with_context(|| format!("creating the raw log folder {}", raw.dir.display()))?;
    info!(dir = %raw.dir.display(), "raw log open");
    Ok(Some(started))
}

/// Starts the embedded broker and publishes into it, or connects to the configured broker.
async fn start_mqtt(
    config: &Config,
    counters: &Arc<Counters>,
    health: &Arc<Health>,
    cancel: &CancellationToken,
) -> Result<Mqtt> {
    let client_id = format!("{SERVICE_IDS}-{}", config.car_id);
    let mut address = format!("{}:{}", config.mqtt.host, config.mqtt.port);
    let (publisher, driver) = if config.broker.embedded {
        let broker_config = broker::load(config.broker.config.as_deref())?;
        if let Some(listener) = broker::listeners(&broker_config).first() {
            address = listener.to_string();
        }
        // Only the service publishes under the topic root, whatever the car.
        let protected = format!("{}/", config.mqtt.topic_prefix.trim_end_matches('/'));
        let broker = broker::spawn(broker_config, SERVICE_IDS, &protected)?;
        broker::gate::start(broker.gate, counters.clone(), cancel.clone()).await?;
        mqtt::embedded(
            broker.link,
            broker.spares,
            config.broker.queue,
            config.topic_prefix(),
            counters.clone(),
            health.clone(),
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

/// Cancels on SIGINT (Ctrl-C) or SIGTERM (what systemd sends to stop a service).
#[cfg(unix)]
fn stop_on_signals(cancel: CancellationToken) -> Result<()> {
    use tokio::signal::unix::{SignalKind, signal};
    let mut terminate = signal(SignalKind::terminate()).context("handling SIGTERM")?;
    let mut interrupt = signal(SignalKind::interrupt()).context("handling SIGINT")?;
    tokio::spawn(async move {
        let name = tokio::select! {
            _ = terminate.recv() => "SIGTERM",
            _ = interrupt.recv() => "SIGINT",
        };
        info!(signal = name, "flushing and stopping");
        cancel.cancel();
    });
    Ok(())
}

#[cfg(not(unix))]
fn stop_on_signals(cancel: CancellationToken) -> Result<()> {
    tokio::spawn(async move {
        if tokio::signal::ctrl_c().await.is_ok() {
            info!("Ctrl-C: flushing and stopping");
            cancel.cancel();
        }
    });
    Ok(())
}

/// Starts `job`'s source on its own task, sending to `inputs`; returns where flow control goes.
fn start_source(
    config: &Config,
    job: &Job,
    inputs: source::Sender,
    counters: &Arc<Counters>,
    health: &Arc<Health>,
    cancel: &CancellationToken,
    broker_address: &str,
) -> Result<Replies> {
    let (counters, cancel) = (counters.clone(), cancel.clone());
    match job.clone() {
        Job::Live => return start_live(config, inputs, &counters, health, &cancel),
        Job::Replay { file, fast } => {
            let options = ReplayOptions {
                fast,
                restamp: false,
            };
            let mut log = std::fs::File::open(&file)
                .with_context(|| format!("opening {}", file.display()))?;
            let mut start = [0u8; 8];
            let raw = std::io::Read::read(&mut log, &mut start)
                .is_ok_and(|n| SegmentReader::is_segment(start.get(..n).unwrap_or(&[])));
            let log = std::fs::File::open(&file)
                .with_context(|| format!("opening {}", file.display()))?;
            tokio::spawn(async move {
                let stats = if raw {
                    let data = std::fs::read(&file).unwrap_or_default();
                    replay_segment(&data, inputs, &counters, options, &cancel)
                        .await
                        .unwrap_or_else(|error| {
                            warn!(%error, file = %file.display(), "not a readable raw log segment");
                            Default::default()
                        })
                } else {
                    replay(BufReader::new(log), inputs, &counters, options, &cancel).await
                };
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
            let (log, from) = demo_log();
            announce_demo(config, broker_address, &from);
            let options = ReplayOptions {
                fast: false,
                restamp: true,
            };
            tokio::spawn(async move {
                while !cancel.is_cancelled() && !inputs.is_closed() {
                    replay(log.as_bytes(), inputs.clone(), &counters, options, &cancel).await;
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
    counters: &Arc<Counters>,
    health: &Arc<Health>,
    cancel: &CancellationToken,
) -> Result<Replies> {
    Ok(source::socketcan::start(
        &config.can.interfaces,
        &config.can.telemetry_interface,
        config.can.isotp,
        inputs,
        counters,
        health,
        cancel,
    ))
}

#[cfg(not(target_os = "linux"))]
fn start_live(
    _: &Config,
    _: source::Sender,
    _: &Arc<Counters>,
    _: &Arc<Health>,
    _: &CancellationToken,
) -> Result<Replies> {
    anyhow::bail!("SocketCAN needs Linux; use `replay` or `synthetic` here")
}

fn announce_demo(config: &Config, broker_address: &str, from: &str) {
    let (host, port) = broker_address
        .rsplit_once(':')
        .unwrap_or((broker_address, "1883"));
    println!(
        "aer-raspi demo: replaying {from} at recorded speed, looping until Ctrl-C.\n\
         Watch it:   mosquitto_sub -h {host} -p {port} -t 'aer/#' -v\n\
         Dashboard:  cargo run --release -p aer-dashboard (Tab: pit view)\n\
         Plot it:    PlotJuggler > Streaming > MQTT, broker {host}:{port}, topic aer/{car}/telemetry (JSON, timestamp field `ts`)\n\
         Data file:  {file} (SQLite, tables from schema/)\n\
         Export it:  aer-raspi export --demo --session latest --out DIR (MCAP, Parquet, CSV)",
        car = config.car_id,
        file = std::fs::canonicalize(&config.store.path)
            .unwrap_or_else(|_| config.store.path.clone())
            .display()
    );
}
