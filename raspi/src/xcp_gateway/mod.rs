//! The pit's XCP gateway: XCP on TCP from a calibration tool on the pit laptop (pyxcp, CANape,
//! the dashboard's Tune page) to the CCM's XCP slave on CAN (the DBC's XCP_Cmd/XCP_Res), and
//! back. The Pi is the only node on both the pit's network and the car's bus, so it forwards:
//! each command packet becomes one 8-byte frame (MAX_DLC_REQUIRED), each frame from the slave
//! one TCP packet. The protocol is the slave's, end to end; the gateway adds who may talk:
//!
//! - **Who.** A master must connect from an address in the allow list (`[xcp_gateway]
//!   allow`); anyone else is refused (the connection closed at once), counted
//!   (`xcp_refused`) and named in the status. Changing calibration needs more: the CCM's own
//!   seed and key (GET_SEED/UNLOCK with the team's secret), which the gateway passes through.
//! - **One at a time.** A second master is refused while one is connected.
//! - **A master that vanishes** (its connection closed or reset, silent for `idle`, or TCP
//!   keepalive finding it gone) is disconnected from the CCM: the gateway sends the slave a
//!   DISCONNECT, which ends its session and locks calibration again. A download cut off
//!   mid-block never reaches the calibration page (the slave writes a block as one
//!   transaction), so the CCM stays consistent and the next master connects.
//!
//! - **Every change recorded.** When a master connects, the gateway reads the working page
//!   (SHORT_UPLOAD, before the master sees the CONNECT answer) and the page the CCM runs on;
//!   then [`record::Recorder`] follows every write, revert, page switch and save and the
//!   slave's answer to it. Each becomes an entry (old and new value, accepted or refused and
//!   why, the checksum after) in the session's record in the store, the status and the
//!   journal.
//!
//! The gateway has its own task and its own CAN socket; it shares nothing with ingest, the
//! store or the live MQTT path but the counters and the status.

pub mod allow;
#[cfg(target_os = "linux")]
pub mod can;
pub mod record;
pub mod rehearsal;

use crate::store::NoteSender;
use crate::store::calibration::{Entry, Kind};
use aer::calibration::PAGE_LEN;
use aer::calibration::xcp::CALIBRATION_ADDRESS;
use aer_host::reports::counters::Counters;
use aer_host::reports::status::XcpGateway;
use aer_xcp::protocol::pid::{ERR, RES};
use aer_xcp::protocol::{cmd, page_mode};
use aer_xcp::transport::{CAN_DLC, TCP_FRAME_MAX, TcpDecoder, TcpEncoder, can_frame};
use allow::Network;
use record::Recorder;
use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::mpsc;
use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;
use tracing::{info, warn};

/// How long a write to the master may wait before it counts as gone.
const WRITE_LIMIT: Duration = Duration::from_secs(2);
/// How long the slave may take to answer the gateway's own commands: its DISCONNECT, its
/// reading of the page (a CAN round trip is a millisecond or two).
const SLAVE_ANSWER: Duration = Duration::from_millis(500);
/// After the slave failed to answer one of the gateway's own commands in time, how long new
/// masters are refused: its late answer must not reach a new master as the answer to
/// something else.
const QUIET_AFTER_SILENCE: Duration = Duration::from_secs(2);
/// Bytes one SHORT_UPLOAD reads at MAX_CTO 8.
const UPLOAD_CHUNK: usize = 7;
/// The pause after a failed accept.
const ACCEPT_RETRY: Duration = Duration::from_millis(100);
/// A master whose packets go unacknowledged this long is gone (TCP_USER_TIMEOUT): the
/// keepalive covers an idle connection, this one a connection with data in flight.
const UNACKNOWLEDGED_LIMIT: Duration = Duration::from_secs(16);
/// Frames waiting for the CAN socket: room for a block-mode download (MAX_BS 32) and more.
pub const TO_SLAVE_FRAMES: usize = 256;

