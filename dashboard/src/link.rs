//! The MQTT link: subscribes to the car's typed topics on the Pi's broker and turns every
//! message into an [`Update`], decoded with the topic's own payload type. The connection is
//! retried every second for as long as the dashboard runs; every loss is reported, so the
//! screens can show it.

use crate::config::Config;
use crate::model::Update;
use aer::mqtt::TELEMETRY;
use aer_host::status::{METRICS, STATUS};
use iced::futures::channel::mpsc;
use iced::futures::{SinkExt, Stream};
use rumqttc::{
    AsyncClient, ConnectReturnCode, ConnectionError, Event, EventLoop, MqttOptions, Packet, QoS,
    StateError, SubscribeFilter,
};
use std::time::{Duration, Instant};

/// Where to connect and what to subscribe to. Part of the subscription's identity: a change
/// reconnects.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct Settings {
    pub host: String,
    pub port: u16,
    pub credentials: Option<(String, String)>,
    /// `aer/<car>`.
    pub prefix: String,
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
        }
    }

    /// The topics the dashboard reads.
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
        _ => undecodable("not a topic the dashboard subscribed to".into()),
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
            let filters = settings
                .topics()
                .into_iter()
                .map(|topic| SubscribeFilter::new(topic, QoS::AtMostOnce));
            match client.try_subscribe_many(filters) {
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
