//! The car on the desk: the closed loop runs in real time (one model millisecond per
//! millisecond of the wall clock, catching up at once after a stall) and its CCM's XCP slave
//! answers a calibration tool (CANape, INCA, pyxcp) as on the car, so a tuner can try the
//! A2L, the DAQ lists, the refusals, a save and a second launch before the car exists.
//!
//! Masters reach it through [`crate::masters`], whose threads never hold up the model. One
//! master holds the slave at a time, for as long as its XCP session lasts: from its CONNECT to
//! its DISCONNECT or the session's end. Any other client that sends a command meanwhile is
//! answered ERR_RESOURCE_TEMPORARY_NOT_ACCESSIBLE (busy) and disconnected, never left waiting;
//! a client outside a session holds nothing. The session ends with its transport (a closed or
//! broken connection), when the master stops reading (its queue fills: dropped, not obeyed),
//! and when the slave's idle time-out ends it; the slot is then free. A client the desk has
//! dropped or told busy is forgotten: what it had still queued is ignored.

use crate::masters::{ClientId, Inbound, NotSent, Outbox, Transport};
use aer_car_model::chassis::Mode;
use aer_car_model::driver::{Activity, Cycle, PARK_MS, STAND_MS};
use aer_car_model::faults::FaultPlan;
use aer_car_model::{ClosedLoop, ModelParams, NoTap, XcpCar};
use aer_ccm::calibration::store::RamFlash;
use aer_ccm::xcp::SECRET_LEN;
use aer_xcp::protocol::{err, pid};
use aer_xcp::{MAX_CTO, SessionEnd};
use anyhow::{Context, Result, bail};
use std::collections::HashMap;
use std::path::Path;
use std::sync::mpsc::{RecvTimeoutError, TryRecvError};
use std::time::{Duration, Instant};

/// Commands handled in one model millisecond at most: more than XCP on CAN can carry
/// (about 4 per ms at 500 kbit/s); a flooding master waits for the next millisecond.
pub const COMMANDS_PER_MS: usize = 32;

/// Reads the team's secret: 64 hex digits (the format of `ccm/xcp-secret.key`).
pub fn read_secret(path: &Path) -> Result<[u8; SECRET_LEN]> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("reading the XCP secret {}", path.display()))?;
    match aer_xcp::seed_key::parse_secret(&text) {
        Some(secret) => Ok(secret),
        None => bail!(
            "{}: the secret is {} hex digits, nothing else",
            path.display(),
            2 * SECRET_LEN
        ),
    }
}

/// What a desk run did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DeskReport {
    /// Model milliseconds run.
    pub model_ms: u32,
    /// Wall-clock time they took.
    pub wall: Duration,
    /// Steps that ran more than 10 ms after their time (the machine stalled the server).
    pub late_steps: u64,
    /// Clients that connected.
    pub clients: u64,
    /// Clients told busy (another master held the slave) and disconnected.
    pub told_busy: u64,
    /// Masters dropped because they stopped reading.
    pub stopped_reading: u64,
    /// Sessions the slave's idle time-out ended.
    pub idle_ended: u64,
    /// Sessions that ended with their transport.
    pub transport_ended: u64,
    /// Transport frames that were not XCP.
    pub malformed: u64,
}

impl DeskReport {
    /// Model time over wall time: 1.0 is real time.
    pub fn real_time_ratio(&self) -> f64 {
        let wall = self.wall.as_secs_f64();
        if wall > 0.0 {
            f64::from(self.model_ms) / 1_000.0 / wall
        } else {
            0.0
        }
    }
}

/// The error answer a second master gets: the slave is busy with another.
const BUSY: [u8; 2] = [pid::ERR, err::RESOURCE_TEMPORARY_NOT_ACCESSIBLE];

/// The desk: the car, its clients, the master.
struct Desk {
    car: XcpCar,
    clients: HashMap<ClientId, (String, Outbox)>,
    master: Option<ClientId>,
    report: DeskReport,
    activity: Activity,
    /// Clients told busy since the last line said so.
    busy_unsaid: u64,
    /// Late steps the last line said.
    late_said: u64,
    /// Parked, and the tractive system seen off.
    parked_off: bool,
}

