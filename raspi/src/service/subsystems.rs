//! The parts the pipeline starts before its source, each on its own: the store (with this
//! run's session), the raw log, the MQTT side (the embedded broker or a connection), and how
//! each is given a bounded time to finish at shutdown.

use super::Job;
use crate::broker::{self, SERVICE_IDS};
use crate::config::Config;
use crate::health::Health;
use crate::rawlog::writer::{RawWriter, Settings};
use crate::rawlog::{Block, segments};
use crate::sink::mqtt::{self, Publisher};
use crate::store::{
    self, Budget, Compaction, Retention, StoreWriter, WhenFull, WriterOptions, lock, session,
};
use aer_host::clock;
use aer_host::formats::pit_stream;
use aer_host::reports::counters::Counters;
use anyhow::{Context, Result};
use std::sync::Arc;
use std::sync::mpsc::SyncSender;
use std::time::Duration;
use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;
use tracing::{info, warn};

/// How long each part may take to finish at shutdown before the service exits anyway.
pub(super) const STOP_WAIT: Duration = Duration::from_secs(5);

/// The MQTT side: the publisher, the task keeping its connection, and the address
/// subscribers use.
pub(super) struct Mqtt {
    pub(super) publisher: Publisher,
    pub(super) connection: JoinHandle<()>,
    pub(super) address: String,
    /// The pits' history requests, when the stream keeps history.
    pub(super) history_requests: Option<tokio::sync::mpsc::Receiver<Vec<u8>>>,
    /// The dashboards' lap marks, for the marks task.
    pub(super) marks: Option<tokio::sync::mpsc::Receiver<Vec<u8>>>,
    /// The clients the gate serves (embedded broker only), for the status.
    pub(super) clients: Option<Arc<broker::gate::Clients>>,
}

/// Runs `finish` off the runtime, waiting at most [`STOP_WAIT`] for it.
pub(super) async fn finish_blocking(part: &str, finish: impl FnOnce() + Send + 'static) {
    let task = tokio::task::spawn_blocking(finish);
    if tokio::time::timeout(STOP_WAIT, task).await.is_err() {
        warn!(
            part,
            "did not finish within {} s; stopping anyway",
            STOP_WAIT.as_secs()
        );
    }
}

/// Takes the store, and the raw log folder this job writes, for this process alone: a second
/// service on the same store refuses here, before it opens a session or binds a port.
pub(super) fn take_store(config: &Config, job: &Job) -> Result<Vec<lock::Held>> {
    let holder = lock::this_process(job.source_name(), now_us());
    let mut held = vec![lock::take(
        &lock::store_lock_path(&config.store.path),
        &format!("the store {}", config.store.path.display()),
        &holder,
    )?];
    if writes_raw_log(config, job) {
        let dir = &config.raw_log.dir;
        std::fs::create_dir_all(dir)
            .with_context(|| format!("creating the raw log folder {}", dir.display()))?;
        held.push(lock::take(
            &lock::raw_log_lock_path(dir),
            &format!("the raw log folder {}", dir.display()),
            &holder,
        )?);
    }
    Ok(held)
}

/// Whether `job` keeps a raw log: unless it is off or the job replays a log once (which is its
/// own record).
fn writes_raw_log(config: &Config, job: &Job) -> bool {
    config.raw_log.enabled && !matches!(job, Job::Replay { looping: false, .. })
}

