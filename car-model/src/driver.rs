//! The driver: the start-up procedure (wait for the tractive system, ready-to-move button
//! with the brake held, the ready-to-drive sound), then a drive cycle, as a driver would do
//! it from what the dashboard shows. After a fault the driver brakes to a stop and starts
//! again once the car is ready.

use crate::rng::Rng;
use aer_ccm::vehicle::State;

/// What the driver does after the start-up.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Cycle {
    /// FSAE acceleration: launch control armed on the line, full throttle for 75 m, brake.
    Acceleration,
    /// Skidpad-like: a steady 13 m/s on part throttle.
    Skidpad,
    /// Autocross: random straights, brakes and corners, with throttle/brake overlaps where a
    /// driver changes feet late.
    Autocross,
    /// Full throttle throughout (on the dynamometer).
    FullThrottle,
    /// The desk car's practice loop for a tuner: a launch and 75 m at full throttle, a stop,
    /// [`STAND_MS`] at standstill with the tractive system live (launch parameters change
    /// only at standstill), then [`PARK_MS`] parked with the tractive system off (saving, and
    /// the pedal, brake and shock parameters, need it), and again.
    Practice,
}

/// How long the practice loop stands still with the tractive system live (ms).
pub const STAND_MS: u32 = 20_000;
/// How long the practice loop stays parked with the tractive system off (ms).
pub const PARK_MS: u32 = 30_000;

/// The driver's hands and feet this millisecond.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DriverCommand {
    /// Accelerator pedal travel (0..1).
    pub pedal: f32,
    /// Front brake line pressure (psi).
    pub brake_psi: f32,
    /// Ready-to-move button.
    pub ready_to_move: bool,
    /// Launch-control button.
    pub launch: bool,
    /// The driver parked the car: the tractive-system master switch off, so the shutdown
    /// circuit is open.
    pub park: bool,
}

/// What the driver sees.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Seen {
    /// Now (ms).
    pub now_ms: u32,
    /// The vehicle state on the dashboard.
    pub vehicle: State,
    /// Car speed (m/s).
    pub speed_m_s: f32,
    /// The car stands still (or is strapped to a dynamometer).
    pub stopped: bool,
    /// Distance travelled (m).
    pub distance_m: f32,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Phase {
    /// Waiting for the car to be ready (IDLE).
    WaitForIdle,
    /// Brake held, ready-to-move button pressed.
    PressButton { since_ms: u32 },
    /// Brake held while the ready-to-drive sound plays.
    WaitForDrive,
    /// On the launch line: brake held, launch button pressed.
    Launch { since_ms: u32 },
    /// Foot off the brake, not yet on the throttle (a driver changes feet, and the CCM latches
    /// the APPS/brake plausibility fault if both are pressed).
    ChangeFeet { since_ms: u32 },
    /// Off the throttle at the end of the cycle, about to brake.
    Lift { since_ms: u32 },
    /// Driving the cycle, started at this distance.
    Drive { start_m: f32 },
    /// Braking to a stop after the cycle or a fault.
    Stop,
    /// Practice: standing still, brake held, tractive system live.
    Stand { since_ms: u32 },
    /// Practice: parked, the tractive system off.
    Park { since_ms: u32 },
}

/// Where the driver is, for people watching the desk car.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Activity {
    /// Starting the car: waiting for the tractive system, ready-to-move, the sound.
    Starting,
    /// Launching or driving the cycle.
    Driving,
    /// Braking to a stop.
    Stopping,
    /// Standing still with the tractive system live.
    Standing,
    /// Parked with the tractive system off.
    Parked,
}

/// What a driver does in an autocross segment.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    /// Full or nearly full throttle.
    Straight,
    /// Off the throttle before braking.
    Lift,
    /// Late foot change: braking with the throttle still partly open.
    Overlap,
    /// Braking.
    Brake,
    /// Off the brake before the throttle.
    Coast,
    /// Part throttle through a corner.
    Corner,
}

/// One segment of an autocross lap.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Segment {
    kind: Kind,
    until_ms: u32,
    pedal: f32,
    brake_psi: f32,
}

