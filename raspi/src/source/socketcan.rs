//! Live SocketCAN: every configured interface is read (and reopened with a 1 s backoff when missing
//! or failing; the log says so at once, then once a minute, and the status names the interface
//! until it works). A socket is bound to an interface index, and a CAN socket whose interface is
//! deleted blocks for ever without an error (a USB adapter replugged, a CAN hat's driver reloaded:
//! the new interface has a new index), so every reader checks the index behind its interface's name
//! each `WATCH` (250 ms) and reopens when it changed; each reopening is counted (`can_reopened`).
//! Error frames (bus errors, error passive, bus off) are counted (`can_error_frames`), never
//! decoded. Frames the kernel drops because a socket's receive queue is full (a flooded bus, a
//! reader behind) are counted too (`can_rx_overflows`, from the socket's `SO_MEMINFO`), so no loss
//! between the wire and the service goes unseen. With kernel ISO-TP the telemetry arrives as whole
//! packets from the can-isotp socket (which sends the flow control itself); otherwise ingest
//! reassembles it from raw frames and its flow control goes out through this source's bus writer
//! ([`Replies`]).

use super::failures::{Failures, REPORT_EVERY};
use super::{Batcher, Input, Replies, Sender};
use crate::config::IsoTpMode;
use crate::health::Health;
use aer::telemetry::Telemetry;
use aer_host::clock::now_us;
use aer_host::formats::candump::LoggedFrame;
use aer_host::reports::counters::Counters;
use embedded_can::{Frame as _, StandardId};
use socketcan::SocketOptions as _;
use std::io::ErrorKind;
use std::os::fd::{AsRawFd, BorrowedFd};
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::sync::mpsc;
use tokio_util::sync::CancellationToken;
use tracing::{error, info, warn};

/// Flow-control frames waiting for a bus writer.
const REPLY_QUEUE: usize = 64;
/// Inputs waiting between the bus readers and the batching task.
const READ_QUEUE: usize = 4_096;
/// How often a reader checks that its interface is still the one it opened, and the kernel
/// ISO-TP reader looks at the cancellation token: a stop takes at most this long.
const WATCH: Duration = Duration::from_millis(250);
/// The receive queue each socket asks for: about 2.5 s of the car's traffic, so a reader
/// stalled for a moment loses nothing (the kernel caps it at `net.core.rmem_max`, which the
/// package raises to this; what still overflows is counted).
const RECEIVE_BUFFER: usize = 4 << 20;
/// Between attempts to open a missing or failing interface.
const RETRY: Duration = Duration::from_secs(1);

/// The kernel's index of the interface called `name` now (`None`: there is none). Read from
/// sysfs, which the service's sandbox leaves readable.
fn interface_index(name: &str) -> Option<u32> {
    let path = std::path::Path::new("/sys/class/net")
        .join(name)
        .join("ifindex");
    std::fs::read_to_string(path).ok()?.trim().parse().ok()
}

/// True when the interface called `name` is up (`IFF_UP` in sysfs's flags).
fn interface_up(name: &str) -> bool {
    let path = std::path::Path::new("/sys/class/net")
        .join(name)
        .join("flags");
    std::fs::read_to_string(path)
        .ok()
        .and_then(|flags| u32::from_str_radix(flags.trim().trim_start_matches("0x"), 16).ok())
        .is_some_and(|flags| flags & 0x1 != 0)
}

/// Why an interface cannot be opened, when it is not there.
fn missing(name: &str) -> String {
    format!("no interface called {name}")
}

/// Starts a reader per interface (and the kernel ISO-TP reader on the telemetry interface)
/// feeding `out`; returns where ingest sends flow control.
pub fn start(
    interfaces: &[String],
    telemetry_interface: &str,
    isotp: IsoTpMode,
    out: Sender,
    counters: &Arc<Counters>,
    health: &Arc<Health>,
    cancel: &CancellationToken,
) -> Replies {
    let (inputs_tx, inputs_rx) = mpsc::channel::<Input>(READ_QUEUE);
    let kernel = isotp == IsoTpMode::Kernel;
    let mut replies = Replies::default();
    let mut announcements = Vec::new();
    for (index, name) in interfaces.iter().enumerate() {
        let bus = u8::try_from(index).unwrap_or(u8::MAX);
        announcements.push(Input::Bus {
            index: bus,
            name: name.as_str().into(),
        });
        let (reply_tx, reply_rx) = mpsc::channel(REPLY_QUEUE);
        let telemetry_bus = name == telemetry_interface;
        if telemetry_bus && !kernel {
            replies.insert(bus, reply_tx);
        }
        tokio::spawn(read_bus(
            name.clone(),
            bus,
            inputs_tx.clone(),
            reply_rx,
            counters.clone(),
            health.clone(),
            cancel.clone(),
        ));
        if telemetry_bus && kernel {
            let (name, inputs, cancel) = (name.clone(), inputs_tx.clone(), cancel.clone());
            let (counters, health) = (counters.clone(), health.clone());
            std::thread::Builder::new()
                .name("isotp".into())
                .spawn(move || kernel_isotp(&name, bus, &inputs, &counters, &health, &cancel))
                .ok();
        }
    }
    tokio::spawn(batch(announcements, inputs_rx, out));
    replies
}

