//! The gate: every MQTT client reaches the embedded broker through it, because rumqttd has no
//! access control of its own. The broker itself listens only on loopback, on a port and with
//! a password only the gate knows. For each client the gate
//! - checks the listener's credentials and refuses the service's own client ids (a client
//!   with the same id would take the service's link off the broker);
//! - refuses a will, and disconnects any publish, under the protected topic prefix: only the
//!   service publishes there, but for the few topics open to clients (the pits' history
//!   requests, which the service reads and checks);
//! - caps the keep-alive, so a dead client's slot frees within a minute and a half;
//! - waits for the broker's CONNACK before relaying anything, even if the client has gone
//!   meanwhile, and never offers the broker again a client id it did not acknowledge.
//!   rumqttd 0.20 keeps a will handler per client id; when a connection fails between its
//!   CONNECT and CONNACK the handler is left behind, and the next connection with that id
//!   panics on it while holding the handlers' lock. That poisons the lock, and from then on
//!   every new connection panics: the pit could no longer connect until the service restarted.
//!   Waiting for the CONNACK keeps a client that leaves while connecting from causing it; an
//!   id the broker still did not acknowledge (no room, no answer) is rewritten from then on
//!   (`<id>-gate<serial>`, a new one each time);
//! - keeps what a client has not taken in its own bounded queue
//!   (`broker/client_queue.rs`), whose age is the client's lag. On a network
//!   listener the gate reads the broker without waiting on the client, so the connection
//!   behind the gate never backs up, and a client that cannot keep up gets the newest live
//!   data, the rest dropped and counted (`mqtt_client_dropped`, and per client on the status).
//!   On loopback (the car's display, tools on the Pi) a client gets everything: with its queue
//!   full the gate stops reading the broker for it;
//! - disconnects a client that stops reading altogether, and at the connection limit makes
//!   room by disconnecting one that stalled;
//! - serves MQTT 5 clients by rewriting their packets to 3.1.1 and back
//!   (`broker/mqtt5.rs`), so the same rules apply to both;
//! - speaks TLS on listeners that have certificates.
//!
//! Everything refused is counted (`mqtt_refused`, `mqtt_slow_clients`) and logged, before the
//! client is told: what a refused client saw is already in the service's status.

use super::client_queue::ClientQueue;
use super::mqtt5::{self, Unsubscribes};
use super::packet::{self, CONNACK, CONNECT, Connect, PUBLISH, Refusal, Version};
use super::tls;
use aer_host::reports::counters::{Counters, worth_logging};
use aer_host::reports::status::MqttClient;
use std::collections::{HashMap, HashSet};
use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio_util::sync::CancellationToken;
use tracing::{debug, info, warn};

/// A listener clients connect to.
#[derive(Debug, Clone)]
pub struct Listener {
    pub name: String,
    pub listen: SocketAddr,
    /// Users and passwords; `None` (loopback only) lets anyone subscribe.
    pub auth: Option<HashMap<String, String>>,
    /// Certificate and key (PEM): TLS on this listener.
    pub tls: Option<tls::Files>,
    /// A client that falls behind gets the newest live data, its oldest dropped (network
    /// listeners: a pit's radio). Otherwise (loopback: the car's display, tools on the Pi) it
    /// gets everything and the broker waits for it, its backlog still bounded and measured.
    pub newest_first: bool,
}

/// How the gate treats clients.
#[derive(Debug, Clone)]
pub struct Settings {
    pub listeners: Vec<Listener>,
    /// The broker's own (loopback) listener, and the credentials it accepts.
    pub broker: SocketAddr,
    pub broker_user: String,
    pub broker_password: String,
    /// Topic roots only the service may publish under (`aer/`, and the pit stream's
    /// `aer-pit/`).
    pub protected: Vec<String>,
    /// Topics under those roots that clients may publish on: the pits' history requests
    /// (`aer-pit/<car>/history/request`) and the dashboards' lap marks (`aer-pit/<car>/marks`).
    pub open: Vec<String>,
    /// Client ids only the service may use (`aer-raspi`).
    pub reserved_ids: String,
    /// Clients at once, beyond which a stalled one makes room or the newcomer is refused.
    pub max_clients: usize,
    /// A client that has not taken data for this long is disconnected.
    pub stall_limit: Duration,
    /// Live messages that waited longer than this for their client are dropped.
    pub max_lag: Duration,
    /// The most the gate holds for one client (bytes).
    pub max_queue_bytes: usize,
    /// Keep-alive asked for by clients is capped at this (0, "never", included).
    pub max_keep_alive_s: u16,
    /// How long the broker has to acknowledge a connection.
    pub connack_timeout: Duration,
}

