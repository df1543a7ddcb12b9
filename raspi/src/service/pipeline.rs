//! The pipeline, started in two steps so whoever runs it can connect before the first frame:
//! [`Pipeline::start`] brings up the store, the raw log, the broker and the MQTT link, the
//! reporter and the forwarder; [`Pipeline::run`] starts the source and runs until it ends or
//! the shutdown future completes, then stops everything in order, each part within its time:
//! the source stops; the stage drains; the raw log and the store write what they hold; MQTT
//! sends what is queued.

use super::subsystems::{self, Mqtt};
use super::{Job, start_source};
use crate::config::{self, Config};
use crate::health::Health;
use crate::ingest::Stage;
use crate::rawlog::writer::RawWriter;
use crate::rawlog::{Block, RawTap};
use crate::sink::Sink;
use crate::sink::store::StoreSink;
use crate::source;
use crate::store::StoreWriter;
use crate::{forward, status_topics};
use aer_host::reports::counters::{Counters, ServiceCounters};
use anyhow::Result;
use std::future::Future;
use std::sync::Arc;
use std::sync::mpsc::SyncSender;
use std::time::Duration;
use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;
use tracing::{info, warn};

/// The service assembled, its source not yet started.
pub struct Pipeline {
    config: Config,
    job: Job,
    counters: Arc<Counters>,
    health: Arc<Health>,
    cancel: CancellationToken,
    store: StoreWriter,
    session: Option<i64>,
    raw_log: Option<(RawWriter, SyncSender<Block>)>,
    mqtt: Mqtt,
    reporter: JoinHandle<()>,
    forwarder: Option<JoinHandle<()>>,
    xcp_gateway: Option<crate::xcp_gateway::Gateway>,
    inputs: Option<source::Sender>,
    batches: source::Receiver,
    /// The store and raw log folder, this process's alone until the pipeline is dropped.
    _held: Vec<crate::store::lock::Held>,
}