/// Opens (or recovers) the store, opens this run's session in it and starts its writer with
/// the retention budget.
pub(super) fn start_store(
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
            // A replay is not live: it waits for the store rather than dropping rows (a looping
            // replay stands in for live traffic, and is treated as such).
            when_full: if matches!(job, Job::Replay { looping: false, .. }) {
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
pub(super) fn end_session(path: &std::path::Path, session: Option<i64>) {
    let Some(id) = session else { return };
    let ended = rusqlite::Connection::open(path).and_then(|db| session::end(&db, now_us()));
    if let Err(error) = ended {
        warn!(%error, id, "cannot close the session");
    }
}

fn max_age(days: u64) -> Option<Duration> {
    (days > 0).then(|| Duration::from_secs(days.saturating_mul(86_400)))
}

/// Starts the raw log's writer, unless it is off or the job replays a log once (which is its own
/// record).
pub(super) fn start_raw_log(
    config: &Config,
    job: &Job,
    counters: &Arc<Counters>,
    health: &Arc<Health>,
) -> Result<Option<(RawWriter, SyncSender<Block>)>> {
    let raw = &config.raw_log;
    if !writes_raw_log(config, job) {
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

/// Lap marks that may wait for the marks task.
const MARKS_INTAKE: usize = 16;

/// History requests that may arrive before the history task reads them.
const HISTORY_INTAKE: usize = 16;

/// Starts the embedded broker and publishes into it, or connects to the configured broker.
pub(super) async fn start_mqtt(
    config: &Config,
    counters: &Arc<Counters>,
    health: &Arc<Health>,
    cancel: &CancellationToken,
) -> Result<Mqtt> {
    let client_id = format!("{SERVICE_IDS}-{}", config.car_id);
    let mut address = format!("{}:{}", config.mqtt.host, config.mqtt.port);
    let mut clients = None;
    let (publisher, driver) = if config.broker.embedded {
        let broker_config = broker::load(config.broker.config.as_deref())?;
        if let Some(listener) = broker::listeners(&broker_config).first() {
            address = listener.to_string();
        }
        // Only the service publishes under the topic root, whatever the car.
        let root = config.mqtt.topic_prefix.trim_end_matches('/');
        let protected = [
            format!("{root}/"),
            format!("{root}{}/", pit_stream::ROOT_SUFFIX),
        ];
        // ... but for the pits' history requests and the dashboards' lap marks, which their
        // tasks check.
        let open = [
            aer_host::link::pit_history::request_topic(&config.topic_prefix()),
            aer_host::link::marks::topic(&config.topic_prefix()),
        ];
        let broker = broker::spawn(broker_config, SERVICE_IDS, &protected, &open)?;
        clients = Some(broker::gate::start(broker.gate, counters.clone(), cancel.clone()).await?);
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
        .context("the MQTT broker's TLS (mqtt.tls_ca)")?
    };
    let (driver, history_requests) = if config.pit_stream.keeps_history() {
        let (sender, receiver) = tokio::sync::mpsc::channel(HISTORY_INTAKE);
        let intake = mqtt::Intake {
            filter: aer_host::link::pit_history::request_topic(&config.topic_prefix()),
            sender,
            counters: counters.clone(),
            refused: |c| &c.history_refused,
        };
        (driver.with_intake(intake), Some(receiver))
    } else {
        (driver, None)
    };
    let (sender, marks) = tokio::sync::mpsc::channel(MARKS_INTAKE);
    let driver = driver.with_intake(mqtt::Intake {
        filter: aer_host::link::marks::topic(&config.topic_prefix()),
        sender,
        counters: counters.clone(),
        refused: |c| &c.marks_refused,
    });
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
        history_requests,
        marks: Some(marks),
        clients,
    })
}

/// The pit's XCP gateway, for the live service when configured: `None` otherwise, or when it
/// cannot start (which the status names; the rest of the service runs).
pub(super) async fn start_xcp_gateway(
    config: &Config,
    job: &Job,
    counters: &Arc<Counters>,
    health: &Arc<Health>,
    record: crate::store::NoteSender,
    cancel: &CancellationToken,
) -> Option<crate::xcp_gateway::Gateway> {
    if *job != Job::Live || !config.xcp_gateway.enabled {
        return None;
    }
    let started = async {
        let settings = config.xcp_gateway.settings(&config.can)?;
        #[cfg(target_os = "linux")]
        let link = crate::xcp_gateway::can::open(&settings.interface)
            .map_err(|e| anyhow::anyhow!("opening {}: {e}", settings.interface))?;
        #[cfg(not(target_os = "linux"))]
        anyhow::bail!("XCP on CAN needs Linux's SocketCAN");
        let listen = settings.listen;
        crate::xcp_gateway::spawn(
            settings,
            link,
            counters.clone(),
            Some(record),
            cancel.child_token(),
        )
        .await
        .map_err(|e| anyhow::anyhow!("listening on {listen}: {e}"))
    };
    match started.await {
        Ok(gateway) => Some(gateway),
        Err(error) => {
            let error = format!("{error:#}");
            warn!(%error, "the XCP gateway did not start; the rest of the service runs");
            health.xcp_gateway.failed(&error);
            None
        }
    }
}