/// The connected clients: for the connection limit, and for the status.
pub struct Clients {
    started: Instant,
    by_id: Mutex<ClientTable>,
}

#[derive(Default)]
struct ClientTable {
    next: u64,
    by_id: HashMap<u64, Client>,
}

struct Client {
    client_id: String,
    listener: String,
    version: Version,
    load: Arc<ClientLoad>,
    /// Drops already reported on the status.
    dropped_reported: u64,
    disconnect: CancellationToken,
}

/// What the gate measures of one client while serving it.
#[derive(Default)]
struct ClientLoad {
    /// Since when a write to the client has been waiting (us since the gate started; 0 when
    /// none waits).
    stalled_since: AtomicU64,
    /// When the oldest message held for it came (us; 0 when none waits).
    oldest_us: AtomicU64,
    queued_bytes: AtomicU64,
    dropped: AtomicU64,
}

impl std::fmt::Debug for Clients {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let count = self.by_id.lock().map_or(0, |table| table.by_id.len());
        f.debug_struct("Clients")
            .field("connected", &count)
            .finish()
    }
}

impl Clients {
    fn now_us(&self) -> u64 {
        (self.started.elapsed().as_micros() as u64).max(1)
    }

    /// What the gate holds for the client `client_id` now (bytes), if it is connected.
    pub fn queued_for(&self, client_id: &str) -> Option<u64> {
        let table = self.by_id.lock().ok()?;
        table
            .by_id
            .values()
            .filter(|client| client.client_id == client_id)
            .map(|client| client.load.queued_bytes.load(Ordering::Relaxed))
            .max()
    }

    /// Every client now, with the live messages each lost since the previous call.
    pub fn snapshot(&self) -> Vec<(MqttClient, u64)> {
        let now = self.now_us();
        let Ok(mut table) = self.by_id.lock() else {
            return Vec::new();
        };
        let mut clients: Vec<(MqttClient, u64)> = table
            .by_id
            .values_mut()
            .map(|client| {
                let load = &client.load;
                let oldest = load.oldest_us.load(Ordering::Relaxed);
                let dropped = load.dropped.load(Ordering::Relaxed);
                let recent = dropped.saturating_sub(client.dropped_reported);
                client.dropped_reported = dropped;
                let lag_us = if oldest == 0 {
                    0
                } else {
                    now.saturating_sub(oldest)
                };
                (
                    MqttClient {
                        client_id: client.client_id.clone(),
                        listener: client.listener.clone(),
                        protocol: client.version.name().to_owned(),
                        lag_ms: lag_us / 1000,
                        queued_bytes: load.queued_bytes.load(Ordering::Relaxed),
                        dropped,
                    },
                    recent,
                )
            })
            .collect();
        clients.sort_by(|a, b| a.0.client_id.cmp(&b.0.client_id));
        clients
    }
}

struct Gate {
    settings: Settings,
    counters: Arc<Counters>,
    clients: Arc<Clients>,
    /// Client ids the broker did not acknowledge: never offered to it again.
    unacknowledged_ids: Mutex<HashSet<String>>,
    /// The serial in rewritten client ids.
    rewritten: AtomicU64,
    /// Clients refused for their protocol version (MQTT 5, 3.1).
    version_refusals: AtomicU64,
}