/// Where the gateway listens and whom it serves.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Settings {
    pub listen: SocketAddr,
    pub allow: Vec<Network>,
    /// The CAN interface the slave is on (for the status).
    pub interface: String,
    /// A master that sends nothing for this long is taken as gone.
    pub idle: Duration,
}

/// The slave's side: command frames out, the slave's packets in.
pub struct SlaveLink {
    pub to_slave: mpsc::Sender<[u8; CAN_DLC]>,
    pub from_slave: mpsc::Receiver<Vec<u8>>,
}

/// The gateway's state, as the status reports it.
#[derive(Debug, Default)]
pub struct State {
    now: Mutex<XcpGateway>,
}

impl State {
    /// The state now.
    pub fn snapshot(&self) -> XcpGateway {
        self.now.lock().map(|s| s.clone()).unwrap_or_default()
    }

    fn update(&self, change: impl FnOnce(&mut XcpGateway)) {
        if let Ok(mut now) = self.now.lock() {
            change(&mut now);
        }
    }
}

/// A running gateway.
pub struct Gateway {
    pub state: Arc<State>,
    /// The address it listens on (the port the system chose, for port 0).
    pub address: SocketAddr,
    pub task: JoinHandle<()>,
}

/// Starts listening and serving; fails only if the address cannot be bound.
pub async fn spawn(
    settings: Settings,
    link: SlaveLink,
    counters: Arc<Counters>,
    record: Option<NoteSender>,
    cancel: CancellationToken,
) -> std::io::Result<Gateway> {
    let listener = TcpListener::bind(settings.listen).await?;
    let address = listener.local_addr()?;
    let state = Arc::new(State::default());
    state.update(|s| {
        s.listen = address.to_string();
        s.interface.clone_from(&settings.interface);
    });
    info!(%address, interface = %settings.interface, "XCP gateway listening");
    let mut gateway = Forwarder {
        settings,
        link,
        counters,
        state: state.clone(),
        master: None,
        recorder: Recorder::new(),
        record,
        quiet_until: None,
    };
    let task = tokio::spawn(async move { gateway.run(listener, cancel).await });
    Ok(Gateway {
        state,
        address,
        task,
    })
}

/// The master connected now.
struct Master {
    stream: TcpStream,
    peer: SocketAddr,
    decoder: TcpDecoder,
    encoder: TcpEncoder,
    last_heard: Instant,
    /// The last command sent to the slave (to tell which response answers CONNECT).
    last_command: Option<u8>,
}

struct Forwarder {
    settings: Settings,
    link: SlaveLink,
    counters: Arc<Counters>,
    state: Arc<State>,
    master: Option<Master>,
    recorder: Recorder,
    /// Where the entries go to be stored (none without a store).
    record: Option<NoteSender>,
    /// Until when masters are refused after the slave went silent on the gateway.
    quiet_until: Option<Instant>,
}

/// What woke the gateway.
enum Event {
    Accepted(std::io::Result<(TcpStream, SocketAddr)>),
    FromMaster(std::io::Result<usize>),
    FromSlave(Option<Vec<u8>>),
    Idle,
    Stop,
}

