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
//! - disconnects a client that stops reading what it subscribed to (its data is dropped, not
//!   queued), and at the connection limit makes room by disconnecting one that stalled;
//! - speaks TLS on listeners that have certificates.
//!
//! Everything refused is counted (`mqtt_refused`, `mqtt_slow_clients`) and logged.

use super::packet::{self, CONNACK, CONNECT, Connect, PUBLISH};
use super::tls;
use aer_host::counters::{Counters, worth_logging};
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
    /// (`aer-pit/<car>/history/request`).
    pub open: Vec<String>,
    /// Client ids only the service may use (`aer-raspi`).
    pub reserved_ids: String,
    /// Clients at once, beyond which a stalled one makes room or the newcomer is refused.
    pub max_clients: usize,
    /// A client that has not taken data for this long is disconnected.
    pub stall_limit: Duration,
    /// Keep-alive asked for by clients is capped at this (0, "never", included).
    pub max_keep_alive_s: u16,
    /// How long the broker has to acknowledge a connection.
    pub connack_timeout: Duration,
}

/// The connected clients, for the connection limit.
#[derive(Default)]
struct Clients {
    next: u64,
    by_id: HashMap<u64, Client>,
}

struct Client {
    /// Since when a write to the client has been waiting (us since the gate started; 0 when
    /// none waits).
    stalled_since: Arc<AtomicU64>,
    disconnect: CancellationToken,
}

struct Gate {
    settings: Settings,
    counters: Arc<Counters>,
    clients: Mutex<Clients>,
    started: Instant,
    /// Client ids the broker did not acknowledge: never offered to it again.
    unacknowledged_ids: Mutex<HashSet<String>>,
    /// The serial in rewritten client ids.
    rewritten: AtomicU64,
    /// Clients refused for their protocol version (MQTT 5, 3.1).
    version_refusals: AtomicU64,
}