/// Binds every listener (so a taken port fails at start-up) and serves them until `cancel`;
/// the clients it serves, for the status.
pub async fn start(
    settings: Settings,
    counters: Arc<Counters>,
    cancel: CancellationToken,
) -> anyhow::Result<Arc<Clients>> {
    let mut bound = Vec::new();
    for listener in &settings.listeners {
        let socket = TcpListener::bind(listener.listen).await.map_err(|e| {
            anyhow::anyhow!(
                "broker listener `{}` on {}: {e}",
                listener.name,
                listener.listen
            )
        })?;
        let acceptor = listener.tls.as_ref().map(tls::acceptor).transpose()?;
        bound.push((socket, acceptor, listener.clone()));
    }
    let clients = Arc::new(Clients {
        started: Instant::now(),
        by_id: Mutex::new(ClientTable::default()),
    });
    let gate = Arc::new(Gate {
        settings,
        counters,
        clients: clients.clone(),
        unacknowledged_ids: Mutex::new(HashSet::new()),
        rewritten: AtomicU64::new(0),
        version_refusals: AtomicU64::new(0),
    });
    for (socket, acceptor, listener) in bound {
        let (gate, cancel) = (gate.clone(), cancel.clone());
        tokio::spawn(async move {
            info!(listener = listener.name, address = %listener.listen, tls = acceptor.is_some(), "MQTT listener open");
            loop {
                let accepted = tokio::select! {
                    accepted = socket.accept() => accepted,
                    () = cancel.cancelled() => return,
                };
                let Ok((stream, peer)) = accepted else {
                    continue;
                };
                let _ = stream.set_nodelay(true);
                // A small send buffer: a client that stops reading shows within a moment,
                // rather than after megabytes of kernel buffer.
                let _ = socket2::SockRef::from(&stream).set_send_buffer_size(CLIENT_SEND_BUFFER);
                let (gate, listener, acceptor) = (gate.clone(), listener.clone(), acceptor.clone());
                tokio::spawn(async move {
                    match acceptor {
                        Some(_) if sent_in_the_clear(&stream).await => {
                            // MQTT 3.1.1 has no code for "use TLS": "not authorised" (5),
                            // sent in the clear, is an answer the client can show.
                            // The CONNECT is read first: closing with it unread would
                            // reset the connection and could discard the answer.
                            let mut stream = stream;
                            let mut buffer = Vec::with_capacity(256);
                            let read = tokio::time::timeout(
                                HANDSHAKE,
                                read_packet(&mut stream, &mut buffer),
                            )
                            .await;
                            let version = match read {
                                Ok(Ok(Some((CONNECT, len)))) => {
                                    Connect::parse(buffer.get(..len).unwrap_or_default())
                                        .map_or(Version::V311, |connect| connect.version)
                                }
                                _ => Version::V311,
                            };
                            let refusal = packet::refusal(version, Refusal::NotAuthorised);
                            let _ = stream.write_all(&refusal).await;
                            let _ = stream.shutdown().await;
                            gate.refused(peer, "MQTT without TLS on a TLS listener");
                        }
                        Some(acceptor) => {
                            match tokio::time::timeout(HANDSHAKE, acceptor.accept(stream)).await {
                                Ok(Ok(stream)) => gate.serve(stream, &listener, peer).await,
                                _ => gate.refused(peer, "TLS handshake failed"),
                            }
                        }
                        None => gate.serve(stream, &listener, peer).await,
                    }
                });
            }
        });
    }
    Ok(clients)
}

/// True if the client's first byte opens an MQTT CONNECT (0x10) rather than a TLS record
/// (0x16): a client that forgot TLS. Waits at most the handshake time for that byte.
async fn sent_in_the_clear(stream: &TcpStream) -> bool {
    let mut first = [0u8; 1];
    matches!(
        tokio::time::timeout(HANDSHAKE, stream.peek(&mut first)).await,
        Ok(Ok(1))
    ) && first[0] == CONNECT << 4
}

/// Bytes the kernel may hold for a client before a write waits (Linux doubles it). Small, so
/// the backlog shows in the gate's queue, where it is measured, rather than hiding in the
/// kernel: 32 KiB is about a second of a 250 kbit/s radio, and still 13 Mbit/s at 20 ms.
const CLIENT_SEND_BUFFER: usize = 16 * 1024;