/// A driver following `cycle`.
#[derive(Debug, Clone)]
pub struct Driver {
    cycle: Cycle,
    phase: Phase,
    rng: Rng,
    segment: Segment,
}

/// Brake pressure the driver holds while stopped (psi).
const HOLD_PSI: f32 = 120.0;
/// Acceleration event length (m).
const ACCELERATION_M: f32 = 75.0;
/// Skidpad speed (m/s).
const SKIDPAD_M_S: f32 = 13.0;
/// Time between lifting one foot and pressing the other pedal (ms).
const FOOT_CHANGE_MS: u32 = 150;

impl Driver {
    /// A driver about to start the car, then drive `cycle`; `seed` picks the autocross course.
    pub fn new(cycle: Cycle, seed: u32) -> Self {
        Self {
            cycle,
            phase: Phase::WaitForIdle,
            rng: Rng::new(seed),
            segment: Segment {
                kind: Kind::Coast,
                until_ms: 0,
                pedal: 0.0,
                brake_psi: 0.0,
            },
        }
    }

    /// The drive cycle.
    pub fn cycle(&self) -> Cycle {
        self.cycle
    }

    /// True once the start-up is done and the cycle is being driven.
    pub fn driving(&self) -> bool {
        matches!(self.phase, Phase::Drive { .. })
    }

    /// What the driver is doing now.
    pub fn activity(&self) -> Activity {
        match self.phase {
            Phase::WaitForIdle | Phase::PressButton { .. } | Phase::WaitForDrive => {
                Activity::Starting
            }
            Phase::Launch { .. } | Phase::ChangeFeet { .. } | Phase::Drive { .. } => {
                Activity::Driving
            }
            Phase::Lift { .. } | Phase::Stop => Activity::Stopping,
            Phase::Stand { .. } => Activity::Standing,
            Phase::Park { .. } => Activity::Parked,
        }
    }

    /// What the driver does now.
    pub fn command(&mut self, seen: &Seen) -> DriverCommand {
        let hold = DriverCommand {
            pedal: 0.0,
            brake_psi: HOLD_PSI,
            ready_to_move: false,
            launch: false,
            park: false,
        };
        let now = seen.now_ms;
        match self.phase {
            Phase::WaitForIdle => {
                if seen.vehicle == State::Idle && seen.stopped {
                    self.phase = Phase::PressButton { since_ms: now };
                }
                hold
            }
            Phase::PressButton { since_ms } => {
                if now.wrapping_sub(since_ms) >= 300 {
                    self.phase = Phase::WaitForDrive;
                }
                DriverCommand {
                    ready_to_move: true,
                    ..hold
                }
            }
            Phase::WaitForDrive => {
                match seen.vehicle {
                    State::Driving => {
                        self.phase = if matches!(self.cycle, Cycle::Acceleration | Cycle::Practice)
                        {
                            Phase::Launch { since_ms: now }
                        } else {
                            Phase::ChangeFeet { since_ms: now }
                        };
                    }
                    State::Idle => {}
                    _ => self.phase = Phase::Stop,
                }
                hold
            }
            Phase::Launch { since_ms } => {
                if seen.vehicle != State::Driving {
                    self.phase = Phase::Stop;
                    return hold;
                }
                if now.wrapping_sub(since_ms) < 200 {
                    // Brake held, launch button pressed: launch control arms.
                    DriverCommand {
                        launch: true,
                        ..hold
                    }
                } else {
                    self.phase = Phase::ChangeFeet { since_ms: now };
                    DriverCommand::default()
                }
            }
            Phase::ChangeFeet { since_ms } => {
                if seen.vehicle != State::Driving {
                    self.phase = Phase::Stop;
                    return hold;
                }
                if now.wrapping_sub(since_ms) >= FOOT_CHANGE_MS {
                    self.phase = Phase::Drive {
                        start_m: seen.distance_m,
                    };
                }
                DriverCommand::default()
            }
            Phase::Drive { start_m } => {
                if seen.vehicle != State::Driving {
                    self.phase = Phase::Stop;
                    return hold;
                }
                self.drive(seen, start_m)
            }
            Phase::Lift { since_ms } => {
                if now.wrapping_sub(since_ms) >= FOOT_CHANGE_MS {
                    self.phase = Phase::Stop;
                }
                DriverCommand::default()
            }
            Phase::Stop => {
                if seen.stopped && self.cycle == Cycle::Practice {
                    self.phase = Phase::Stand { since_ms: now };
                } else if seen.stopped && seen.vehicle == State::Idle {
                    self.phase = Phase::PressButton { since_ms: now };
                }
                DriverCommand {
                    brake_psi: if seen.stopped { HOLD_PSI } else { 500.0 },
                    ..hold
                }
            }
            Phase::Stand { since_ms } => {
                if now.wrapping_sub(since_ms) >= STAND_MS {
                    self.phase = Phase::Park { since_ms: now };
                }
                hold
            }
            Phase::Park { since_ms } => {
                if now.wrapping_sub(since_ms) >= PARK_MS {
                    self.phase = Phase::WaitForIdle;
                    return hold;
                }
                DriverCommand { park: true, ..hold }
            }
        }
    }