impl Pipeline {
    /// Starts every part but the source. The store first: a bad path stops the service before
    /// anything else starts (a damaged file is moved aside and reported instead).
    pub async fn start(config: Config, job: Job) -> Result<Self> {
        let counters = Arc::new(Counters::default());
        let health = Arc::new(Health::default());
        let cancel = CancellationToken::new();
        let held = subsystems::take_store(&config, &job)?;
        let (store, session) = subsystems::start_store(&config, &job, &counters, &health)?;
        let raw_log = subsystems::start_raw_log(&config, &job, &counters, &health)?;
        let mut mqtt = subsystems::start_mqtt(&config, &counters, &health, &cancel).await?;
        // What every key of every topic means (label, unit, value names), retained, once.
        for (suffix, schema) in crate::column_descriptions::topic_schemas() {
            mqtt.publisher
                .publish_json(&format!("schema/{suffix}"), &schema, true);
        }
        let xcp_gateway = subsystems::start_xcp_gateway(
            &config,
            &job,
            &counters,
            &health,
            store.note_sender(),
            &cancel,
        )
        .await;
        if job == Job::Demo {
            // The demo's sessions get a calibration record as a pit master's would make.
            tokio::spawn(crate::xcp_gateway::rehearsal::run(
                store.note_sender(),
                counters.clone(),
                now_us,
                cancel.child_token(),
            ));
        }
        if let Some(marks) = mqtt.marks.take() {
            tokio::spawn(crate::marks::run(
                marks,
                store.note_sender(),
                counters.clone(),
                cancel.child_token(),
            ));
        }
        let reporter = tokio::spawn(status_topics::run(
            mqtt.publisher.clone(),
            config.car_id.clone(),
            counters.clone(),
            health.clone(),
            status_topics::Served {
                clients: mqtt.clients.clone(),
                xcp_gateway: xcp_gateway.as_ref().map(|g| g.state.clone()),
                events: Some(store.note_sender()),
            },
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
        let (inputs, batches) = source::channel();
        Ok(Self {
            config,
            job,
            counters,
            health,
            cancel,
            store,
            session,
            raw_log,
            mqtt,
            reporter,
            forwarder,
            xcp_gateway,
            inputs: Some(inputs),
            batches,
            _held: held,
        })
    }

    /// Where MQTT subscribers connect (the embedded broker's first listener, or the broker
    /// the service publishes to).
    pub fn mqtt_address(&self) -> &str {
        &self.mqtt.address
    }

    /// The pipeline's counters, live: what it took, published, stored and dropped.
    pub fn counters(&self) -> Arc<Counters> {
        self.counters.clone()
    }

    /// The sender a [`Job::Fed`] pipeline reads its inputs from, once; `None` for any other
    /// job (its source sends) or when already taken.
    pub fn input(&mut self) -> Option<source::Sender> {
        if self.job == Job::Fed {
            self.inputs.take()
        } else {
            None
        }
    }

    /// Starts the source and runs until it ends or `shutdown` completes, then stops every
    /// part, writing and sending what is left. Returns the counters as they ended.
    pub async fn run(
        mut self,
        shutdown: impl Future<Output = ()> + Send + 'static,
    ) -> Result<ServiceCounters> {
        let cancel = self.cancel.clone();
        tokio::spawn(async move {
            tokio::select! {
                () = shutdown => cancel.cancel(),
                () = cancel.cancelled() => {}
            }
        });
        let replies = match self.inputs.take() {
            Some(inputs) => start_source::start_source(
                &self.config,
                &self.job,
                inputs,
                &self.counters,
                &self.health,
                &self.cancel,
                &self.mqtt.address,
            )?,
            // A fed pipeline's caller took the sender.
            None => source::Replies::default(),
        };
        let mut sinks: Vec<Box<dyn Sink>> = vec![Box::new(self.mqtt.publisher.clone())];
        if let Some(rows) = self.store.sender() {
            sinks.push(Box::new(StoreSink::new(rows, &self.config.car_id)));
        }
        let mut stage = Stage::new(self.counters.clone(), sinks, replies);
        if self.job == Job::Live && self.config.can.isotp == config::IsoTpMode::Kernel {
            stage = stage.with_kernel_isotp();
        }
        let mut pit_stream = None;
        if self.config.pit_stream.enabled {
            let kernel_isotp =
                self.job == Job::Live && self.config.can.isotp == config::IsoTpMode::Kernel;
            let (tap, inputs) = crate::pit::PitTap::new(self.counters.clone(), kernel_isotp);
            stage = stage.with_pit_stream(tap);
            let ring = Arc::new(std::sync::Mutex::new(crate::pit::history::Ring::new(
                self.config.pit_stream.history_bytes(),
            )));
            pit_stream = Some(tokio::spawn(crate::pit::run(
                self.mqtt.publisher.clone(),
                aer_host::formats::pit_stream::topic(&self.config.topic_prefix()),
                self.counters.clone(),
                inputs,
                Duration::from_millis(self.config.pit_stream.window_ms),
                ring.clone(),
                self.cancel.clone(),
            )));
            if let Some(requests) = self.mqtt.history_requests.take() {
                tokio::spawn(crate::pit::history::serve(
                    self.mqtt.publisher.clone(),
                    ring,
                    self.counters.clone(),
                    crate::pit::history::Settings {
                        car_prefix: self.config.topic_prefix(),
                        bytes_per_s: self.config.pit_stream.history_kbit_s * 1000 / 8,
                        clients: self.mqtt.clients.clone(),
                    },
                    requests,
                    self.cancel.clone(),
                ));
            }
        }
        let mut raw_writer = None;
        if let Some((writer, blocks)) = self.raw_log {
            stage = stage.with_raw_log(RawTap::new(blocks, self.counters.clone()));
            raw_writer = Some(writer);
        }
        // Dropping the stage hands the raw log its last block and lets the store's queue close.
        drop(stage.run(self.batches).await);

        // The source is done (or stopped): stop the rest, each part within its time.
        self.cancel.cancel();
        let (store, session) = (self.store, self.session);
        let store_path = self.config.store.path.clone();
        subsystems::finish_blocking("local store", move || {
            store.finish();
            subsystems::end_session(&store_path, session);
        })
        .await;
        if let Some(raw_writer) = raw_writer {
            subsystems::finish_blocking("raw log", move || raw_writer.finish()).await;
        }
        let _ = tokio::time::timeout(Duration::from_secs(2), self.reporter).await;
        if let Some(pit_stream) = pit_stream {
            // Its last batch, before MQTT is drained.
            let _ = tokio::time::timeout(Duration::from_secs(2), pit_stream).await;
        }
        if let Some(forwarder) = self.forwarder {
            let _ = tokio::time::timeout(subsystems::STOP_WAIT, forwarder).await;
        }
        if let Some(gateway) = self.xcp_gateway {
            // It ends a connected master's session with the CCM first.
            let _ = tokio::time::timeout(Duration::from_secs(1), gateway.task).await;
        }
        // An unreachable broker with a full queue would make this wait for ever.
        let publisher = self.mqtt.publisher;
        if tokio::time::timeout(Duration::from_secs(2), publisher.disconnect())
            .await
            .is_err()
            || tokio::time::timeout(Duration::from_secs(2), self.mqtt.connection)
                .await
                .is_err()
        {
            warn!("MQTT queue not drained within 2 s");
        }
        let snapshot = self.counters.snapshot();
        info!(?snapshot, "stopped");
        Ok(snapshot)
    }
}

fn now_us() -> i64 {
    i64::try_from(aer_host::clock::now_us()).unwrap_or(i64::MAX)
}