/// What the gate writes to a client at once, at most (one packet more may overrun it).
const WRITE_BATCH: usize = 16 * 1024;

/// The gate's receive buffer on its connection to the broker: the gate reads it at once
/// whatever the client does, so little is ever in it.
const BROKER_RECEIVE_BUFFER: u32 = 64 * 1024;

/// How long a new client has for TLS and its CONNECT.
const HANDSHAKE: Duration = Duration::from_secs(10);

impl Gate {
    fn refused(&self, peer: SocketAddr, why: &str) {
        let count = Counters::bump(&self.counters.mqtt_refused);
        if worth_logging(count) {
            warn!(%peer, why, count, "MQTT client refused");
        }
    }

    /// Refuses a CONNECT with the CONNACK of the client's version: counted first, so a client
    /// that has read its refusal finds it in the status already.
    async fn refuse_connect(
        &self,
        stream: &mut (impl AsyncWrite + Unpin),
        version: Version,
        refusal: Refusal,
        peer: SocketAddr,
        why: &str,
    ) {
        self.refused(peer, why);
        let _ = stream.write_all(&packet::refusal(version, refusal)).await;
    }

    fn now_us(&self) -> u64 {
        self.clients.now_us()
    }

    /// True for a topic under one of the service's roots.
    fn is_protected(&self, topic: &str) -> bool {
        self.settings
            .protected
            .iter()
            .any(|root| topic.starts_with(root.as_str()))
            && !self.settings.open.iter().any(|open| open == topic)
    }

    /// Checks a new client's CONNECT; the reason if it is refused.
    fn admit(&self, connect: &Connect, listener: &Listener) -> Result<(), (&'static str, Refusal)> {
        if connect.client_id.starts_with(&self.settings.reserved_ids) {
            return Err(("client id reserved for the service", Refusal::IdRejected));
        }
        if let Some(users) = listener.auth.as_ref().filter(|users| !users.is_empty()) {
            let matches = connect
                .username
                .as_ref()
                .and_then(|user| users.get(user))
                .is_some_and(|password| connect.password.as_deref() == Some(password.as_bytes()));
            if !matches {
                return Err(("bad username or password", Refusal::BadCredentials));
            }
        }
        if connect
            .will
            .as_ref()
            .is_some_and(|(topic, ..)| self.is_protected(topic))
        {
            return Err(("will under the service's topics", Refusal::NotAuthorised));
        }
        Ok(())
    }

    /// Makes room for one more client: true if there is (or now is) room.
    fn make_room(&self) -> bool {
        let Ok(clients) = self.clients.by_id.lock() else {
            return false;
        };
        if clients.by_id.len() < self.settings.max_clients {
            return true;
        }
        // A write pending for a second is a client that stopped reading, not a slow moment.
        let stalled_before = self.now_us().saturating_sub(1_000_000);
        let stalled = clients
            .by_id
            .values()
            .map(|c| (c, c.load.stalled_since.load(Ordering::Relaxed)))
            .filter(|(_, since)| *since != 0 && *since <= stalled_before)
            .min_by_key(|(_, since)| *since)
            .map(|(c, _)| c);
        match stalled {
            Some(client) => {
                client.disconnect.cancel();
                Counters::bump(&self.counters.mqtt_slow_clients);
                true
            }
            None => false,
        }
    }

    fn register(
        &self,
        connect: &Connect,
        listener: &Listener,
    ) -> Option<(u64, Arc<ClientLoad>, CancellationToken)> {
        let mut clients = self.clients.by_id.lock().ok()?;
        clients.next += 1;
        let id = clients.next;
        let load = Arc::new(ClientLoad::default());
        let disconnect = CancellationToken::new();
        clients.by_id.insert(
            id,
            Client {
                client_id: connect.client_id.clone(),
                listener: listener.name.clone(),
                version: connect.version,
                load: load.clone(),
                dropped_reported: 0,
                disconnect: disconnect.clone(),
            },
        );
        Some((id, load, disconnect))
    }

    fn unregister(&self, id: u64) {
        if let Ok(mut clients) = self.clients.by_id.lock() {
            clients.by_id.remove(&id);
        }
    }