impl Forwarder {
    async fn run(&mut self, listener: TcpListener, cancel: CancellationToken) {
        let mut buffer = [0u8; 1024];
        loop {
            let idle_at = self
                .master
                .as_ref()
                .map(|m| m.last_heard + self.settings.idle);
            let event = tokio::select! {
                () = cancel.cancelled() => Event::Stop,
                accepted = listener.accept() => Event::Accepted(accepted),
                read = read_master(&mut self.master, &mut buffer) => Event::FromMaster(read),
                packet = self.link.from_slave.recv() => Event::FromSlave(packet),
                () = sleep_until(idle_at) => Event::Idle,
            };
            match event {
                Event::Stop => {
                    self.end_master("the service stopped").await;
                    return;
                }
                Event::Accepted(Ok((stream, peer))) => self.accept(stream, peer),
                Event::Accepted(Err(error)) => {
                    // Out of file descriptors, say: a moment before trying again, rather than
                    // a loop that fills the journal.
                    warn!(%error, "XCP gateway: accept failed");
                    tokio::time::sleep(ACCEPT_RETRY).await;
                }
                Event::FromMaster(Ok(0)) => self.end_master("it closed the connection").await,
                Event::FromMaster(Ok(read)) => {
                    let input = buffer.get(..read).unwrap_or_default().to_vec();
                    self.forward_commands(&input).await;
                }
                Event::FromMaster(Err(error)) => {
                    self.end_master(&format!("its connection failed: {error}"))
                        .await;
                }
                Event::FromSlave(Some(packet)) => self.forward_answer(&packet).await,
                Event::FromSlave(None) => {
                    warn!("XCP gateway: the CAN side ended; the gateway stops");
                    self.end_master("the CAN side ended").await;
                    return;
                }
                Event::Idle => {
                    let idle = self.settings.idle.as_secs();
                    self.end_master(&format!("silent for {idle} s")).await;
                }
            }
        }
    }

    fn accept(&mut self, stream: TcpStream, peer: SocketAddr) {
        let why = if !self.settings.allow.iter().any(|n| n.contains(peer.ip())) {
            Some("its address is not in the gateway's allow list")
        } else if self.quiet_until.is_some_and(|until| Instant::now() < until) {
            Some("the CCM just stopped answering (try again in a few seconds)")
        } else if self.master.is_some() {
            Some("another master is connected (one at a time)")
        } else {
            None
        };
        if let Some(why) = why {
            let count = Counters::bump(&self.counters.xcp_refused);
            warn!(%peer, why, count, "XCP master refused");
            self.state
                .update(|s| s.last_refusal = Some(format!("{peer}: {why}")));
            drop(stream);
            return;
        }
        let _ = stream.set_nodelay(true);
        // A master that vanishes without closing (the radio gone) shows within about 16 s.
        let keepalive = socket2::TcpKeepalive::new()
            .with_time(Duration::from_secs(10))
            .with_interval(Duration::from_secs(2))
            .with_retries(3);
        let socket = socket2::SockRef::from(&stream);
        let _ = socket.set_tcp_keepalive(&keepalive);
        #[cfg(target_os = "linux")]
        let _ = socket.set_tcp_user_timeout(Some(UNACKNOWLEDGED_LIMIT));
        info!(%peer, "XCP master connected");
        self.state.update(|s| {
            s.master = Some(peer.to_string());
            s.master_since_us = Some(aer_host::clock::now_us());
            s.session = false;
        });
        self.master = Some(Master {
            stream,
            peer,
            decoder: TcpDecoder::new(),
            encoder: TcpEncoder::new(),
            last_heard: Instant::now(),
            last_command: None,
        });
    }

    /// Forwards every whole packet in `input` to the slave, one frame each.
    async fn forward_commands(&mut self, mut input: &[u8]) {
        let Some(master) = self.master.as_mut() else {
            return;
        };
        master.last_heard = Instant::now();
        let mut broken = false;
        let mut stalled = false;
        while !input.is_empty() {
            let (used, packet) = master.decoder.decode(input);
            input = input.get(used..).unwrap_or_default();
            match packet {
                Some(Ok(packet)) => match can_frame(packet.data) {
                    Some(frame) => {
                        self.recorder.command(packet.data);
                        master.last_command = packet.data.first().copied();
                        if self.link.to_slave.try_send(frame).is_ok() {
                            Counters::bump(&self.counters.xcp_commands);
                        } else {
                            // The bus is not taking commands (it is being reopened): a
                            // command lost in the middle of a session would leave the master
                            // and the slave disagreeing, so the master goes.
                            Counters::bump(&self.counters.xcp_dropped);
                            stalled = true;
                        }
                    }
                    None => broken = true,
                },
                Some(Err(_)) => broken = true,
                None => {}
            }
            if broken || stalled || used == 0 {
                break;
            }
        }
        if stalled {
            self.end_master("the CAN bus is not taking commands").await;
        } else if broken {
            // A broken stream cannot be resynchronised.
            Counters::bump(&self.counters.xcp_dropped);
            self.end_master("it sent something that is not XCP on TCP")
                .await;
        }
    }