impl Desk {
    fn handle(&mut self, event: Inbound) {
        match event {
            Inbound::Opened {
                client,
                peer,
                outbox,
            } => {
                self.report.clients += 1;
                self.clients.insert(client, (peer, outbox));
            }
            Inbound::Packet { client, packet } => self.command(client, &packet),
            Inbound::Malformed => self.report.malformed += 1,
            Inbound::Closed { client, malformed } => {
                if malformed {
                    self.report.malformed += 1;
                }
                if let Some((peer, _)) = self.clients.remove(&client) {
                    if self.master == Some(client) {
                        self.master = None;
                        if self.car.transport_lost().is_some() {
                            self.report.transport_ended += 1;
                            eprintln!("{peer}: connection ended: its XCP session ended with it");
                        }
                    }
                }
            }
        }
    }

    fn command(&mut self, client: ClientId, packet: &[u8]) {
        // A client dropped or told busy is gone: what it still had queued counts for nothing.
        if !self.clients.contains_key(&client) {
            return;
        }
        let master = *self.master.get_or_insert(client);
        if master != client {
            if let Some((_, outbox)) = self.clients.remove(&client) {
                let _ = outbox.send(&BUSY);
                outbox.finish();
                self.report.told_busy += 1;
                self.busy_unsaid += 1;
            }
            return;
        }
        let mut reply = [0u8; MAX_CTO];
        if let Some(len) = self.car.command(packet, &mut reply) {
            self.send_to_master(reply.get(..len).unwrap_or_default());
        }
        // Outside a session (before CONNECT, after DISCONNECT) a client holds nothing.
        if !self.car.is_connected() {
            self.master = None;
        }
    }

    /// Sends `packet` to the master; one that stopped reading is dropped, its session ended.
    fn send_to_master(&mut self, packet: &[u8]) -> bool {
        let Some(master) = self.master else {
            return false;
        };
        let sent = match self.clients.get(&master) {
            Some((_, outbox)) => outbox.send(packet),
            None => Err(NotSent::Gone),
        };
        match sent {
            Ok(()) => true,
            Err(NotSent::Full) => {
                self.report.stopped_reading += 1;
                self.end_master(true, "stopped reading: dropped, its XCP session ended");
                false
            }
            Err(NotSent::Gone) => false,
        }
    }

    /// Ends the master's session and its connection: at once (`now`: it stopped reading), or
    /// once what is queued for it has gone out.
    fn end_master(&mut self, now: bool, why: &str) {
        let Some(master) = self.master.take() else {
            return;
        };
        self.car.transport_lost();
        // A bus outlives its sessions: the next master may be any node on it.
        if let Some((peer, outbox)) = self.clients.get(&master)
            && outbox.is_lasting()
        {
            eprintln!("{peer}: {why}");
            return;
        }
        if let Some((peer, outbox)) = self.clients.remove(&master) {
            if now {
                outbox.close();
            } else {
                outbox.finish();
            }
            eprintln!("{peer}: {why}");
        }
    }

    /// One model millisecond: the car, its DAQ to the master, the slave's clock.
    fn step(&mut self) {
        let mut out = Vec::new();
        self.car.step(&mut NoTap, &mut |packet| {
            out.push(packet.to_vec());
            true
        });
        if let Some(ended) = self.car.poll(&mut |packet| {
            out.push(packet.to_vec());
            true
        }) {
            self.report.idle_ended += 1;
            if ended == SessionEnd::Idle {
                for packet in &out {
                    self.send_to_master(packet);
                }
                out.clear();
                self.end_master(
                    false,
                    "no command for the idle time-out: its XCP session ended",
                );
            } else {
                eprintln!("no command for the idle time-out: calibration locked, DAQ goes on");
            }
        }
        for packet in &out {
            if !self.send_to_master(packet) {
                break;
            }
        }
        let activity = self.car.run.car.driver.activity();
        if activity != self.activity {
            self.activity = activity;
            self.parked_off = false;
            say(activity);
        }
        // Parked: the tractive system takes about a second to fall below 60 V; the CCM
        // allows saving and the sensor parameters from then on.
        if activity == Activity::Parked
            && !self.parked_off
            && !self.car.run.ccm.vehicle_state().tractive_live
        {
            self.parked_off = true;
            eprintln!(
                "car: the tractive system is off now: saving and the pedal, brake and shock parameters are allowed until the next start"
            );
        }
        // Once a second at most: what a storm of clients or a stalled machine would otherwise
        // say a line at a time.
        if self.car.run.now_ms() % 1_000 == 0 {
            if self.busy_unsaid > 0 {
                eprintln!(
                    "{} client(s) told busy (another master holds the slave) and disconnected",
                    self.busy_unsaid
                );
                self.busy_unsaid = 0;
            }
            if self.report.late_steps > self.late_said {
                eprintln!(
                    "{} model millisecond(s) ran more than 10 ms late (the machine stalled the desk car; it caught up)",
                    self.report.late_steps - self.late_said
                );
                self.late_said = self.report.late_steps;
            }
        }
    }
}