/// Binds every listener (so a taken port fails at start-up) and serves them until `cancel`.
pub async fn start(
    settings: Settings,
    counters: Arc<Counters>,
    cancel: CancellationToken,
) -> anyhow::Result<()> {
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
    let gate = Arc::new(Gate {
        settings,
        counters,
        clients: Mutex::new(Clients::default()),
        started: Instant::now(),
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
                            let _ = tokio::time::timeout(
                                HANDSHAKE,
                                read_packet(&mut stream, &mut buffer),
                            )
                            .await;
                            let _ = stream.write_all(&packet::connack(5)).await;
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
    Ok(())
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

/// Bytes the kernel may hold for a client before a write waits.
const CLIENT_SEND_BUFFER: usize = 64 * 1024;

/// How long a new client has for TLS and its CONNECT.
const HANDSHAKE: Duration = Duration::from_secs(10);

impl Gate {
    fn refused(&self, peer: SocketAddr, why: &str) {
        let count = Counters::bump(&self.counters.mqtt_refused);
        if worth_logging(count) {
            warn!(%peer, why, count, "MQTT client refused");
        }
    }

    fn now_us(&self) -> u64 {
        (self.started.elapsed().as_micros() as u64).max(1)
    }

    /// True for a topic under one of the service's roots.
    fn is_protected(&self, topic: &str) -> bool {
        self.settings
            .protected
            .iter()
            .any(|root| topic.starts_with(root.as_str()))
            && !self.settings.open.iter().any(|open| open == topic)
    }

    /// Checks a new client's CONNECT; the reason and CONNACK code if it is refused.
    fn admit(&self, connect: &Connect, listener: &Listener) -> Result<(), (&'static str, u8)> {
        if connect.client_id.starts_with(&self.settings.reserved_ids) {
            return Err(("client id reserved for the service", 2));
        }
        if let Some(users) = listener.auth.as_ref().filter(|users| !users.is_empty()) {
            let matches = connect
                .username
                .as_ref()
                .and_then(|user| users.get(user))
                .is_some_and(|password| connect.password.as_deref() == Some(password.as_bytes()));
            if !matches {
                return Err(("bad username or password", 4));
            }
        }
        if connect
            .will
            .as_ref()
            .is_some_and(|(topic, ..)| self.is_protected(topic))
        {
            return Err(("will under the service's topics", 5));
        }
        Ok(())
    }

    /// Makes room for one more client: true if there is (or now is) room.
    fn make_room(&self) -> bool {
        let Ok(clients) = self.clients.lock() else {
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
            .map(|c| (c, c.stalled_since.load(Ordering::Relaxed)))
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

    fn register(&self) -> Option<(u64, Arc<AtomicU64>, CancellationToken)> {
        let mut clients = self.clients.lock().ok()?;
        clients.next += 1;
        let id = clients.next;
        let stalled_since = Arc::new(AtomicU64::new(0));
        let disconnect = CancellationToken::new();
        clients.by_id.insert(
            id,
            Client {
                stalled_since: stalled_since.clone(),
                disconnect: disconnect.clone(),
            },
        );
        Some((id, stalled_since, disconnect))
    }

    fn unregister(&self, id: u64) {
        if let Ok(mut clients) = self.clients.lock() {
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
                let _ = stream.write_all(&packet::unsupported_version(level)).await;
                let _ = stream.shutdown().await;
                Counters::bump(&self.counters.mqtt_refused);
                // Counted apart from other refusals, so the first of its kind is always logged.
                let count = self.version_refusals.fetch_add(1, Ordering::Relaxed) + 1;
                if worth_logging(count) {
                    warn!(%peer, level, count, "MQTT client refused: {error}; it was told so (CONNACK 'unsupported protocol version')");
                }
                return;
            }
            Err(error) => return self.refused(peer, &error.to_string()),
        };
        buffer.drain(..len);
        if let Err((why, code)) = self.admit(&connect, listener) {
            let _ = stream.write_all(&packet::connack(code)).await;
            return self.refused(peer, why);
        }
        if !self.make_room() {
            let _ = stream.write_all(&packet::connack(3)).await;
            return self.refused(peer, "connection limit reached");
        }
        let Ok(mut broker) = TcpStream::connect(self.settings.broker).await else {
            let _ = stream.write_all(&packet::connack(3)).await;
            return self.refused(peer, "broker not reachable");
        };
        let _ = broker.set_nodelay(true);
        let max = self.settings.max_keep_alive_s;
        if connect.keep_alive_s == 0 || connect.keep_alive_s > max {
            connect.keep_alive_s = max;
        }
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
            let _ = stream.write_all(&packet::connack(3)).await;
            return self.refused(peer, "the broker did not acknowledge the connection");
        }
        if stream.write_all(&acknowledgement).await.is_err() {
            return;
        }
        let Some((id, stalled_since, disconnect)) = self.register() else {
            return;
        };
        // Clients come and go all day (a laptop's Wi-Fi, a dashboard restarted): not news.
        let client = connect.client_id.clone();
        debug!(%peer, client, listener = listener.name, "MQTT client connected");
        let (client_read, client_write) = tokio::io::split(stream);
        let (broker_read, broker_write) = broker.into_split();
        tokio::select! {
            () = self.upstream(client_read, broker_write, buffer, peer) => {}
            () = self.downstream(broker_read, client_write, &stalled_since, peer) => {}
            () = disconnect.cancelled() => {
                warn!(%peer, "MQTT client disconnected to make room: it stopped reading");
            }
        }
        debug!(%peer, client, "MQTT client gone");
        self.unregister(id);
    }

    /// Client to broker, packet by packet: a publish under the protected prefix (or a second
    /// CONNECT) ends the connection.
    async fn upstream(
        &self,
        mut client: impl AsyncRead + Unpin,
        mut broker: impl AsyncWrite + Unpin,
        mut buffer: Vec<u8>,
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

    /// Broker to client: a client that takes nothing for the stall limit is disconnected
    /// (what it did not read is dropped).
    async fn downstream(
        &self,
        mut broker: impl AsyncRead + Unpin,
        mut client: impl AsyncWrite + Unpin,
        stalled_since: &AtomicU64,
        peer: SocketAddr,
    ) {
        let mut chunk = vec![0u8; 16 * 1024];
        loop {
            let n = match broker.read(&mut chunk).await {
                Ok(0) | Err(_) => return,
                Ok(n) => n,
            };
            let Some(data) = chunk.get(..n) else {
                return;
            };
            stalled_since.store(self.now_us(), Ordering::Relaxed);
            let written =
                tokio::time::timeout(self.settings.stall_limit, client.write_all(data)).await;
            stalled_since.store(0, Ordering::Relaxed);
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
