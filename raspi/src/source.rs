//! Where frames come from: a recorded candump log, the synthetic vehicle, or live SocketCAN.
//! All of them feed the same [`Pipeline`].

use crate::candump::{LoggedFrame, parse_line};
use crate::ingest::{Ingest, Record};
use crate::metrics::{Counters, worth_logging};
use crate::pipeline::Pipeline;
use aer::telemetry::{Telemetry, TelemetryHeader};
use std::collections::HashMap;
use std::io::BufRead;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, SystemTime, UNIX_EPOCH};
use tokio::time::Instant;
use tracing::warn;

/// Microseconds since the Unix epoch, now.
pub fn now_us() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_micros()).unwrap_or(u64::MAX))
}

/// Frames a fast replay takes between handing its records to the broker.
const FLUSH_FRAMES: u64 = 256;

/// How a log is replayed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReplayOptions {
    /// As fast as possible instead of at recorded speed.
    pub fast: bool,
    /// Stamp frames with the time they are replayed instead of the recorded time (the demo:
    /// the data looks live to subscribers).
    pub restamp: bool,
}

/// What a replay did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ReplayStats {
    pub lines: u64,
    pub frames: u64,
    pub bad_lines: u64,
}

/// Replays a candump log through `pipeline` until its end or `stop`.
pub async fn replay(
    log: impl BufRead,
    pipeline: &mut Pipeline,
    counters: &Counters,
    options: ReplayOptions,
    stop: &AtomicBool,
) -> ReplayStats {
    let mut stats = ReplayStats::default();
    let mut interfaces: HashMap<String, u8> = HashMap::new();
    let mut origin: Option<(u64, Instant)> = None;
    for (number, line) in log.lines().enumerate() {
        if stop.load(Ordering::Relaxed) {
            break;
        }
        stats.lines += 1;
        let line = match line {
            Ok(line) => line,
            Err(error) => {
                // Not UTF-8 or unreadable: count it like any broken line.
                stats.bad_lines += 1;
                let count = Counters::bump(&counters.bad_lines);
                if worth_logging(count) {
                    warn!(line = number + 1, %error, count, "unreadable log line");
                }
                continue;
            }
        };
        if line.trim().is_empty() {
            continue;
        }
        let parsed = parse_line(&line, |name| {
            let next = u8::try_from(interfaces.len()).unwrap_or(u8::MAX);
            *interfaces.entry(name.to_owned()).or_insert_with(|| {
                pipeline.bus_names_mut().push(name.into());
                next
            })
        });
        let mut frame = match parsed {
            Ok(frame) => frame,
            Err(error) => {
                stats.bad_lines += 1;
                let count = Counters::bump(&counters.bad_lines);
                if worth_logging(count) {
                    warn!(line = number + 1, %error, count, "log line skipped");
                }
                continue;
            }
        };
        if options.fast {
            if stats.frames % FLUSH_FRAMES == 0 {
                pipeline.flush();
            }
        } else {
            let (first_us, start) = *origin.get_or_insert((frame.ts_us, Instant::now()));
            let due = start + Duration::from_micros(frame.ts_us.saturating_sub(first_us));
            if due > Instant::now() {
                pipeline.flush();
                tokio::time::sleep_until(due).await;
            }
        }
        if options.restamp {
            frame.ts_us = now_us();
        }
        stats.frames += 1;
        // A replay cannot answer the CCM: flow control is computed and dropped.
        pipeline.feed(&frame, |_, _| {});
    }
    pipeline.flush();
    stats
}

/// Replays a whole log as fast as possible with its recorded timestamps (tests, benchmarks).
pub async fn replay_all(log: &[u8], pipeline: &mut Pipeline, counters: &Counters) -> ReplayStats {
    let options = ReplayOptions {
        fast: true,
        restamp: false,
    };
    replay(log, pipeline, counters, options, &AtomicBool::new(false)).await
}

/// A candump log decoded as the pipeline decodes it, without outputs.
#[derive(Debug)]
pub struct DecodedLog {
    /// Every telemetry packet: receive time (us since the epoch), header and values.
    pub packets: Vec<(u64, TelemetryHeader, Telemetry)>,
    /// What decoding counted (frames, errors, the firmware fingerprint seen, ...).
    pub counters: Arc<Counters>,
}