/// What the driver does now, for the tuner at the desk.
fn say(activity: Activity) {
    let line = match activity {
        Activity::Starting => "car: starting (precharge, ready-to-move, the ready-to-drive sound)",
        Activity::Driving => "car: driving",
        Activity::Stopping => "car: braking to a stop",
        Activity::Standing => {
            "car: standing still with the tractive system live: launch parameters can change"
        }
        Activity::Parked => "car: parking: the tractive system switched off",
    };
    let seconds = match activity {
        Activity::Standing => format!(" (for {} s)", STAND_MS / 1_000),
        Activity::Parked => format!(" (parked for {} s)", PARK_MS / 1_000),
        _ => String::new(),
    };
    eprintln!("{line}{seconds}");
}

/// Runs `cycle` in real time and serves its slave on `transport` until `running` says stop
/// (it is asked every model millisecond). `entropy` (32 bytes from the operating system's
/// random source) seeds the slave's seeds.
pub fn serve(
    transport: &Transport,
    cycle: Cycle,
    secret: Option<[u8; SECRET_LEN]>,
    entropy: &[u8],
    mut running: impl FnMut(u32) -> bool,
) -> Result<DeskReport> {
    let run = ClosedLoop::new(ModelParams::NOMINAL, Mode::Road, cycle, FaultPlan::NONE);
    let mut desk = Desk {
        car: XcpCar::new(run, RamFlash::default(), secret, entropy),
        clients: HashMap::new(),
        master: None,
        report: DeskReport::default(),
        activity: Activity::Starting,
        busy_unsaid: 0,
        late_said: 0,
        parked_off: false,
    };
    say(desk.activity);
    let started = Instant::now();
    let mut ms: u32 = 0;
    while running(ms) {
        let due = started + Duration::from_millis(u64::from(ms) + 1);
        // Commands until this millisecond's step is due, at most COMMANDS_PER_MS of them.
        let mut handled = 0;
        while handled < COMMANDS_PER_MS {
            let now = Instant::now();
            let event = if now >= due {
                match transport.inbound.try_recv() {
                    Ok(event) => event,
                    Err(TryRecvError::Empty) => break,
                    Err(TryRecvError::Disconnected) => bail!("the transport stopped"),
                }
            } else {
                match transport.inbound.recv_timeout(due - now) {
                    Ok(event) => event,
                    Err(RecvTimeoutError::Timeout) => break,
                    Err(RecvTimeoutError::Disconnected) => bail!("the transport stopped"),
                }
            };
            if matches!(event, Inbound::Packet { .. }) {
                handled += 1;
            }
            desk.handle(event);
        }
        // A flooding master used up this millisecond's commands: the rest wait for the step.
        let now = Instant::now();
        if now < due {
            std::thread::sleep(due - now);
        } else if now > due + Duration::from_millis(10) {
            desk.report.late_steps += 1;
        }
        desk.step();
        ms = ms.wrapping_add(1);
    }
    desk.report.model_ms = ms;
    desk.report.wall = started.elapsed();
    for (_, outbox) in desk.clients.values() {
        outbox.close();
    }
    Ok(desk.report)
}
