//! Live SocketCAN: every configured interface is read (and reopened with a 1 s backoff when
//! missing or failing; the log says so at once, then once a minute, and the status names the
//! interface until it works). With kernel ISO-TP the telemetry arrives as whole packets from the
//! can-isotp socket (which sends the flow control itself); otherwise ingest reassembles it
//! from raw frames and its flow control goes out through this source's bus writer
//! ([`Replies`]).

use super::failures::{Failures, REPORT_EVERY};
use super::{Batcher, Input, Replies, Sender};
use crate::config::IsoTpMode;
use crate::health::Health;
use aer::telemetry::Telemetry;
use aer_host::candump::LoggedFrame;
use aer_host::clock::now_us;
use embedded_can::{Frame as _, StandardId};
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::sync::mpsc;
use tokio_util::sync::CancellationToken;
use tracing::{error, info};

/// Flow-control frames waiting for a bus writer.
const REPLY_QUEUE: usize = 64;
/// Inputs waiting between the bus readers and the batching task.
const READ_QUEUE: usize = 4_096;

/// Starts a reader per interface (and the kernel ISO-TP reader on the telemetry interface)
/// feeding `out`; returns where ingest sends flow control.
pub fn start(
    interfaces: &[String],
    telemetry_interface: &str,
    isotp: IsoTpMode,
    out: Sender,
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
            health.clone(),
            cancel.clone(),
        ));
        if telemetry_bus && kernel {
            let (name, inputs, cancel) = (name.clone(), inputs_tx.clone(), cancel.clone());
            let health = health.clone();
            std::thread::Builder::new()
                .name("isotp".into())
                .spawn(move || kernel_isotp(&name, bus, &inputs, &health, &cancel))
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

/// Reads whole telemetry packets from the kernel's ISO-TP socket (blocking, own thread).
fn kernel_isotp(
    name: &str,
    bus: u8,
    inputs: &mpsc::Sender<Input>,
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
    while !cancel.is_cancelled() {
        let mut socket = match socketcan_isotp::IsoTpSocket::open(name, rx, tx) {
            Ok(socket) => socket,
            Err(err) => {
                health.can.failed(&part, &err.to_string());
                if let Some(attempts) = failures.failed(Instant::now()) {
                    error!(interface = %name, error = %err, attempts, "cannot open the kernel ISO-TP socket (modprobe can-isotp); retrying every second");
                }
                std::thread::sleep(Duration::from_secs(1));
                continue;
            }
        };
        health.can.recovered(&part);
        if !announced {
            info!(interface = %name, "reading telemetry from the kernel's ISO-TP socket");
            announced = true;
        }
        loop {
            match socket.read() {
                Ok(packet) => {
                    if let Some(attempts) = failures.recovered() {
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
                Err(err) => {
                    health.can.failed(&part, &err.to_string());
                    if let Some(attempts) = failures.failed(Instant::now()) {
                        error!(interface = %name, error = %err, attempts, "ISO-TP read failed; reopening every second");
                    }
                    break;
                }
            }
        }
        std::thread::sleep(Duration::from_secs(1));
    }
}

/// Reads one interface, and writes the flow control ingest sends back for it.
async fn read_bus(
    name: String,
    bus: u8,
    inputs: mpsc::Sender<Input>,
    mut replies: mpsc::Receiver<aer_isotp::Frame>,
    health: Arc<Health>,
    cancel: CancellationToken,
) {
    let mut failures = Failures::new(REPORT_EVERY);
    let mut announced = false;
    while !cancel.is_cancelled() {
        let socket = match socketcan::tokio::CanSocket::open(&name) {
            Ok(socket) => socket,
            Err(err) => {
                let error = err.to_string();
                health.can.failed(&name, &error);
                if let Some(attempts) = failures.failed(Instant::now()) {
                    error!(interface = %name, %error, attempts, "cannot open CAN interface; retrying every second");
                }
                tokio::select! {
                    () = tokio::time::sleep(Duration::from_secs(1)) => continue,
                    () = cancel.cancelled() => return,
                }
            }
        };
        // The interface is there; the log waits for frames before it calls it recovered, so
        // a link that opens and fails every read is still reported once a minute.
        health.can.recovered(&name);
        if !announced {
            info!(interface = %name, "reading CAN");
            announced = true;
        }
        loop {
            tokio::select! {
                () = cancel.cancelled() => return,
                read = socket.read_frame() => match read {
                    Ok(frame) => {
                        if let Some(attempts) = failures.recovered() {
                            info!(interface = %name, failed_attempts = attempts, "CAN frames arriving again");
                        }
                        let logged = LoggedFrame::new(now_us(), bus, frame.id(), frame.data());
                        if let Some(logged) = logged {
                            if inputs.send(Input::Frame(logged)).await.is_err() {
                                return;
                            }
                        }
                    }
                    Err(err) => {
                        let error = err.to_string();
                        health.can.failed(&name, &error);
                        if let Some(attempts) = failures.failed(Instant::now()) {
                            error!(interface = %name, %error, attempts, "CAN read failed; reopening every second");
                        }
                        break;
                    }
                },
                Some(fc) = replies.recv() => {
                    let frame = StandardId::new(Telemetry::FLOW_CONTROL_ID)
                        .and_then(|id| socketcan::CanFrame::new(id, fc.as_slice()));
                    if let Some(frame) = frame {
                        if let Err(err) = socket.write_frame(frame).await {
                            error!(interface = %name, error = %err, "flow control not sent");
                        }
                    }
                }
            }
        }
        tokio::select! {
            () = tokio::time::sleep(Duration::from_secs(1)) => {}
            () = cancel.cancelled() => return,
        }
    }
}