/// Hands everything that has arrived on as one batch, then waits for more.
async fn batch(announcements: Vec<Input>, mut inputs: mpsc::Receiver<Input>, out: Sender) {
    let mut batcher = Batcher::new(out);
    for announcement in announcements {
        if !batcher.push(announcement).await {
            return;
        }
    }
    loop {
        let input = match inputs.try_recv() {
            Ok(input) => input,
            Err(_) => {
                if !batcher.flush().await {
                    return;
                }
                match inputs.recv().await {
                    Some(input) => input,
                    None => return,
                }
            }
        };
        if !batcher.push(input).await {
            return;
        }
    }
}

/// Reads whole telemetry packets from the kernel's ISO-TP socket (blocking, own thread; its
/// reads time out every [`WATCH`] so that it sees a stop and a vanished interface).
fn kernel_isotp(
    name: &str,
    bus: u8,
    inputs: &mpsc::Sender<Input>,
    counters: &Counters,
    health: &Health,
    cancel: &CancellationToken,
) {
    let (Some(rx), Some(tx)) = (
        StandardId::new(Telemetry::TX_ID),
        StandardId::new(Telemetry::FLOW_CONTROL_ID),
    ) else {
        return;
    };
    let part = format!("{name} ISO-TP");
    let mut failures = Failures::new(REPORT_EVERY);
    let mut announced = false;
    let mut opened_before = false;
    while !cancel.is_cancelled() {
        let opened = interface_index(name)
            .ok_or_else(|| missing(name))
            .and_then(|index| {
                let ifindex = i32::try_from(index).map_err(|_| missing(name))?;
                let socket = socketcan_isotp::IsoTpSocket::open_if(ifindex, rx, tx)
                    .map_err(|err| err.to_string())?;
                with_options(&socket, |socket| socket.set_read_timeout(Some(WATCH)))
                    .map_err(|err| err.to_string())?;
                enlarge_receive_queue(&socket);
                Ok((index, socket))
            });
        let (index, mut socket) = match opened {
            Ok(opened) => opened,
            Err(error) => {
                health.can.failed(&part, &error);
                if let Some(attempts) = failures.failed(Instant::now()) {
                    error!(interface = %name, %error, attempts, "cannot open the kernel ISO-TP socket (modprobe can-isotp); retrying every second");
                }
                sleep_unless_cancelled(RETRY, cancel);
                continue;
            }
        };
        health.can.recovered(&part);
        if opened_before {
            Counters::bump(&counters.can_reopened);
        }
        opened_before = true;
        if !announced {
            info!(interface = %name, "reading telemetry from the kernel's ISO-TP socket");
            announced = true;
        }
        let mut drops = QueueDrops::default();
        let mut link_is_down = false;
        let error = loop {
            if cancel.is_cancelled() {
                return;
            }
            drops.count(&socket, &counters.can_rx_overflows);
            match socket.read() {
                Ok(packet) => {
                    if let Some(attempts) = failures.recovered() {
                        health.can.recovered(&part);
                        info!(interface = %name, failed_attempts = attempts, "ISO-TP telemetry arriving again");
                    }
                    let input = Input::Packet {
                        ts_us: now_us(),
                        bus,
                        packet: packet.to_vec(),
                    };
                    if inputs.blocking_send(input).is_err() {
                        return;
                    }
                }
                // The read timeout: a look at the token and the interface.
                Err(err) if err.kind() == ErrorKind::WouldBlock => {
                    if interface_index(name) != Some(index) {
                        break format!("the interface went away (it had index {index})");
                    }
                    if link_is_down && interface_up(name) {
                        link_is_down = false;
                        link_up(&part, health, &mut failures);
                    }
                }
                // A packet the kernel gave up on (a lost or repeated consecutive frame, the
                // sender gone quiet mid-packet): counted like userspace reassembly's errors;
                // the socket goes on with the next packet.
                Err(err) if is_packet_error(&err) => {
                    let count = Counters::bump(&counters.isotp_errors);
                    if aer_host::reports::counters::worth_logging(count) {
                        warn!(interface = %name, error = %err, count, "ISO-TP packet dropped by the kernel");
                    }
                }
                // The link went down (an administrator, systemd-networkd reconfiguring it):
                // the socket stays bound and reads again once it is up.
                Err(err) if err.raw_os_error() == Some(libc::ENETDOWN) => {
                    link_is_down = true;
                    link_down(&part, &err, health, &mut failures);
                }
                Err(err) => break err.to_string(),
            }
        };
        health.can.failed(&part, &error);
        if let Some(attempts) = failures.failed(Instant::now()) {
            error!(interface = %name, %error, attempts, "ISO-TP read failed; reopening every second");
        }
        sleep_unless_cancelled(RETRY, cancel);
    }
}

