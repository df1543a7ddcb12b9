//! Publishes records on the generated typed topics through rumqttc, with a counted drop
//! policy: the MQTT client's queue is bounded, and a record that does not fit is dropped and
//! counted rather than stalling decoding (the local store still gets it).

use crate::config::MqttConfig;
use crate::ingest::Record;
use crate::metrics::{Counters, worth_logging};
use aer::mqtt::{
    METRICS, Metrics, STATUS, Sample, ServiceCounters, Status, TELEMETRY, TelemetryRecord, Topic,
    encode_message,
};
use rumqttc::{AsyncClient, Event, EventLoop, MqttOptions, Packet, QoS};
use serde::Serialize;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;
use tracing::{info, warn};

/// Sends records to the broker.
#[derive(Clone)]
pub struct Publisher {
    client: AsyncClient,
    prefix: String,
    counters: Arc<Counters>,
}

/// Connects (lazily: the event loop connects and reconnects) and returns the publisher and
/// the event loop to drive with [`drive`].
pub fn connect(
    config: &MqttConfig,
    client_id: &str,
    prefix: String,
    counters: Arc<Counters>,
) -> (Publisher, EventLoop) {
    let mut options = MqttOptions::new(client_id, config.host.clone(), config.port);
    options.set_keep_alive(Duration::from_secs(5));
    options.set_max_packet_size(64 * 1024, 64 * 1024);
    if let (Some(user), Some(password)) = (&config.username, &config.password) {
        options.set_credentials(user.clone(), password.clone());
    }
    let (client, mut eventloop) = AsyncClient::new(options, config.queue.max(1));
    // Without TCP_NODELAY, Nagle's algorithm holds small publishes back for up to the peer's
    // delayed-ACK time (~40 ms): the measured p99 latency was 35 ms before this.
    let mut network = eventloop.network_options();
    network.set_tcp_nodelay(true);
    eventloop.set_network_options(network);
    (
        Publisher {
            client,
            prefix,
            counters,
        },
        eventloop,
    )
}

/// Polls the MQTT event loop in its own task (publishing from the polling task would
/// deadlock once the queue fills: rumqtt issue #263); connection errors are logged and
/// retried after a second. `connected` is set on every (re)connection; after a disconnect
/// the loop ends once the broker has closed the connection.
pub async fn drive(mut eventloop: EventLoop, connected_tx: tokio::sync::watch::Sender<bool>) {
    let mut connected = false;
    let mut closing = false;
    loop {
        match eventloop.poll().await {
            Ok(Event::Incoming(Packet::ConnAck(_))) => {
                connected = true;
                let _ = connected_tx.send(true);
                info!("connected to the MQTT broker");
            }
            Ok(Event::Outgoing(rumqttc::Outgoing::Disconnect)) => closing = true,
            Ok(_) => {}
            Err(_) if closing => return,
            Err(error) => {
                if connected {
                    warn!(%error, "MQTT connection lost; reconnecting every second");
                    connected = false;
                }
                tokio::time::sleep(Duration::from_secs(1)).await;
            }
        }
    }
}

impl Publisher {
    /// Publishes one record on its typed topic.
    pub fn publish(&self, record: &Record) {
        let (topic, payload) = match record {
            Record::Telemetry {
                ts_us,
                header,
                telemetry,
                ..
            } => {
                let sample = Sample {
                    ts: seconds(*ts_us),
                    value: TelemetryRecord {
                        header: *header,
                        telemetry: **telemetry,
                    },
                };
                (TELEMETRY.path(&self.prefix), TELEMETRY.encode(&sample))
            }
            Record::Can { ts_us, message, .. } => match encode_message(message, seconds(*ts_us)) {
                Ok((suffix, payload)) => (format!("{}/{suffix}", self.prefix), Ok(payload)),
                Err(error) => (String::new(), Err(error)),
            },
        };
        match payload {
            Ok(payload) => self.send(topic, payload, false),
            Err(error) => {
                // Serialising generated types cannot fail short of a bug; count it as a drop.
                let count = Counters::bump(&self.counters.publish_dropped);
                warn!(%error, count, "record could not be serialised");
            }
        }
    }

    /// Sends everything queued, then disconnects (the event loop then ends).
    pub async fn disconnect(&self) {
        let _ = self.client.disconnect().await;
    }

    /// Publishes any JSON value on `<prefix>/<suffix>` (outside the typed topics: probes and
    /// the benchmark's stand-in for today's payload).
    pub fn publish_json(&self, suffix: &str, value: &impl Serialize, retain: bool) {
        if let Ok(payload) = serde_json::to_vec(value) {
            self.send(format!("{}/{suffix}", self.prefix), payload, retain);
        }
    }

    /// Publishes `value` on `topic`, typed by the topic.
    pub fn publish_on<P: Serialize>(&self, topic: &Topic<P>, value: &P, retain: bool) {
        match topic.encode(value) {
            Ok(payload) => self.send(topic.path(&self.prefix), payload, retain),
            Err(error) => {
                let count = Counters::bump(&self.counters.publish_dropped);
                warn!(%error, count, topic = topic.suffix(), "payload could not be serialised");
            }
        }
    }

    fn send(&self, topic: String, payload: Vec<u8>, retain: bool) {
        match self
            .client
            .try_publish(topic, QoS::AtMostOnce, retain, payload)
        {
            Ok(()) => {
                Counters::bump(&self.counters.published);
            }
            Err(_) => {
                let count = Counters::bump(&self.counters.publish_dropped);
                if worth_logging(count) {
                    warn!(
                        count,
                        "MQTT queue full (broker slow or unreachable): message dropped"
                    );
                }
            }
        }
    }
}

/// Seconds since the epoch, as PlotJuggler reads `ts`.
pub fn seconds(ts_us: u64) -> f64 {
    ts_us as f64 / 1e6
}

/// The counters now, with the packet rate since `previous` (read one second earlier).
pub fn metrics(now: ServiceCounters, previous: ServiceCounters) -> Metrics {
    Metrics {
        ts: seconds(crate::source::now_us()),
        packets_per_s: now.packets.saturating_sub(previous.packets) as f64,
        store_lag: (now.packets + now.messages).saturating_sub(now.stored),
        counters: now,
    }
}

/// Publishes the retained status and the metrics.
pub fn report(publisher: &Publisher, car_id: &str, counters: &Counters, metrics: &Metrics) {
    publisher.publish_on(&STATUS, &status(car_id, counters), true);
    publisher.publish_on(&METRICS, metrics, false);
}

/// The status as of now.
pub fn status(car_id: &str, counters: &Counters) -> Status {
    let seen = counters.firmware_fingerprint.load(Ordering::Relaxed);
    let last = counters.last_packet_us.load(Ordering::Relaxed);
    let ours = aer::telemetry::TELEMETRY_FINGERPRINT;
    Status {
        service: "aer-raspi".to_owned(),
        car_id: car_id.to_owned(),
        schema_fingerprint: format!("{:#010x}", aer::can::SCHEMA_FINGERPRINT),
        telemetry_fingerprint: format!("{ours:#010x}"),
        firmware_fingerprint_seen: (seen != 0).then(|| format!("{seen:#010x}")),
        fingerprint_match: (seen != 0).then_some(seen == u64::from(ours)),
        last_packet_ts: (last != 0).then(|| seconds(last)),
    }
}