    /// Forwards a packet of the slave's to the master, if there is one, and records what it
    /// answered.
    async fn forward_answer(&mut self, packet: &[u8]) {
        let Some(master) = self.master.as_ref() else {
            Counters::bump(&self.counters.xcp_dropped);
            return;
        };
        let (peer, last_command) = (master.peer.to_string(), master.last_command);
        if matches!(packet.first(), Some(&RES | &ERR)) {
            let at_us = now_us();
            let entries = self.recorder.answer(packet, at_us, &peer);
            self.publish(entries);
            match (packet.first(), last_command) {
                (Some(&RES), Some(cmd::CONNECT)) => {
                    self.state.update(|s| s.session = true);
                    // Before the master sees the answer, so nothing of its own is lost.
                    if !self.read_page(&peer).await {
                        self.end_master("the CCM did not answer the gateway's page read")
                            .await;
                        return;
                    }
                }
                (Some(&RES), Some(cmd::DISCONNECT)) => self.state.update(|s| s.session = false),
                // A wrong key ends the slave's session (the standard's rule).
                (Some(&ERR), Some(cmd::UNLOCK))
                    if packet.get(1) == Some(&aer_xcp::protocol::err::ACCESS_LOCKED) =>
                {
                    self.state.update(|s| s.session = false);
                }
                _ => {}
            }
        }
        let Some(master) = self.master.as_mut() else {
            return;
        };
        let mut frame = [0u8; TCP_FRAME_MAX];
        let Ok(len) = master.encoder.encode(packet, &mut frame) else {
            Counters::bump(&self.counters.xcp_dropped);
            return;
        };
        let write = master
            .stream
            .write_all(frame.get(..len).unwrap_or_default());
        match tokio::time::timeout(WRITE_LIMIT, write).await {
            Ok(Ok(())) => {
                // A master that only measures (DAQ) sends nothing for minutes: what it takes
                // counts as alive too.
                master.last_heard = Instant::now();
                Counters::bump(&self.counters.xcp_responses);
            }
            Ok(Err(error)) => {
                self.end_master(&format!("writing to it failed: {error}"))
                    .await;
            }
            Err(_) => self.end_master("it stopped reading").await,
        }
    }

    /// Forgets the master and, if it held a session with the slave, ends that session.
    async fn end_master(&mut self, why: &str) {
        let Some(master) = self.master.take() else {
            return;
        };
        let had_session = self.state.snapshot().session;
        if had_session {
            self.disconnect_slave().await;
        }
        self.recorder.session_ended();
        info!(
            peer = %master.peer,
            why,
            ended_session = had_session,
            "XCP master gone"
        );
        self.state.update(|s| {
            s.master = None;
            s.master_since_us = None;
            s.session = false;
        });
    }
}

impl Forwarder {
    /// Sends the slave a command of the gateway's own and waits (a little) for its answer,
    /// dropping what the slave sends first (an old session's DAQ): `None` if it does not
    /// answer in time.
    async fn ask(&mut self, command: &[u8]) -> Option<Vec<u8>> {
        let deadline = tokio::time::Instant::now() + SLAVE_ANSWER;
        let frame = can_frame(command)?;
        let queued = tokio::time::timeout_at(deadline, self.link.to_slave.send(frame)).await;
        if !matches!(queued, Ok(Ok(()))) {
            return None;
        }
        loop {
            match tokio::time::timeout_at(deadline, self.link.from_slave.recv()).await {
                Ok(Some(packet)) if matches!(packet.first(), Some(&RES | &ERR)) => {
                    return Some(packet);
                }
                Ok(Some(_)) => {
                    Counters::bump(&self.counters.xcp_dropped);
                }
                Ok(None) => return None,
                Err(_) => {
                    self.quiet_until = Some(Instant::now() + QUIET_AFTER_SILENCE);
                    return None;
                }
            }
        }
    }

