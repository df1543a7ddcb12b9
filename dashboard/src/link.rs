//! The MQTT link: subscribes to the car's typed topics on the Pi's broker and turns every
//! message into an [`Update`], decoded with the topic's own payload type. The connection is
//! retried every second for as long as the dashboard runs; every loss is reported, so the
//! screens can show it. CAN topics are subscribed to only while the pit view shows their
//! message (the application says which through the link's [`Control`]), so the link carries
//! what the screen needs and no more.

use crate::backfill::Backfill;
use crate::config::{Config, StreamFormat};
use crate::model::Update;
use crate::model::can::CanMessages;
use crate::pit_stream::StreamDecoder;
use aer::mqtt::TELEMETRY;
use aer_host::link::marks::Mark;
use aer_host::reports::status::{METRICS, STATUS};
use iced::futures::channel::mpsc;
use iced::futures::{SinkExt, Stream, StreamExt};
use rumqttc::{
    AsyncClient, ConnectReturnCode, ConnectionError, Event as MqttEvent, EventLoop, MqttOptions,
    Packet, QoS, StateError, SubscribeFilter, TlsConfiguration, Transport,
};
use std::collections::BTreeSet;
use std::path::PathBuf;
use std::time::{Duration, Instant};
use tracing::warn;

/// Where to connect and what to subscribe to first. The subscription's identity: a change
/// reconnects (the CAN topics shown later go through [`Control`], on the live connection).
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct Settings {
    pub host: String,
    pub port: u16,
    pub credentials: Option<(String, String)>,
    /// TLS, trusting the certificates in this PEM file (the pit listener is TLS-only).
    pub tls_ca: Option<PathBuf>,
    /// `aer/<car>`.
    pub prefix: String,
    /// The CAN topics (below the prefix) the pit view shows when the link starts.
    pub can: Vec<&'static str>,
    /// Telemetry and CAN from the compact stream or the JSON topics.
    pub format: StreamFormat,
    /// How far back a pit that joins asks for history (s).
    pub join_history_s: u64,
}

/// What the link hands the application: first the [`Control`] to steer it with, then every
/// update with the time it arrived.
#[derive(Debug, Clone)]
pub enum Event {
    Ready(Control),
    Update(Instant, Update),
}

/// The application's side of the link (iced's worker pattern: the link hands back a sender):
/// which CAN topics the pit view shows now. The link subscribes to the new ones and
/// unsubscribes from the others on the live connection, without reconnecting; every new
/// connection subscribes to the picks of the moment.
#[derive(Debug, Clone)]
pub struct Control(mpsc::UnboundedSender<Request>);

/// What the application asks of the link.
#[derive(Debug, Clone, PartialEq)]
pub enum Request {
    /// Show exactly these CAN topics (suffixes below the car's prefix).
    ShowCan(Vec<&'static str>),
    /// Send the Pi a lap mark, stored in the running session.
    Mark(Mark),
}

impl Control {
    /// A control and the receiving end the link reads (tests drive an application with it).
    pub fn channel() -> (Self, mpsc::UnboundedReceiver<Request>) {
        let (sender, receiver) = mpsc::unbounded();
        (Self(sender), receiver)
    }

    /// Shows exactly `suffixes` (below the car's prefix) from now on. A link that has ended
    /// (the dashboard closing) ignores it.
    pub fn show_can(&self, suffixes: impl IntoIterator<Item = &'static str>) {
        let _ = self
            .0
            .unbounded_send(Request::ShowCan(suffixes.into_iter().collect()));
    }

    /// Sends the Pi `mark` (queued while the link reconnects).
    pub fn mark(&self, mark: Mark) {
        let _ = self.0.unbounded_send(Request::Mark(mark));
    }
}

/// What the link subscribes to: the base topics and the CAN topics the application picks. It
/// owns the picks and the client's subscriptions, on a task of its own: the application's
/// picks and the connection's arrivals come to it as messages, so nothing is shared and the
/// connection's polling is never interrupted.
struct Subscriptions {
    client: AsyncClient,
    prefix: String,
    base: Vec<String>,
    shown: BTreeSet<&'static str>,
    /// Whether the broker has accepted the current connection (picks go out at once).
    live: bool,
    /// The compact stream carries every CAN message: picks subscribe to nothing.
    compact: bool,
}

impl Subscriptions {
    async fn run(
        mut self,
        mut picks: mpsc::UnboundedReceiver<Request>,
        mut connections: mpsc::UnboundedReceiver<bool>,
    ) {
        loop {
            tokio::select! {
                connection = connections.next() => match connection {
                    Some(true) => self.connected(),
                    Some(false) => self.live = false,
                    // The link has ended.
                    None => return,
                },
                Some(request) = picks.next() => match request {
                    Request::ShowCan(wanted) => self.show(wanted),
                    Request::Mark(mark) => self.send_mark(&mark),
                },
            }
        }
    }

