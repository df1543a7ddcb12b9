//! The MQTT link: subscribes to the car's typed topics on the Pi's broker and turns every
//! message into an [`Update`], decoded with the topic's own payload type. The connection is
//! retried every second for as long as the dashboard runs; every loss is reported, so the
//! screens can show it. CAN topics are subscribed to only while the pit view shows their
//! message ([`CanTopics`]), so the link carries what the screen needs and no more.

use crate::config::Config;
use crate::model::Update;
use crate::model::can::CanMessages;
use aer::mqtt::TELEMETRY;
use aer_host::status::{METRICS, STATUS};
use iced::futures::channel::mpsc;
use iced::futures::{SinkExt, Stream};
use rumqttc::{
    AsyncClient, ConnectReturnCode, ConnectionError, Event, EventLoop, MqttOptions, Packet, QoS,
    StateError, SubscribeFilter,
};
use std::collections::BTreeSet;
use std::hash::{Hash, Hasher};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};
use tracing::warn;

/// Where to connect and what to subscribe to. Part of the subscription's identity: a change
/// reconnects.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct Settings {
    pub host: String,
    pub port: u16,
    pub credentials: Option<(String, String)>,
    /// `aer/<car>`.
    pub prefix: String,
    /// The CAN topics the screens show, shared with the application.
    pub can: CanTopics,
}

/// The CAN topics the pit view shows, shared by the application (which picks them) and the
/// link (which subscribes to them): a pick is subscribed to or dropped at once, on the live
/// connection, without reconnecting; every new connection subscribes to the picks of the moment.
#[derive(Debug, Clone, Default)]
pub struct CanTopics(Arc<Mutex<Picks>>);

#[derive(Debug, Default)]
struct Picks {
    suffixes: BTreeSet<&'static str>,
    /// The connection's client, once the link has one.
    client: Option<AsyncClient>,
}

impl CanTopics {
    /// Showing the CAN topics `suffixes` (below the car's prefix).
    pub fn new(suffixes: impl IntoIterator<Item = &'static str>) -> Self {
        Self(Arc::new(Mutex::new(Picks {
            suffixes: suffixes.into_iter().collect(),
            client: None,
        })))
    }