/// Decodes a whole log in memory with its recorded timestamps (tests, benchmarks, the
/// dashboard's screenshots). Broken lines are counted in `bad_lines`, as in a replay.
pub fn decode_log(log: &str) -> DecodedLog {
    let counters = Arc::new(Counters::default());
    let mut ingest = Ingest::new(counters.clone());
    let mut buses: HashMap<String, u8> = HashMap::new();
    let mut packets = Vec::new();
    for line in log.lines().filter(|line| !line.trim().is_empty()) {
        let parsed = parse_line(line, |name| {
            let next = u8::try_from(buses.len()).unwrap_or(u8::MAX);
            *buses.entry(name.to_owned()).or_insert(next)
        });
        let Ok(frame) = parsed else {
            Counters::bump(&counters.bad_lines);
            continue;
        };
        ingest.on_frame(
            &frame,
            |record| {
                if let Record::Telemetry {
                    ts_us,
                    header,
                    telemetry,
                    ..
                } = record
                {
                    packets.push((ts_us, header, *telemetry));
                }
            },
            |_, _| {},
        );
    }
    DecodedLog { packets, counters }
}

/// Frames of a synthetic vehicle: see [`crate::synthetic`].
pub async fn synthetic(
    rate_hz: f64,
    pipeline: &mut Pipeline,
    stop: &AtomicBool,
    limit: Option<u64>,
) {
    let mut vehicle = crate::synthetic::Vehicle::new();
    pipeline.bus_names_mut().push("can0".into());
    let period = Duration::from_secs_f64(1.0 / rate_hz.max(0.001));
    let mut next = Instant::now();
    let mut packets = 0u64;
    while !stop.load(Ordering::Relaxed) && limit.is_none_or(|limit| packets < limit) {
        next += period;
        for frame in vehicle.step(period.as_secs_f64(), now_us()) {
            pipeline.feed(&frame, |_, _| {});
        }
        packets += 1;
        pipeline.flush();
        tokio::time::sleep_until(next).await;
    }
}

/// Live SocketCAN: every configured interface is read (and reopened with a 1 s backoff when
/// missing or failing). With kernel ISO-TP the telemetry arrives as whole packets from the
/// can-isotp socket (which sends the flow control itself); otherwise the service reassembles
/// it from raw frames and sends the flow control on the telemetry interface.
#[cfg(target_os = "linux")]
pub async fn socketcan(
    interfaces: Vec<String>,
    telemetry_interface: &str,
    isotp: crate::config::IsoTpMode,
    pipeline: &mut Pipeline,
    stop: Arc<AtomicBool>,
) {
    use tokio::sync::mpsc;
    let (frames_tx, mut frames_rx) = mpsc::channel::<Input>(4_096);
    let kernel = isotp == crate::config::IsoTpMode::Kernel;
    let mut replies = Vec::new();
    for (index, name) in interfaces.iter().enumerate() {
        pipeline.bus_names_mut().push(name.as_str().into());
        let (reply_tx, reply_rx) = mpsc::channel::<aer_isotp::Frame>(64);
        let telemetry_bus = name == telemetry_interface;
        replies.push((telemetry_bus && !kernel).then_some(reply_tx));
        let bus = u8::try_from(index).unwrap_or(u8::MAX);
        tokio::spawn(bus_task(
            name.clone(),
            bus,
            frames_tx.clone(),
            reply_rx,
            stop.clone(),
        ));
        if telemetry_bus && kernel {
            let (name, frames, stop) = (name.clone(), frames_tx.clone(), stop.clone());
            std::thread::Builder::new()
                .name("isotp".into())
                .spawn(move || kernel_isotp(&name, bus, &frames, &stop))
                .ok();
        }
    }
    drop(frames_tx);
    loop {
        // Everything that has arrived, then hand it to the broker before waiting again.
        let input = match frames_rx.try_recv() {
            Ok(input) => input,
            Err(_) => {
                pipeline.flush();
                match frames_rx.recv().await {
                    Some(input) => input,
                    None => break,
                }
            }
        };
        if stop.load(Ordering::Relaxed) {
            break;
        }
        match input {
            Input::Frame(frame) => pipeline.feed(&frame, |bus, fc| {
                if let Some(Some(reply)) = replies.get(usize::from(bus)) {
                    // The bus task writes it; if its queue is full the CCM's sender times out
                    // (N_Bs) and its next packet starts afresh.
                    let _ = reply.try_send(fc);
                }
            }),
            Input::Packet { ts_us, bus, packet } => pipeline.feed_packet(ts_us, bus, &packet),
        }
    }
}