    /// A clean session forgets subscriptions: subscribes a new connection to every topic, in
    /// one request (the client's queue holds 16, so this never waits on the link).
    fn connected(&mut self) {
        self.live = true;
        let can = self
            .shown
            .iter()
            .filter(|_| !self.compact)
            .map(|suffix| format!("{}/{suffix}", self.prefix));
        let all = self.base.iter().cloned().chain(can);
        if let Err(error) = self
            .client
            .try_subscribe_many(all.map(|topic| SubscribeFilter::new(topic, QoS::AtMostOnce)))
        {
            warn!(%error, "subscribing a new connection");
        }
    }

    /// Publishes a lap mark for the Pi (at least once: a repeat is a second mark at the same
    /// instant, which ends no lap of its own).
    fn send_mark(&self, mark: &Mark) {
        let topic = aer_host::link::marks::topic(&self.prefix);
        if let Err(error) =
            self.client
                .try_publish(topic, QoS::AtLeastOnce, false, mark.to_payload())
        {
            warn!(%error, "sending the Pi a lap mark");
        }
    }

    /// Shows `wanted` from now on: on a live connection, subscribes to the new topics and
    /// unsubscribes from the others.
    fn show(&mut self, wanted: Vec<&'static str>) {
        let wanted: BTreeSet<&'static str> = wanted.into_iter().collect();
        if self.live && !self.compact {
            let prefix = &self.prefix;
            let added: Vec<_> = wanted
                .difference(&self.shown)
                .map(|suffix| SubscribeFilter::new(format!("{prefix}/{suffix}"), QoS::AtMostOnce))
                .collect();
            // The client's queue holds 16 requests and the link drains it as it runs, so a
            // request only fails to fit when the link is stuck; it is logged, and the next
            // connection subscribes to every pick.
            if !added.is_empty()
                && let Err(error) = self.client.try_subscribe_many(added)
            {
                warn!(%error, "subscribing to a CAN topic the pit view shows");
            }
            for suffix in self.shown.difference(&wanted) {
                if let Err(error) = self.client.try_unsubscribe(format!("{prefix}/{suffix}")) {
                    warn!(%error, "unsubscribing from a CAN topic the pit view no longer shows");
                }
            }
        }
        self.shown = wanted;
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
            tls_ca: config.mqtt.tls_ca.clone(),
            prefix: config.topic_prefix(),
            can: CanMessages::new(&config.display.can_messages).suffixes(),
            format: config.link.stream,
            join_history_s: config.link.join_history_s,
        }
    }