    /// One client, from its CONNECT to its disconnection.
    async fn serve<S>(&self, mut stream: S, listener: &Listener, peer: SocketAddr)
    where
        S: AsyncRead + AsyncWrite + Unpin,
    {
        let mut buffer = Vec::with_capacity(4096);
        let first = tokio::time::timeout(HANDSHAKE, read_packet(&mut stream, &mut buffer)).await;
        let Ok(Ok(Some((CONNECT, len)))) = first else {
            return self.refused(peer, "no CONNECT");
        };
        let mut connect = match Connect::parse(buffer.get(..len).unwrap_or_default()) {
            Ok(connect) => connect,
            Err(error @ packet::PacketError::Protocol { level, .. }) => {
                // Answered as the client's protocol defines, so it stops retrying and says
                // why, instead of reconnecting for ever.
                Counters::bump(&self.counters.mqtt_refused);
                // Counted apart from other refusals, so the first of its kind is always logged.
                let count = self.version_refusals.fetch_add(1, Ordering::Relaxed) + 1;
                if worth_logging(count) {
                    warn!(%peer, level, count, "MQTT client refused: {error}; it was told so (CONNACK 'unsupported protocol version')");
                }
                let _ = stream.write_all(&packet::unsupported_version(level)).await;
                let _ = stream.shutdown().await;
                return;
            }
            Err(error) => return self.refused(peer, &error.to_string()),
        };
        buffer.drain(..len);
        let version = connect.version;
        if let Err((why, refusal)) = self.admit(&connect, listener) {
            return self
                .refuse_connect(&mut stream, version, refusal, peer, why)
                .await;
        }
        if !self.make_room() {
            let why = "connection limit reached";
            return self
                .refuse_connect(&mut stream, version, Refusal::Busy, peer, why)
                .await;
        }
        let Ok(mut broker) = self.connect_broker().await else {
            let why = "broker not reachable";
            return self
                .refuse_connect(&mut stream, version, Refusal::Unavailable, peer, why)
                .await;
        };
        let max = self.settings.max_keep_alive_s;
        if connect.keep_alive_s == 0 || connect.keep_alive_s > max {
            connect.keep_alive_s = max;
        }
        let client = connect.client_id.clone();
        let unacknowledged = self
            .unacknowledged_ids
            .lock()
            .map_or(true, |ids| ids.contains(&connect.client_id));
        if unacknowledged {
            let serial = self.rewritten.fetch_add(1, Ordering::Relaxed);
            connect.client_id = format!("{}-gate{serial}", connect.client_id);
        }
        connect.username = Some(self.settings.broker_user.clone());
        connect.password = Some(self.settings.broker_password.clone().into_bytes());
        if broker.write_all(&connect.encode()).await.is_err() {
            return;
        }
        let mut acknowledgement = Vec::with_capacity(16);
        let answered = tokio::time::timeout(
            self.settings.connack_timeout,
            read_packet(&mut broker, &mut acknowledgement),
        )
        .await;
        if !matches!(answered, Ok(Ok(Some((CONNACK, _))))) {
            // A rewritten id is never offered again anyway.
            if !unacknowledged && let Ok(mut ids) = self.unacknowledged_ids.lock() {
                ids.insert(connect.client_id.clone());
            }
            let why = "the broker did not acknowledge the connection";
            return self
                .refuse_connect(&mut stream, version, Refusal::Unavailable, peer, why)
                .await;
        }
        let pending = Unsubscribes::default();
        let acknowledgement = match version {
            Version::V311 => Ok(acknowledgement),
            Version::V5 => acknowledgement
                .get(..4)
                .ok_or(packet::PacketError::Short)
                .and_then(|connack| mqtt5::to_client(connack, &pending)),
        };
        let Ok(acknowledgement) = acknowledgement else {
            return;
        };
        if stream.write_all(&acknowledgement).await.is_err() {
            return;
        }
        let connect = Connect {
            client_id: client,
            ..connect
        };
        let Some((id, load, disconnect)) = self.register(&connect, listener) else {
            return;
        };
        // Clients come and go all day (a laptop's Wi-Fi, a dashboard restarted): not news.
        let client = connect.client_id;
        debug!(%peer, client, listener = listener.name, version = version.name(), "MQTT client connected");
        let (client_read, client_write) = tokio::io::split(stream);
        let (broker_read, broker_write) = broker.into_split();
        let translation = (version == Version::V5).then_some(&pending);
        tokio::select! {
            () = self.upstream(client_read, broker_write, buffer, translation, peer) => {}
            () = self.downstream(broker_read, client_write, &load, translation, listener.newest_first, peer) => {}
            () = disconnect.cancelled() => {
                warn!(%peer, "MQTT client disconnected to make room: it stopped reading");
            }
        }
        debug!(%peer, client, "MQTT client gone");
        self.unregister(id);
    }

