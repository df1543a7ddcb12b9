//! Publishes records on the generated typed topics, with a counted drop policy: the queue to
//! the broker is bounded, and a record that does not fit is dropped and counted rather than
//! stalling decoding (the local store still gets it).
//!
//! Into the embedded broker the publisher uses rumqttd's in-process link: a publish is a push
//! onto the router's queue. Through rumqttc and loopback TCP, every message cost a system call
//! on each side and two more thread hand-offs, a third of the pipeline's time on one core. A
//! broker elsewhere (`embedded_broker = false`) is reached with rumqttc, its event loop in its
//! own task.

use crate::broker;
use crate::health::Health;
use aer::mqtt::{TELEMETRY, TelemetryRecord, Topic, encode_message};
use aer_host::clock::seconds;
use aer_host::config::BrokerConfig;
use aer_host::decode::Record;
use aer_host::reports::counters::{Counters, worth_logging};
use rumqttc::{AsyncClient, Event, EventLoop, MqttOptions, Packet, QoS};
use rumqttd::local::{LinkRx, LinkTx};
use serde::Serialize;
use std::sync::Arc;
use std::sync::Mutex;
use std::time::Duration;
use tracing::{error, info, warn};

/// Sends records to the broker.
#[derive(Clone)]
pub struct Publisher {
    connection: Connection,
    prefix: String,
    /// The telemetry topic under the prefix, built once: it carries every packet.
    telemetry_topic: bytes::Bytes,
    counters: Arc<Counters>,
}

#[derive(Clone)]
enum Connection {
    /// The embedded broker's router, in process; the notification ends [`drive`].
    Embedded(Arc<Mutex<EmbeddedLink>>, Arc<tokio::sync::Notify>),
    /// A broker over TCP (rumqttc; its event loop runs in [`drive`]).
    Remote(AsyncClient),
}

struct EmbeddedLink {
    tx: LinkTx,
    /// Messages that may wait for the router before new ones are dropped.
    queue: usize,
    /// The newest record, queued at the next flush: it carries the router's wake-up.
    held: Option<rumqttd::protocol::Packet>,
}

impl EmbeddedLink {
    /// Queues `packet`: with `wake`, it goes now and wakes the router for everything queued;
    /// without, it is held until the next message or [`Self::flush`]. Waking the router for
    /// each message of a burst cost a context switch each (the woken router preempts the
    /// pipeline); the router takes the whole queue at each wake-up.
    fn queue(&mut self, packet: rumqttd::protocol::Packet, wake: bool) -> bool {
        let mut waiting = self.tx.buffer();
        // The link's queue is unbounded: bound it here.
        if waiting.len() >= self.queue {
            return false;
        }
        if let Some(held) = self.held.take() {
            waiting.push_back(held);
        }
        drop(waiting);
        if wake {
            push(&mut self.tx, packet)
        } else {
            self.held = Some(packet);
            true
        }
    }

    /// Queues the held message and wakes the router.
    fn flush(&mut self) -> bool {
        self.held
            .take()
            .is_none_or(|packet| push(&mut self.tx, packet))
    }
}

/// What keeps a publisher's connection going: run it with [`drive`].
pub enum Driver {
    /// Reads what the embedded broker's router sends back on the in-process link, until the
    /// publisher disconnects.
    Embedded(Box<EmbeddedDriver>),
    /// The rumqttc event loop.
    Remote(Box<RemoteDriver>),
}

/// Where the connection hands what arrives on one topic (the pits' history requests, the
/// dashboards' lap marks): a bounded queue; what does not fit is dropped, counted in
/// `refused`'s counter.
pub struct Intake {
    pub filter: String,
    pub sender: tokio::sync::mpsc::Sender<Vec<u8>>,
    pub counters: Arc<Counters>,
    /// The counter of what did not fit.
    pub refused: fn(&Counters) -> &std::sync::atomic::AtomicU64,
}

impl Intake {
    fn deliver(&self, payload: &[u8]) {
        if self.sender.try_send(payload.to_vec()).is_err() {
            let count = Counters::bump((self.refused)(&self.counters));
            if worth_logging(count) {
                warn!(
                    count,
                    filter = %self.filter,
                    "messages arrive faster than they are served: refused"
                );
            }
        }
    }
}

/// Hands a message that arrived on `topic` to the intake of that topic.
fn deliver(intakes: &[Intake], topic: &[u8], payload: &[u8]) {
    if let Some(intake) = intakes.iter().find(|i| i.filter.as_bytes() == topic) {
        intake.deliver(payload);
    }
}