    fn drive(&mut self, seen: &Seen, start_m: f32) -> DriverCommand {
        match self.cycle {
            Cycle::Acceleration | Cycle::Practice => {
                if seen.distance_m - start_m >= ACCELERATION_M {
                    self.phase = Phase::Lift {
                        since_ms: seen.now_ms,
                    };
                    DriverCommand::default()
                } else {
                    DriverCommand {
                        pedal: 1.0,
                        ..DriverCommand::default()
                    }
                }
            }
            Cycle::Skidpad => DriverCommand {
                pedal: (0.3 + 0.2 * (SKIDPAD_M_S - seen.speed_m_s)).clamp(0.0, 1.0),
                ..DriverCommand::default()
            },
            Cycle::FullThrottle => DriverCommand {
                pedal: 1.0,
                ..DriverCommand::default()
            },
            Cycle::Autocross => {
                if seen.now_ms >= self.segment.until_ms {
                    self.segment = self.next_segment(seen.now_ms);
                }
                DriverCommand {
                    pedal: self.segment.pedal,
                    brake_psi: self.segment.brake_psi,
                    ..DriverCommand::default()
                }
            }
        }
    }

    /// The next autocross segment: a straight ends by lifting and braking (one time in four
    /// braking with the throttle still partly open for up to 0.3 s), braking ends with a coast
    /// onto the throttle, then a corner or another straight.
    fn next_segment(&mut self, now_ms: u32) -> Segment {
        let rng = &mut self.rng;
        let change = (FOOT_CHANGE_MS, FOOT_CHANGE_MS + 1);
        // (kind, length range in ms, pedal range, brake range in psi)
        let (kind, (low, high), pedal, brake) = match self.segment.kind {
            Kind::Straight if rng.below(4) == 0 => {
                (Kind::Overlap, (80, 300), (0.3, 0.5), (200.0, 500.0))
            }
            Kind::Straight => (Kind::Lift, change, (0.0, 0.0), (0.0, 0.0)),
            Kind::Lift | Kind::Overlap => (Kind::Brake, (400, 1_500), (0.0, 0.0), (200.0, 900.0)),
            Kind::Brake => (Kind::Coast, change, (0.0, 0.0), (0.0, 0.0)),
            Kind::Coast | Kind::Corner if rng.below(2) == 0 => {
                (Kind::Corner, (800, 3_000), (0.15, 0.5), (0.0, 0.0))
            }
            Kind::Coast | Kind::Corner => (Kind::Straight, (800, 3_000), (0.7, 1.0), (0.0, 0.0)),
        };
        Segment {
            kind,
            until_ms: now_ms + low + rng.below(high - low),
            pedal: rng.range(pedal.0, pedal.1),
            brake_psi: rng.range(brake.0, brake.1),
        }
    }
}