/// What the live sources hand the pipeline.
#[cfg(target_os = "linux")]
enum Input {
    Frame(LoggedFrame),
    Packet {
        ts_us: u64,
        bus: u8,
        packet: Vec<u8>,
    },
}

/// Reads whole telemetry packets from the kernel's ISO-TP socket (blocking, own thread).
#[cfg(target_os = "linux")]
fn kernel_isotp(
    name: &str,
    bus: u8,
    packets: &tokio::sync::mpsc::Sender<Input>,
    stop: &AtomicBool,
) {
    use aer::telemetry::Telemetry;
    use embedded_can::StandardId;
    use tracing::{error, info};
    let (Some(rx), Some(tx)) = (
        StandardId::new(Telemetry::TX_ID),
        StandardId::new(Telemetry::FLOW_CONTROL_ID),
    ) else {
        return;
    };
    while !stop.load(Ordering::Relaxed) {
        let mut socket = match socketcan_isotp::IsoTpSocket::open(name, rx, tx) {
            Ok(socket) => socket,
            Err(err) => {
                error!(interface = %name, error = %err, "cannot open the kernel ISO-TP socket (modprobe can-isotp); retrying in 1 s");
                std::thread::sleep(Duration::from_secs(1));
                continue;
            }
        };
        info!(interface = %name, "reading telemetry from the kernel's ISO-TP socket");
        loop {
            match socket.read() {
                Ok(packet) => {
                    let input = Input::Packet {
                        ts_us: now_us(),
                        bus,
                        packet: packet.to_vec(),
                    };
                    if packets.blocking_send(input).is_err() {
                        return;
                    }
                }
                Err(err) => {
                    error!(interface = %name, error = %err, "ISO-TP read failed; reopening in 1 s");
                    break;
                }
            }
        }
        std::thread::sleep(Duration::from_secs(1));
    }
}

#[cfg(target_os = "linux")]
async fn bus_task(
    name: String,
    bus: u8,
    frames: tokio::sync::mpsc::Sender<Input>,
    mut replies: tokio::sync::mpsc::Receiver<aer_isotp::Frame>,
    stop: Arc<AtomicBool>,
) {
    use embedded_can::{Frame as _, StandardId};
    use tracing::{error, info};
    while !stop.load(Ordering::Relaxed) {
        let socket = match socketcan::tokio::CanSocket::open(&name) {
            Ok(socket) => socket,
            Err(err) => {
                error!(interface = %name, error = %err, "cannot open CAN interface; retrying in 1 s");
                tokio::time::sleep(Duration::from_secs(1)).await;
                continue;
            }
        };
        info!(interface = %name, "reading CAN");
        loop {
            tokio::select! {
                read = socket.read_frame() => match read {
                    Ok(frame) => {
                        let logged = LoggedFrame::new(now_us(), bus, frame.id(), frame.data());
                        if let Some(logged) = logged {
                            if frames.send(Input::Frame(logged)).await.is_err() {
                                return;
                            }
                        }
                    }
                    Err(err) => {
                        error!(interface = %name, error = %err, "CAN read failed; reopening in 1 s");
                        break;
                    }
                },
                Some(fc) = replies.recv() => {
                    let frame = StandardId::new(aer::telemetry::Telemetry::FLOW_CONTROL_ID)
                        .and_then(|id| socketcan::CanFrame::new(id, fc.as_slice()));
                    if let Some(frame) = frame {
                        if let Err(err) = socket.write_frame(frame).await {
                            error!(interface = %name, error = %err, "flow control not sent");
                        }
                    }
                }
            }
        }
        tokio::time::sleep(Duration::from_secs(1)).await;
    }
}