impl Driver {
    /// Subscribes the connection to `intake.filter` and hands what arrives there to it.
    pub fn with_intake(self, intake: Intake) -> Self {
        match self {
            Self::Embedded(mut driver) => {
                if let Ok(mut link) = driver.link.lock()
                    && let Err(error) = link.tx.subscribe(intake.filter.clone())
                {
                    warn!(%error, filter = %intake.filter, "could not subscribe");
                }
                driver.intakes.push(intake);
                Self::Embedded(driver)
            }
            Self::Remote(mut driver) => {
                driver.intakes.push(intake);
                Self::Remote(driver)
            }
        }
    }
}

/// The rumqttc event loop, and the client to subscribe with after each connection.
pub struct RemoteDriver {
    eventloop: EventLoop,
    client: AsyncClient,
    intakes: Vec<Intake>,
}

/// A publisher into the embedded broker over its in-process `link`; should the broker drop
/// that link, the publisher switches to one of the `spares`.
pub fn embedded(
    link: broker::Link,
    spares: Vec<broker::Link>,
    queue: usize,
    prefix: String,
    counters: Arc<Counters>,
    health: Arc<Health>,
) -> (Publisher, Driver) {
    let closed = Arc::new(tokio::sync::Notify::new());
    let shared = Arc::new(Mutex::new(EmbeddedLink {
        tx: link.tx,
        queue: queue.max(1),
        held: None,
    }));
    let connection = Connection::Embedded(shared.clone(), closed.clone());
    (
        Publisher::new(connection, prefix, counters),
        Driver::Embedded(Box::new(EmbeddedDriver {
            rx: link.rx,
            link: shared,
            spares,
            closed,
            health,
            intakes: Vec::new(),
        })),
    )
}

/// What keeps the embedded link going: reads what the router sends back, and replaces the
/// link if the router drops it.
pub struct EmbeddedDriver {
    rx: LinkRx,
    link: Arc<Mutex<EmbeddedLink>>,
    spares: Vec<broker::Link>,
    closed: Arc<tokio::sync::Notify>,
    health: Arc<Health>,
    intakes: Vec<Intake>,
}

/// A publisher to the broker `config` names, over TCP (TLS when `config.tls_ca` names the
/// trusted certificates), queueing up to `queue` messages. It connects lazily: [`drive`]
/// connects, and reconnects after a failure. Fails only if the trusted certificates cannot
/// be read.
pub fn connect(
    config: &BrokerConfig,
    queue: usize,
    client_id: &str,
    prefix: String,
    counters: Arc<Counters>,
) -> Result<(Publisher, Driver), aer_host::link::tls::TlsSetupError> {
    let mut options = MqttOptions::new(client_id, config.host.clone(), config.port);
    options.set_keep_alive(Duration::from_secs(5));
    options.set_max_packet_size(64 * 1024, 64 * 1024);
    if let (Some(user), Some(password)) = (&config.username, &config.password) {
        options.set_credentials(user.clone(), password.clone());
    }
    if let Some(trusted) = &config.tls_ca {
        let tls = aer_host::link::tls::client_config(trusted)?;
        options.set_transport(rumqttc::Transport::tls_with_config(
            rumqttc::TlsConfiguration::Rustls(tls),
        ));
    }
    let (client, mut eventloop) = AsyncClient::new(options, queue.max(1));
    // Without TCP_NODELAY, Nagle's algorithm holds small publishes back for up to the peer's
    // delayed-ACK time (~40 ms).
    let mut network = eventloop.network_options();
    network.set_tcp_nodelay(true);
    eventloop.set_network_options(network);
    Ok((
        Publisher::new(Connection::Remote(client.clone()), prefix, counters),
        Driver::Remote(Box::new(RemoteDriver {
            eventloop,
            client,
            intakes: Vec::new(),
        })),
    ))
}

/// Keeps the publisher's connection going until it is closed; `connected` is set on every
/// (re)connection.
///
/// Remote: polls the rumqttc event loop in its own task (publishing from the polling task would
/// deadlock once the queue fills: rumqtt issue #263); connection errors are logged and retried
/// after a second; after a disconnect the loop ends once the broker has closed the connection.
/// Embedded: reads (and discards) what the router sends back until the publisher disconnects
/// (the link itself stays open: the router logs errors when a local link disconnects).
pub async fn drive(driver: Driver, connected_tx: tokio::sync::watch::Sender<bool>) {
    match driver {
        Driver::Embedded(mut driver) => {
            let _ = connected_tx.send(true);
            loop {
                tokio::select! {
                    () = driver.closed.notified() => return,
                    received = driver.rx.next() => match received {
                        Ok(Some(rumqttd::Notification::Forward(forward))) => {
                            deliver(&driver.intakes, &forward.publish.topic, &forward.publish.payload);
                        }
                        // The router paused forwarding (the link's buffer filled): resume.
                        Ok(Some(rumqttd::Notification::Unschedule)) => {
                            let _ = driver.rx.ready();
                        }
                        Ok(_) => {}
                        Err(_) => if !driver.replace() {
                            return;
                        },
                    },
                }
            }
        }
        Driver::Remote(driver) => drive_remote(*driver, connected_tx).await,
    }
}