/// A socket's link went down: reported (the status names it until the link is up again or
/// frames come), not reopened. Reopening would lose a second of traffic each time
/// systemd-networkd or an administrator takes the link down and up, and the socket reads
/// again by itself.
fn link_down(part: &str, err: &std::io::Error, health: &Health, failures: &mut Failures) {
    let error = err.to_string();
    health.can.failed(part, &error);
    if let Some(attempts) = failures.failed(Instant::now()) {
        warn!(interface = %part, %error, attempts, "CAN link down; reading on when it is up");
    }
}

/// The link of a socket reported down is up again: the status clears at once, not only at
/// the next frame (a quiet bus would leave it reported for ever).
fn link_up(part: &str, health: &Health, failures: &mut Failures) {
    health.can.recovered(part);
    if let Some(attempts) = failures.recovered() {
        info!(interface = %part, failed_attempts = attempts, "CAN link up again");
    }
}

/// True for the errors the kernel's ISO-TP socket reports about one packet (`net/can/isotp.c`:
/// a wrong sequence number, a receive or flow-control timeout, a packet too long for its
/// buffer), as opposed to the socket or its interface failing.
fn is_packet_error(err: &std::io::Error) -> bool {
    matches!(
        err.raw_os_error(),
        Some(libc::EILSEQ | libc::ETIMEDOUT | libc::ECOMM | libc::EMSGSIZE | libc::EBADMSG)
    )
}

/// What the kernel dropped from a socket's receive queue since the last look.
#[derive(Debug, Default)]
struct QueueDrops {
    seen: u64,
}

impl QueueDrops {
    /// Adds the drops since the last look at `socket` to `counter`.
    fn count(&mut self, socket: &impl AsRawFd, counter: &std::sync::atomic::AtomicU64) {
        let Some(drops) = queue_drops(socket) else {
            return;
        };
        let new = drops.saturating_sub(self.seen);
        self.seen = drops;
        if new > 0 {
            counter.fetch_add(new, std::sync::atomic::Ordering::Relaxed);
        }
    }
}

/// The frames (or packets) the kernel dropped from `socket`'s receive queue since it was
/// opened because the queue was full; `None` if the kernel does not say.
fn queue_drops(socket: &impl AsRawFd) -> Option<u64> {
    // SK_MEMINFO_VARS is 9 on every kernel since 4.6; room for more costs nothing.
    let mut info = [0u32; 16];
    let mut len = libc::socklen_t::try_from(std::mem::size_of_val(&info)).ok()?;
    // SAFETY: `info` is writable for `len` bytes and the kernel writes at most `len`.
    let read = unsafe {
        libc::getsockopt(
            socket.as_raw_fd(),
            libc::SOL_SOCKET,
            libc::SO_MEMINFO,
            info.as_mut_ptr().cast(),
            &mut len,
        )
    };
    let drops = usize::try_from(libc::SK_MEMINFO_DROPS).ok()?;
    let written = usize::try_from(len).ok()? / std::mem::size_of::<u32>();
    (read == 0 && written > drops)
        .then(|| info.get(drops).copied().map(u64::from))
        .flatten()
}