    /// The topics shown now.
    pub fn suffixes(&self) -> Vec<&'static str> {
        self.lock().suffixes.iter().copied().collect()
    }

    /// Shows exactly `suffixes` from now on: subscribes to the new ones and unsubscribes from
    /// the others on the live connection (if there is none, the next one subscribes).
    pub fn set(&self, prefix: &str, suffixes: impl IntoIterator<Item = &'static str>) {
        let wanted: BTreeSet<&'static str> = suffixes.into_iter().collect();
        let mut picks = self.lock();
        if let Some(client) = &picks.client {
            let added: Vec<_> = wanted
                .difference(&picks.suffixes)
                .map(|suffix| SubscribeFilter::new(format!("{prefix}/{suffix}"), QoS::AtMostOnce))
                .collect();
            // The client's queue holds 16 requests and the link drains it as it runs, so a
            // request only fails to fit when the link is stuck; it is logged, and the next
            // connection subscribes to every pick.
            if !added.is_empty() {
                if let Err(error) = client.try_subscribe_many(added) {
                    warn!(%error, "subscribing to a CAN topic the pit view shows");
                }
            }
            for suffix in picks.suffixes.difference(&wanted) {
                if let Err(error) = client.try_unsubscribe(format!("{prefix}/{suffix}")) {
                    warn!(%error, "unsubscribing from a CAN topic the pit view no longer shows");
                }
            }
        }
        picks.suffixes = wanted;
    }

    /// Subscribes a new connection's `client` to `base` and the topics shown now, and keeps
    /// the client for later picks. Under the lock, so a pick made meanwhile is not missed.
    fn connected(
        &self,
        client: &AsyncClient,
        prefix: &str,
        base: impl IntoIterator<Item = String>,
    ) -> Result<(), rumqttc::ClientError> {
        let mut picks = self.lock();
        picks.client = Some(client.clone());
        let can = picks
            .suffixes
            .iter()
            .map(|suffix| format!("{prefix}/{suffix}"));
        client.try_subscribe_many(
            base.into_iter()
                .chain(can)
                .map(|topic| SubscribeFilter::new(topic, QoS::AtMostOnce)),
        )
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Picks> {
        // The picks stay consistent whatever panicked while holding them.
        self.0.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

/// The same picks, shared: a subscription keeps its identity while the picks change.
impl PartialEq for CanTopics {
    fn eq(&self, other: &Self) -> bool {
        Arc::ptr_eq(&self.0, &other.0)
    }
}

impl Eq for CanTopics {}

impl Hash for CanTopics {
    fn hash<H: Hasher>(&self, state: &mut H) {
        std::ptr::hash(Arc::as_ptr(&self.0), state);
    }
}

impl Settings {
    /// The link the configuration describes.
    pub fn from_config(config: &Config) -> Self {
        Self {
            host: config.mqtt.host.clone(),
            port: config.mqtt.port,
            credentials: config
                .mqtt
                .username
                .clone()
                .zip(config.mqtt.password.clone()),
            prefix: config.topic_prefix(),
            can: CanTopics::new(CanMessages::new(&config.display.can_messages).suffixes()),
        }
    }

    /// The topics the dashboard always reads (CAN topics come and go with the pit view).
    pub fn topics(&self) -> [String; 3] {
        [
            TELEMETRY.path(&self.prefix),
            STATUS.path(&self.prefix),
            METRICS.path(&self.prefix),
        ]
    }
}

/// Reads one message of `topic` with the payload type the topic is bound to.
pub fn decode(prefix: &str, topic: &str, payload: &[u8]) -> Update {
    let undecodable = |error: String| Update::Undecodable {
        topic: topic.to_owned(),
        error,
    };
    let suffix = topic
        .strip_prefix(prefix)
        .and_then(|rest| rest.strip_prefix('/'));
    match suffix {
        Some(s) if s == TELEMETRY.suffix() => TELEMETRY.decode(payload).map_or_else(
            |e| undecodable(e.to_string()),
            |sample| Update::Telemetry(Box::new(sample)),
        ),
        Some(s) if s == STATUS.suffix() => STATUS.decode(payload).map_or_else(
            |e| undecodable(e.to_string()),
            |status| Update::Status(Box::new(status)),
        ),
        Some(s) if s == METRICS.suffix() => METRICS.decode(payload).map_or_else(
            |e| undecodable(e.to_string()),
            |metrics| Update::Metrics(Box::new(metrics)),
        ),
        Some(s) => match aer::mqtt::decode_message(s, payload) {
            Some(Ok(sample)) => Update::Can(Box::new(sample)),
            Some(Err(e)) => undecodable(e.to_string()),
            None => undecodable("not a topic the dashboard subscribed to".into()),
        },
        None => undecodable("not a topic the dashboard subscribed to".into()),
    }
}

/// Updates from the broker, each with the time it arrived, for as long as the stream is
/// polled. Runs on the dashboard's async executor (tokio).
pub fn stream(settings: Settings) -> impl Stream<Item = (Instant, Update)> {
    iced::stream::channel(
        256,
        async move |mut output: mpsc::Sender<(Instant, Update)>| {
            let (client, mut eventloop) = connect(&settings);
            let mut accepted = false;
            loop {
                let update = next(&client, &mut eventloop, &mut accepted, &settings).await;
                let failed = matches!(update, Some(Update::Disconnected(_)));
                if let Some(update) = update {
                    // Waits while the screen catches up; the broker then holds (or, beyond its
                    // segments, drops) messages, which show up as lost packets.
                    if output.send((Instant::now(), update)).await.is_err() {
                        return;
                    }
                }
                if failed {
                    tokio::time::sleep(Duration::from_secs(1)).await;
                }
            }
        },
    )
}

fn connect(settings: &Settings) -> (AsyncClient, EventLoop) {
    // Unique per process, so the driver and pit dashboards never take over each other's session.
    let client_id = format!(
        "aer-dashboard-{}-{}",
        std::process::id(),
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.subsec_nanos())
    );
    let mut options = MqttOptions::new(client_id, settings.host.clone(), settings.port);
    options.set_keep_alive(Duration::from_secs(5));
    options.set_max_packet_size(64 * 1024, 64 * 1024);
    if let Some((user, password)) = &settings.credentials {
        options.set_credentials(user.clone(), password.clone());
    }
    AsyncClient::new(options, 16)
}

/// Polls the connection once: an update for the screens, or `None` for protocol traffic.
/// `accepted` tracks whether the broker has accepted the current connection.
async fn next(
    client: &AsyncClient,
    eventloop: &mut EventLoop,
    accepted: &mut bool,
    settings: &Settings,
) -> Option<Update> {
    match eventloop.poll().await {
        Ok(Event::Incoming(Packet::ConnAck(_))) => {
            *accepted = true;
            // A clean session forgets subscriptions: subscribe on every connection, all topics
            // in one request (the queue holds 16, so this never blocks the loop draining it).
            match settings
                .can
                .connected(client, &settings.prefix, settings.topics())
            {
                Ok(()) => None,
                Err(error) => Some(Update::Disconnected(format!("subscribing: {error}"))),
            }
        }
        // Connected means subscribed: nothing published from here on is missed.
        Ok(Event::Incoming(Packet::SubAck(_))) => Some(Update::Connected),
        Ok(Event::Incoming(Packet::Publish(publish))) => {
            Some(decode(&settings.prefix, &publish.topic, &publish.payload))
        }
        Ok(_) => None,
        Err(error) => {
            let reason = why_down(&error, *accepted);
            *accepted = false;
            Some(Update::Disconnected(reason))
        }
    }
}

/// Why the link is down, in words the pit crew can act on.
fn why_down(error: &ConnectionError, accepted: bool) -> String {
    match error {
        // rumqttd answers a wrong or missing username/password by closing the connection, not
        // with a refusal code.
        ConnectionError::MqttState(StateError::ConnectionAborted) if !accepted => {
            "the broker closed the connection before accepting it: wrong or missing \
             username/password (AER_MQTT_USERNAME, AER_MQTT_PASSWORD)?"
                .into()
        }
        ConnectionError::ConnectionRefused(code) => match code {
            ConnectReturnCode::BadUserNamePassword | ConnectReturnCode::NotAuthorized => {
                "the broker refused the username/password (AER_MQTT_USERNAME, \
                 AER_MQTT_PASSWORD)"
                    .into()
            }
            ConnectReturnCode::ServiceUnavailable => {
                "the broker has no room for another client; it frees the slots of clients \
                 that stopped reading within seconds"
                    .into()
            }
            ConnectReturnCode::BadClientId => {
                "the broker refused the client id (the Pi service's ids are reserved)".into()
            }
            other => format!("the broker refused the connection: {other:?}"),
        },
        other => other.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use aer::mqtt::{Sample, TelemetryRecord};
    use aer::telemetry::{Telemetry, TelemetryHeader};

    #[test]
    fn each_topic_is_read_with_its_own_type() {
        let sample = Sample {
            ts: 12.5,
            value: TelemetryRecord {
                header: TelemetryHeader {
                    sequence: 7,
                    timestamp_us: 99,
                },
                telemetry: Telemetry::zeroed(),
            },
        };
        let payload = TELEMETRY.encode(&sample).unwrap();
        assert_eq!(
            decode("aer/car1", "aer/car1/telemetry", &payload),
            Update::Telemetry(Box::new(sample))
        );
        // A telemetry payload on the status topic is not a status.
        assert!(matches!(
            decode("aer/car1", "aer/car1/status", &payload),
            Update::Undecodable { .. }
        ));
        // Another car, garbage, truncated JSON: reported, never a panic.
        for (topic, bytes) in [
            ("aer/car2/telemetry", &payload[..]),
            ("aer/car1/telemetry", b"\xff\x00garbage"),
            ("aer/car1/telemetry", &payload[..payload.len() / 2]),
        ] {
            match decode("aer/car1", topic, bytes) {
                Update::Undecodable { topic: t, error } => {
                    assert_eq!(t, topic);
                    assert!(!error.is_empty());
                }
                other => panic!("{topic}: {other:?}"),
            }
        }
    }
}