async fn drive_remote(driver: RemoteDriver, connected_tx: tokio::sync::watch::Sender<bool>) {
    let RemoteDriver {
        mut eventloop,
        client,
        intakes,
    } = driver;
    let mut connected = false;
    let mut closing = false;
    loop {
        match eventloop.poll().await {
            Ok(Event::Incoming(Packet::ConnAck(_))) => {
                connected = true;
                let _ = connected_tx.send(true);
                info!("connected to the MQTT broker");
                // A clean session forgets subscriptions: subscribe on every connection.
                for intake in &intakes {
                    if let Err(error) = client.try_subscribe(&intake.filter, QoS::AtMostOnce) {
                        warn!(%error, filter = %intake.filter, "could not subscribe");
                    }
                }
            }
            Ok(Event::Incoming(Packet::Publish(publish))) => {
                deliver(&intakes, publish.topic.as_bytes(), &publish.payload);
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

impl EmbeddedDriver {
    /// The router dropped the link (another connection took its id): switches the publisher
    /// to a spare. False when none is left.
    fn replace(&mut self) -> bool {
        let Some(spare) = self.spares.pop() else {
            self.health.mqtt.failed(
                "the broker dropped the service's link and no spare is left: nothing is published",
            );
            error!("the embedded broker dropped the service's link; no spare left");
            return false;
        };
        if let Ok(mut link) = self.link.lock() {
            link.tx = spare.tx;
            link.held = None;
            for intake in &self.intakes {
                if let Err(error) = link.tx.subscribe(intake.filter.clone()) {
                    warn!(%error, filter = %intake.filter, "could not subscribe the spare link");
                }
            }
        }
        self.rx = spare.rx;
        self.health.mqtt.failed(&format!(
            "the broker dropped the service's link; publishing on a spare ({} left)",
            self.spares.len()
        ));
        warn!(
            spares = self.spares.len(),
            "the embedded broker dropped the service's link; switched to a spare"
        );
        true
    }
}

impl Publisher {
    fn new(connection: Connection, prefix: String, counters: Arc<Counters>) -> Self {
        Self {
            telemetry_topic: TELEMETRY.path(&prefix).into(),
            connection,
            prefix,
            counters,
        }
    }

    /// Publishes one record on its typed topic (`buses` names the bus numbers records carry).
    /// Into the embedded broker, the newest record goes out with the next one or at
    /// [`Self::flush`]: call it before waiting for input.
    pub fn publish(&self, record: &Record, buses: &[Arc<str>]) {
        let (topic, payload) = match record {
            Record::Telemetry {
                ts_us,
                header,
                telemetry,
                ..
            } => {
                let record = TelemetryRecord {
                    header: *header,
                    telemetry: **telemetry,
                };
                (
                    self.telemetry_topic.clone(),
                    record.to_json(seconds(*ts_us)),
                )
            }
            Record::Can {
                ts_us,
                bus,
                message,
                ..
            } => {
                let bus = crate::bus_names::bus_name(buses, *bus);
                let (suffix, payload) = encode_message(message, seconds(*ts_us), &bus);
                (format!("{}/{suffix}", self.prefix).into(), payload)
            }
        };
        self.send(topic, payload, false, false);
    }

    /// True while the broker's queue is less than half full: what can wait (history for a
    /// pit) waits for this, so it never takes the live records' room. Always true for a
    /// broker elsewhere (its client's queue is not visible).
    pub fn has_room(&self) -> bool {
        match &self.connection {
            Connection::Embedded(link, _) => link
                .lock()
                .is_ok_and(|link| link.tx.buffer().len() < link.queue / 2),
            Connection::Remote(_) => true,
        }
    }

    /// Hands every published record to the broker now.
    pub fn flush(&self) {
        if let Connection::Embedded(link, _) = &self.connection
            && !link.lock().is_ok_and(|mut link| link.flush())
        {
            let count = Counters::bump(&self.counters.publish_dropped);
            if worth_logging(count) {
                warn!(count, "the embedded broker is gone: message dropped");
            }
        }
    }

    /// Sends everything queued, then disconnects ([`drive`] then ends).
    pub(crate) async fn disconnect(&self) {
        match &self.connection {
            Connection::Remote(client) => {
                let _ = client.disconnect().await;
            }
            Connection::Embedded(_, closed) => {
                self.flush();
                closed.notify_one();
            }
        }
    }

    /// Publishes any JSON value on `<prefix>/<suffix>` (outside the typed topics: the retained
    /// `schema/...` descriptions, probes and the benchmark's stand-in for today's payload).
    pub fn publish_json(&self, suffix: &str, value: &impl Serialize, retain: bool) {
        if let Ok(payload) = serde_json::to_vec(value) {
            self.send(
                format!("{}/{suffix}", self.prefix).into(),
                payload,
                retain,
                true,
            );
        }
    }

    /// Publishes a binary `payload` on `topic` now (the pit stream's batches, outside the
    /// car's JSON topics).
    pub fn publish_bytes(&self, topic: &str, payload: Vec<u8>) {
        self.send(
            bytes::Bytes::copy_from_slice(topic.as_bytes()),
            payload,
            false,
            true,
        );
    }

    /// Publishes `value` on `topic`, typed by the topic.
    pub fn publish_on<P: Serialize>(&self, topic: &Topic<P>, value: &P, retain: bool) {
        match topic.encode(value) {
            Ok(payload) => self.send(topic.path(&self.prefix).into(), payload, retain, true),
            Err(error) => {
                let count = Counters::bump(&self.counters.publish_dropped);
                warn!(%error, count, topic = topic.suffix(), "payload could not be serialised");
            }
        }
    }

    fn send(&self, topic: bytes::Bytes, payload: Vec<u8>, retain: bool, wake: bool) {
        let accepted = match &self.connection {
            // Topics are built from UTF-8 strings, so the conversion cannot fail.
            Connection::Remote(client) => std::str::from_utf8(&topic).is_ok_and(|topic| {
                client
                    .try_publish(topic, QoS::AtMostOnce, retain, payload)
                    .is_ok()
            }),
            Connection::Embedded(link, _) => link.lock().is_ok_and(|mut link| {
                let packet = rumqttd::protocol::Packet::Publish(
                    rumqttd::protocol::Publish::new(topic, bytes::Bytes::from(payload), retain),
                    None,
                );
                link.queue(packet, wake)
            }),
        };
        if accepted {
            Counters::bump(&self.counters.published);
        } else {
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

/// Queues `packet` for the router and wakes it. `LinkTx::send` is the one public way to queue
/// any packet with a wake-up (`try_publish` cannot retain); it has no await point, so one poll
/// runs it to the end. Were it ever pending, the packet would still be queued, taken with the
/// next wake.
fn push(tx: &mut LinkTx, packet: rumqttd::protocol::Packet) -> bool {
    let mut send = std::pin::pin!(tx.send(packet));
    let mut context = std::task::Context::from_waker(std::task::Waker::noop());
    !matches!(
        send.as_mut().poll(&mut context),
        std::task::Poll::Ready(Err(_))
    )
}

impl super::Sink for Publisher {
    fn accept(&mut self, record: &Record, buses: &[Arc<str>]) {
        self.publish(record, buses);
    }

    fn flush(&mut self) {
        Publisher::flush(self);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_message_goes_to_the_intake_of_its_topic_and_an_overflow_is_counted() {
        let counters = Arc::new(Counters::default());
        let (history, mut requests) = tokio::sync::mpsc::channel(1);
        let (marks, mut marked) = tokio::sync::mpsc::channel(1);
        let intakes = [
            Intake {
                filter: "aer-pit/car1/history/request".into(),
                sender: history,
                counters: counters.clone(),
                refused: |c| &c.history_refused,
            },
            Intake {
                filter: "aer-pit/car1/marks".into(),
                sender: marks,
                counters: counters.clone(),
                refused: |c| &c.marks_refused,
            },
        ];
        deliver(&intakes, b"aer-pit/car1/marks", b"mark 1");
        deliver(&intakes, b"aer-pit/car1/marks", b"mark 2");
        deliver(&intakes, b"aer/car1/telemetry", b"not for an intake");
        assert_eq!(marked.try_recv().ok(), Some(b"mark 1".to_vec()));
        assert!(requests.try_recv().is_err(), "nothing for the history task");
        let seen = counters.snapshot();
        assert_eq!((seen.marks_refused, seen.history_refused), (1, 0));
    }
}