    /// Ends the slave's session for a vanished master, so none of its state (unlocked
    /// calibration, DAQ) reaches the next one; the answer is not the next master's either.
    async fn disconnect_slave(&mut self) {
        if self.ask(&[cmd::DISCONNECT]).await.is_some() {
            Counters::bump(&self.counters.xcp_dropped);
        } else {
            warn!("XCP gateway: the slave did not answer the DISCONNECT for a vanished master");
        }
    }

    /// Reads the working page and the page the CCM runs on, for the record's old values and
    /// checksum, and records what it found. A page the slave refuses to give leaves old values
    /// unknown; false if the slave stopped answering (the master must go: a late answer would
    /// reach it as the answer to its next command).
    async fn read_page(&mut self, peer: &str) -> bool {
        let mut page = [0u8; PAGE_LEN];
        for (chunk, start) in (0..PAGE_LEN).step_by(UPLOAD_CHUNK).enumerate() {
            let len = UPLOAD_CHUNK.min(PAGE_LEN - start);
            let address = u32::try_from(start)
                .ok()
                .and_then(|offset| CALIBRATION_ADDRESS.checked_add(offset));
            let (Some(address), Ok(count)) = (address, u8::try_from(len)) else {
                return true;
            };
            let mut upload = [cmd::SHORT_UPLOAD, count, 0, 0, 0, 0, 0, 0];
            if let Some(at) = upload.get_mut(4..8) {
                at.copy_from_slice(&address.to_le_bytes());
            }
            let Some(answer) = self.ask(&upload).await else {
                warn!(chunk, "XCP gateway: the CCM did not answer the page read");
                return false;
            };
            let data = Some(answer.as_slice())
                .filter(|a| a.first() == Some(&RES))
                .and_then(|a| a.get(1..=len));
            match (data, page.get_mut(start..start + len)) {
                (Some(data), Some(slot)) => slot.copy_from_slice(data),
                _ => {
                    warn!(
                        chunk,
                        "XCP gateway: the calibration page could not be read; old values stay unknown"
                    );
                    return true;
                }
            }
        }
        let Some(answer) = self.ask(&[cmd::GET_CAL_PAGE, page_mode::ECU, 0]).await else {
            return false;
        };
        let ecu_page = Some(answer)
            .filter(|a| a.first() == Some(&RES))
            .and_then(|a| a.get(3).copied());
        let entries = self.recorder.found(page, ecu_page, now_us(), peer);
        self.publish(entries);
        true
    }

    /// Counts, logs, shows and stores what the recorder made of an answer.
    fn publish(&mut self, entries: Vec<Entry>) {
        let checksum = self.recorder.checksum();
        let mut last = None;
        for entry in entries {
            if entry.kind != Kind::Found {
                let counter = if entry.accepted {
                    &self.counters.calibration_changes
                } else {
                    &self.counters.calibration_refusals
                };
                Counters::bump(counter);
                info!(change = %entry, "calibration");
                last = Some(entry.to_string());
            }
            if let Some(record) = &self.record {
                record.send(entry);
            }
        }
        self.state.update(|s| {
            s.checksum = checksum.map(|c| format!("{c:08X}"));
            if last.is_some() {
                s.last_change = last;
            }
        });
    }
}

fn now_us() -> i64 {
    i64::try_from(aer_host::clock::now_us()).unwrap_or(i64::MAX)
}

/// Reads from the master, or waits for ever when there is none.
async fn read_master(master: &mut Option<Master>, buffer: &mut [u8]) -> std::io::Result<usize> {
    match master {
        Some(master) => master.stream.read(buffer).await,
        None => std::future::pending().await,
    }
}

async fn sleep_until(at: Option<Instant>) {
    match at {
        Some(at) => tokio::time::sleep_until(at.into()).await,
        None => std::future::pending().await,
    }
}