    /// A connection to the broker whose receive buffer stays small (see
    /// [`BROKER_RECEIVE_BUFFER`]).
    async fn connect_broker(&self) -> std::io::Result<TcpStream> {
        let socket = match self.settings.broker {
            SocketAddr::V4(_) => tokio::net::TcpSocket::new_v4()?,
            SocketAddr::V6(_) => tokio::net::TcpSocket::new_v6()?,
        };
        socket.set_recv_buffer_size(BROKER_RECEIVE_BUFFER)?;
        let stream = socket.connect(self.settings.broker).await?;
        stream.set_nodelay(true)?;
        Ok(stream)
    }

    /// Client to broker, packet by packet (an MQTT 5 client's rewritten to 3.1.1 first): a
    /// publish under the protected prefix (or a second CONNECT) ends the connection.
    async fn upstream(
        &self,
        mut client: impl AsyncRead + Unpin,
        mut broker: impl AsyncWrite + Unpin,
        mut buffer: Vec<u8>,
        translation: Option<&Unsubscribes>,
        peer: SocketAddr,
    ) {
        loop {
            let (kind, len) = match read_packet(&mut client, &mut buffer).await {
                Ok(Some(packet)) => packet,
                Ok(None) => return,
                Err(error) => return self.refused(peer, &error.to_string()),
            };
            let Some(bytes) = buffer.get(..len) else {
                return;
            };
            if kind == CONNECT {
                return self.refused(peer, "second CONNECT");
            }
            let translated;
            let bytes = match translation {
                None => bytes,
                Some(pending) => match mqtt5::to_broker(bytes, pending) {
                    Ok(packet) => {
                        translated = packet;
                        translated.as_slice()
                    }
                    Err(error) => return self.refused(peer, &error.to_string()),
                },
            };
            if kind == PUBLISH {
                match packet::publish_topic(bytes) {
                    Ok(topic) if !self.is_protected(&topic) => {}
                    Ok(_) => return self.refused(peer, "publish under the service's topics"),
                    Err(error) => return self.refused(peer, &error.to_string()),
                }
            }
            if broker.write_all(bytes).await.is_err() {
                return;
            }
            buffer.drain(..len);
        }
    }