/// Runs `f` on `socket` as a socket2 socket, for the options the CAN crates do not offer.
fn with_options<T>(socket: &impl AsRawFd, f: impl FnOnce(socket2::SockRef<'_>) -> T) -> T {
    // SAFETY: the descriptor is `socket`'s, open for as long as `socket`, which outlives
    // this borrow (it ends with the call).
    let fd = unsafe { BorrowedFd::borrow_raw(socket.as_raw_fd()) };
    f(socket2::SockRef::from(&fd))
}

/// Asks for [`RECEIVE_BUFFER`]; a smaller queue (the kernel's cap) still works.
fn enlarge_receive_queue(socket: &impl AsRawFd) {
    let _ = with_options(socket, |socket| socket.set_recv_buffer_size(RECEIVE_BUFFER));
}

/// Waits `wait` on this thread, or less once `cancel` fires.
fn sleep_unless_cancelled(wait: Duration, cancel: &CancellationToken) {
    let until = Instant::now() + wait;
    while !cancel.is_cancelled() {
        let left = until.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return;
        }
        std::thread::sleep(left.min(WATCH));
    }
}

/// Opens the raw CAN socket on the interface called `name` now: its index and the socket,
/// error frames included.
fn open_raw(name: &str) -> Result<(u32, socketcan::tokio::CanSocket), String> {
    let index = interface_index(name).ok_or_else(|| missing(name))?;
    let socket = socketcan::tokio::CanSocket::open_if(index).map_err(|err| err.to_string())?;
    socket
        .set_error_filter_accept_all()
        .map_err(|err| err.to_string())?;
    enlarge_receive_queue(&socket);
    Ok((index, socket))
}

/// Reads one interface, and writes the flow control ingest sends back for it.
async fn read_bus(
    name: String,
    bus: u8,
    inputs: mpsc::Sender<Input>,
    mut replies: mpsc::Receiver<aer_isotp::Frame>,
    counters: Arc<Counters>,
    health: Arc<Health>,
    cancel: CancellationToken,
) {
    let mut failures = Failures::new(REPORT_EVERY);
    let mut announced = false;
    let mut opened_before = false;
    while !cancel.is_cancelled() {
        let (index, socket) = match open_raw(&name) {
            Ok(opened) => opened,
            Err(error) => {
                health.can.failed(&name, &error);
                if let Some(attempts) = failures.failed(Instant::now()) {
                    error!(interface = %name, %error, attempts, "cannot open CAN interface; retrying every second");
                }
                tokio::select! {
                    () = tokio::time::sleep(RETRY) => continue,
                    () = cancel.cancelled() => return,
                }
            }
        };
        // The interface is there; the log waits for frames before it calls it recovered, so
        // a link that opens and fails every read is still reported once a minute.
        health.can.recovered(&name);
        if opened_before {
            Counters::bump(&counters.can_reopened);
        }
        opened_before = true;
        if !announced {
            info!(interface = %name, "reading CAN");
            announced = true;
        }
        let mut watch = tokio::time::interval(WATCH);
        watch.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        let mut drops = QueueDrops::default();
        let mut link_is_down = false;
        let error = loop {
            tokio::select! {
                () = cancel.cancelled() => return,
                read = socket.read_frame() => match read {
                    Ok(socketcan::CanFrame::Error(_)) => {
                        Counters::bump(&counters.can_error_frames);
                    }
                    Ok(frame) => {
                        if let Some(attempts) = failures.recovered() {
                            health.can.recovered(&name);
                            info!(interface = %name, failed_attempts = attempts, "CAN frames arriving again");
                        }
                        let logged = LoggedFrame::new(now_us(), bus, frame.id(), frame.data());
                        if let Some(logged) = logged
                            && inputs.send(Input::Frame(logged)).await.is_err() {
                                return;
                            }
                    }
                    Err(err) if err.raw_os_error() == Some(libc::ENETDOWN) => {
                        link_is_down = true;
                        link_down(&name, &err, &health, &mut failures);
                    }
                    Err(err) => break err.to_string(),
                },
                Some(fc) = replies.recv() => {
                    let frame = StandardId::new(Telemetry::FLOW_CONTROL_ID)
                        .and_then(|id| socketcan::CanFrame::new(id, fc.as_slice()));
                    if let Some(frame) = frame
                        && let Err(err) = socket.write_frame(frame).await {
                            error!(interface = %name, error = %err, "flow control not sent");
                        }
                }
                _ = watch.tick() => {
                    drops.count(&socket, &counters.can_rx_overflows);
                    if interface_index(&name) != Some(index) {
                        break format!("the interface went away (it had index {index})");
                    }
                    if link_is_down && interface_up(&name) {
                        link_is_down = false;
                        link_up(&name, &health, &mut failures);
                    }
                }
            }
        };
        health.can.failed(&name, &error);
        if let Some(attempts) = failures.failed(Instant::now()) {
            error!(interface = %name, %error, attempts, "CAN read failed; reopening every second");
        }
        tokio::select! {
            () = tokio::time::sleep(RETRY) => {}
            () = cancel.cancelled() => return,
        }
    }
}