    /// The topics the dashboard always reads: the compact stream (which carries every CAN
    /// message), or the telemetry topic (CAN topics then come and go with the pit view).
    pub fn topics(&self) -> Vec<String> {
        let mut topics = match self.format {
            StreamFormat::Compact => vec![aer_host::formats::pit_stream::topic(&self.prefix)],
            // The PCC's status always: the driver's display names its latched causes (the
            // compact stream carries it with every other frame).
            StreamFormat::Json => vec![
                TELEMETRY.path(&self.prefix),
                aer::mqtt::can::PCC_STATUS.path(&self.prefix),
            ],
        };
        topics.extend([STATUS.path(&self.prefix), METRICS.path(&self.prefix)]);
        topics
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

/// The link's events (its [`Control`] first, then updates from the broker, each with the time
/// it arrived) for as long as the stream is polled. Runs on the dashboard's async executor
/// (tokio).
pub fn stream(settings: Settings) -> impl Stream<Item = Event> {
    iced::stream::channel(256, async move |mut output: mpsc::Sender<Event>| {
        let (control, picks) = Control::channel();
        if output.send(Event::Ready(control)).await.is_err() {
            return;
        }
        // Unique per process, so the driver and pit dashboards never take over each other's
        // session; also the name of this dashboard's history answers.
        let client_id = format!(
            "aer-dashboard-{}-{}",
            std::process::id(),
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.subsec_nanos())
        );
        let (client, mut eventloop) = match connect(&settings, &client_id) {
            Ok(connection) => connection,
            Err(why) => {
                // Nothing to retry: the settings are wrong until the dashboard restarts.
                let update = Update::Disconnected(why);
                let _ = output.send(Event::Update(Instant::now(), update)).await;
                return;
            }
        };
        let identity = Update::Identity(client_id.clone());
        if output
            .send(Event::Update(Instant::now(), identity))
            .await
            .is_err()
        {
            return;
        }
        let mut backfill = (settings.format == StreamFormat::Compact)
            .then(|| Backfill::new(&settings.prefix, &client_id, settings.join_history_s));
        let mut base = settings.topics();
        base.extend(backfill.as_ref().map(Backfill::reply_topic));
        let requests = client.clone();
        let (connections, connection_events) = mpsc::unbounded();
        let subscriptions = Subscriptions {
            client,
            prefix: settings.prefix.clone(),
            base,
            shown: settings.can.iter().copied().collect(),
            live: false,
            compact: settings.format == StreamFormat::Compact,
        };
        tokio::spawn(subscriptions.run(picks, connection_events));
        let mut accepted = false;
        let mut decoder = StreamDecoder::default();
        let mut updates = Vec::new();
        loop {
            let was_accepted = accepted;
            let request = next(
                &mut eventloop,
                &mut accepted,
                &settings,
                &mut decoder,
                backfill.as_mut(),
                &mut updates,
            )
            .await;
            if let (Some(request), Some(backfill)) = (request, &backfill)
                && let Err(error) =
                    requests.try_publish(backfill.request_topic(), QoS::AtMostOnce, false, request)
            {
                // Asked again when the answer stays away.
                warn!(%error, "asking the Pi for missed history");
            }
            let failed = matches!(updates.last(), Some(Update::Disconnected(_)));
            // The subscriptions follow the connection (their task ends with this loop).
            if accepted != was_accepted {
                let _ = connections.unbounded_send(accepted);
            }
            let arrived = Instant::now();
            for update in updates.drain(..) {
                // Waits while the screen catches up; the broker then holds (or, beyond its
                // segments, drops) messages, which show up as lost packets.
                if output.send(Event::Update(arrived, update)).await.is_err() {
                    return;
                }
            }
            if failed {
                tokio::time::sleep(Duration::from_secs(1)).await;
            }
        }
    })
}

/// The client and its event loop, or why the settings cannot work (an unreadable CA file).
fn connect(settings: &Settings, client_id: &str) -> Result<(AsyncClient, EventLoop), String> {
    let mut options = MqttOptions::new(client_id, settings.host.clone(), settings.port);
    options.set_keep_alive(Duration::from_secs(5));
    options.set_max_packet_size(64 * 1024, 64 * 1024);
    if let Some((user, password)) = &settings.credentials {
        options.set_credentials(user.clone(), password.clone());
    }
    if let Some(trusted) = &settings.tls_ca {
        let config = aer_host::link::tls::client_config(trusted)
            .map_err(|error| format!("TLS cannot start: {error} (AER_MQTT_TLS_CA)"))?;
        options.set_transport(Transport::tls_with_config(TlsConfiguration::Rustls(config)));
    }
    Ok(AsyncClient::new(options, 16))
}

/// Polls the connection once: the updates for the screens go into `out` (none for protocol
/// traffic, many for a batch of the compact stream). `accepted` tracks whether the broker has
/// accepted the current connection. Returns a history request to publish, if one is due.
async fn next(
    eventloop: &mut EventLoop,
    accepted: &mut bool,
    settings: &Settings,
    decoder: &mut StreamDecoder,
    mut backfill: Option<&mut Backfill>,
    out: &mut Vec<Update>,
) -> Option<Vec<u8>> {
    let mut request = None;
    match eventloop.poll().await {
        Ok(MqttEvent::Incoming(Packet::ConnAck(_))) => *accepted = true,
        // Connected means subscribed: nothing published from here on is missed.
        Ok(MqttEvent::Incoming(Packet::SubAck(_))) => {
            out.push(Update::Connected);
            request = backfill.as_deref_mut().and_then(Backfill::reconnected);
        }
        Ok(MqttEvent::Incoming(Packet::Publish(publish))) => {
            let stream = publish.topic == aer_host::formats::pit_stream::topic(&settings.prefix);
            if stream {
                let received = decoder.decode(&publish.topic, &publish.payload, out);
                if let (Some(received), Some(backfill)) = (received, backfill.as_deref_mut()) {
                    request = backfill.live(received);
                    out.push(Update::Backfill(backfill.progress()));
                }
            } else if let Some(backfill) = backfill
                .as_deref_mut()
                .filter(|b| publish.topic == b.reply_topic())
            {
                request = backfill.history(&publish.topic, &publish.payload, out);
                out.push(Update::Backfill(backfill.progress()));
            } else {
                let update = decode(&settings.prefix, &publish.topic, &publish.payload);
                if let (Update::Metrics(metrics), Some(backfill)) = (&update, backfill) {
                    let now_us = std::time::SystemTime::now()
                        .duration_since(std::time::UNIX_EPOCH)
                        .map_or(0, |d| d.as_micros() as u64);
                    request = backfill.published(metrics.counters.pit_batches, now_us);
                }
                out.push(update);
            }
        }
        Ok(_) => {}
        Err(error) => {
            let reason = why_down(&error, *accepted, settings);
            *accepted = false;
            out.push(Update::Disconnected(reason));
        }
    }
    request
}

/// Why the link is down, in words the pit crew can act on.
fn why_down(error: &ConnectionError, accepted: bool, settings: &Settings) -> String {
    let tls = settings.tls_ca.is_some();
    if let Some(failure) = aer_host::link::tls::tls_failure(error) {
        return aer_host::link::tls::explain(failure, &settings.host, "AER_MQTT_TLS_CA");
    }
    match error {
        // The gate answers a CONNECT sent in the clear to a TLS listener with "not
        // authorised" (MQTT 3.1.1 has no code for "use TLS").
        ConnectionError::ConnectionRefused(ConnectReturnCode::NotAuthorized) if !tls => {
            "the listener refused a connection without TLS: the pit listener speaks only TLS \
             (set AER_MQTT_TLS_CA to the team's CA, docs/dashboard.md)"
                .into()
        }
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