    /// Broker to client. The broker is read at once, whatever the client does, into the
    /// client's queue; the client is written from it. A client that takes nothing for the
    /// stall limit is disconnected, and so is one whose backlog is over its bound with nothing
    /// it may drop.
    async fn downstream(
        &self,
        mut broker: impl AsyncRead + Unpin,
        mut client: impl AsyncWrite + Unpin,
        load: &ClientLoad,
        translation: Option<&Unsubscribes>,
        newest_first: bool,
        peer: SocketAddr,
    ) {
        let max_lag_us = u64::try_from(self.settings.max_lag.as_micros()).unwrap_or(u64::MAX);
        let max_bytes = self.settings.max_queue_bytes;
        let queue = Mutex::new(if newest_first {
            ClientQueue::newest_first(max_bytes, max_lag_us)
        } else {
            ClientQueue::everything()
        });
        let arrived = tokio::sync::Notify::new();
        let room = tokio::sync::Notify::new();
        let publish_load = |queue: &ClientQueue, writing_since: Option<u64>| {
            let oldest = writing_since.or(queue.oldest_us()).unwrap_or(0);
            load.oldest_us.store(oldest, Ordering::Relaxed);
            load.queued_bytes
                .store(queue.bytes() as u64, Ordering::Relaxed);
            let dropped = queue.dropped();
            let before = load.dropped.swap(dropped, Ordering::Relaxed);
            if dropped > before {
                self.counters
                    .mqtt_client_dropped
                    .fetch_add(dropped - before, Ordering::Relaxed);
            }
        };
        let read = async {
            let mut buffer = Vec::with_capacity(16 * 1024);
            loop {
                let len = match read_packet(&mut broker, &mut buffer).await {
                    Ok(Some((_, len))) => len,
                    Ok(None) | Err(_) => return,
                };
                let packet: Vec<u8> = buffer.drain(..len).collect();
                let queued = queue.lock().ok().map(|mut queue| {
                    let queued = queue.push(self.now_us(), packet);
                    publish_load(&queue, None);
                    queued
                });
                match queued {
                    Some(Ok(full)) => {
                        arrived.notify_one();
                        // Everything for this client: the broker waits while its queue is full.
                        if full > max_bytes {
                            room.notified().await;
                        }
                    }
                    Some(Err(_)) => {
                        let count = Counters::bump(&self.counters.mqtt_slow_clients);
                        if worth_logging(count) {
                            warn!(%peer, count, "MQTT client cannot keep up with what it must be sent: disconnected");
                        }
                        return;
                    }
                    None => return,
                }
            }
        };
        let write = async {
            let mut batch = Vec::with_capacity(WRITE_BATCH);
            loop {
                // What waits, up to a batch, in one write (one TLS record, one system call).
                let taken = queue.lock().ok().map(|mut queue| {
                    let now = self.now_us();
                    let mut first = None;
                    batch.clear();
                    while batch.len() < WRITE_BATCH {
                        let Some(packet) = queue.pop(now) else {
                            break;
                        };
                        first.get_or_insert(now);
                        match translation {
                            None => batch.extend_from_slice(&packet),
                            Some(pending) => {
                                let translated = mqtt5::to_client(&packet, pending)?;
                                batch.extend_from_slice(&translated);
                            }
                        }
                    }
                    publish_load(&queue, first);
                    if queue.bytes() <= max_bytes {
                        room.notify_one();
                    }
                    Ok::<bool, packet::PacketError>(first.is_some())
                });
                match taken {
                    None => return,
                    Some(Err(error)) => return self.refused(peer, &error.to_string()),
                    Some(Ok(false)) => {
                        arrived.notified().await;
                        continue;
                    }
                    Some(Ok(true)) => {}
                }
                load.stalled_since.store(self.now_us(), Ordering::Relaxed);
                let written = tokio::time::timeout(self.settings.stall_limit, async {
                    client.write_all(&batch).await?;
                    client.flush().await
                })
                .await;
                load.stalled_since.store(0, Ordering::Relaxed);
                match written {
                    Ok(Ok(())) => {}
                    Ok(Err(_)) => return,
                    Err(_) => {
                        let count = Counters::bump(&self.counters.mqtt_slow_clients);
                        if worth_logging(count) {
                            warn!(%peer, count, "MQTT client stopped reading: disconnected, its data dropped");
                        }
                        return;
                    }
                }
            }
        };
        tokio::select! {
            () = read => {}
            () = write => {}
        }
    }
}

/// Reads until `buffer` starts with a whole packet; its type and length, `None` at the end of
/// the stream.
async fn read_packet(
    stream: &mut (impl AsyncRead + Unpin),
    buffer: &mut Vec<u8>,
) -> Result<Option<(u8, usize)>, packet::PacketError> {
    loop {
        if let Some(found) = packet::frame(buffer)? {
            return Ok(Some(found));
        }
        let mut chunk = [0u8; 4096];
        match stream.read(&mut chunk).await {
            Ok(0) | Err(_) => return Ok(None),
            Ok(n) => buffer.extend_from_slice(chunk.get(..n).unwrap_or_default()),
        }
    }
}
