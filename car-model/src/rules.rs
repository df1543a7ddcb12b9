//! The FSAE rules and the CCM's documented limits, checked as invariants on every millisecond
//! of a closed-loop run:
//! - every 100 ms moving average of the power drawn from the accumulator is at most 80 kW
//!   (EV.3.3.1);
//! - no torque outside DRIVING; never DRIVING unless the PCC's last status said ONLINE and
//!   is at most 100 ms old; the command never exceeds what the torque monitor allows;
//! - after each [`Condition`] begins, and for as long as it lasts, the torque is zero once
//!   the condition's allowed time has passed: in the CCM's command after that time plus one
//!   control period, and in what the inverter is asked for after one command period more.

use crate::car::Car;
use crate::faults::Fault;
use aer::can::PrechargeState;
use aer_ccm::ControlOutputs;
use aer_ccm::InverterKind;
use aer_ccm::constants::{
    APPS_BRAKE_TRIP, APPS_IMPLAUSIBLE, BMS_PACK_TIMEOUT_MS, BRAKES_ENGAGED_PSI, CONTROL_PERIOD_MS,
    DTI_SPEED_TIMEOUT_MS, MCU1_TIMEOUT_MS, PCC_STATUS_TIMEOUT_MS, PEDAL_DEADBAND,
    SAMPLE_TIMEOUT_MS, SENSOR_FAULT_PERSIST_MS,
};
use aer_ccm::vehicle::State;

/// How old the inverter's status may get before the CCM must stop (ms): its speed frame's
/// freshness limit, the same for both inverters.
const INVERTER_STATUS_TIMEOUT_MS: u32 = if MCU1_TIMEOUT_MS > DTI_SPEED_TIMEOUT_MS {
    MCU1_TIMEOUT_MS
} else {
    DTI_SPEED_TIMEOUT_MS
};

/// Slack for the sensor path: the converter's 2.3 ms per channel and the 100 Hz filter.
const SENSOR_SLACK_MS: u32 = 10;
/// How far past the 10 % implausibility threshold the signals must be before the condition
/// counts: the CCM sees them through the converter's noise (a count or two) and its filter,
/// and a difference hovering at the threshold is judged either way.
const MEASUREMENT_TOLERANCE: f32 = 0.01;
/// How many conditions there are.
const CONDITIONS: usize = 13;
/// The period of the status that carries an inverter's own fault (ms): MCU2 and DTI packet
/// 0x22 are both sent every 100 ms.
const INVERTER_FAULT_REPORT_MS: u32 = 100;
/// Samples in the power window (1 ms each).
const WINDOW: usize = 100;

/// Something after which the torque must stop.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Condition {
    /// The pedal sensors say the accelerator is released (the lower one within the rest
    /// deadband), and they agree.
    PedalReleased,
    /// The two pedal sensors' signals differ by more than 10 % of travel.
    PedalImplausible,
    /// A pedal sensor's signal is outside 10-90 % of its supply.
    PedalOutOfRange,
    /// The pedal converter delivers nothing.
    PedalSignalLost,
    /// The brakes are engaged with more than 25 % throttle on a pedal sensor.
    BrakesWithThrottle,
    /// The brake sensors read nonsense.
    BrakeSensorFault,
    /// The CCM's sensor sampling has stopped.
    SamplingStopped,
    /// The BMS is silent.
    BmsLost,
    /// The inverter is silent (or, for the IFL100, repeats a stuck frame).
    InverterLost,
    /// The inverter reports a fault of its own (it stops driving by itself; the CCM must
    /// stop asking).
    InverterFaulted,
    /// The PCC does not hold AIR+ closed (not ONLINE or CHARGING). On the team's board an
    /// open shutdown circuit drops AIR- and AIR+ in hardware at once; the PCC, which has no
    /// input that reads the shutdown circuit, knows only once the tractive system has fallen
    /// away (`PrechargeConfig::online_min_percent`), and the CCM only from the PCC's status.
    /// The deadline counts from when the PCC knows.
    PccNotOnline,
    /// CAN1 is off for the CCM.
    Can1Off,
    /// CAN2 is off for the CCM.
    Can2Off,
}

impl Condition {
    /// Every condition.
    pub const ALL: [Self; CONDITIONS] = [
        Self::PedalReleased,
        Self::PedalImplausible,
        Self::PedalOutOfRange,
        Self::PedalSignalLost,
        Self::BrakesWithThrottle,
        Self::BrakeSensorFault,
        Self::SamplingStopped,
        Self::BmsLost,
        Self::InverterLost,
        Self::InverterFaulted,
        Self::PccNotOnline,
        Self::Can1Off,
        Self::Can2Off,
    ];

    /// How long (ms) the torque may last after the condition begins, and where that limit
    /// comes from.
    pub const fn allowed(self) -> (u32, &'static str) {
        match self {
            Self::PedalReleased => (SENSOR_FAULT_PERSIST_MS, "T.4.2.5 (a stuck sensor)"),
            Self::PedalImplausible => (SENSOR_FAULT_PERSIST_MS, "T.4.2.5"),
            Self::PedalOutOfRange | Self::PedalSignalLost => (SENSOR_FAULT_PERSIST_MS, "T.4.2.10"),
            Self::BrakesWithThrottle => (500, "EV.4.7"),
            Self::BrakeSensorFault => (SENSOR_FAULT_PERSIST_MS, "T.4.3.4"),
            Self::SamplingStopped => (SAMPLE_TIMEOUT_MS, "SAMPLE_TIMEOUT_MS"),
            Self::BmsLost => (BMS_PACK_TIMEOUT_MS, "BMS_PACK_TIMEOUT_MS"),
            // The fault arrives in the 100 ms status (MCU2, DTI packet 0x22).
            Self::InverterFaulted => (INVERTER_FAULT_REPORT_MS, "MCU2 / DTI 0x22 period"),
            Self::InverterLost | Self::Can2Off => (
                INVERTER_STATUS_TIMEOUT_MS,
                "MCU1_TIMEOUT_MS, DTI_SPEED_TIMEOUT_MS",
            ),
            // The CCM learns it from the PCC's status; if status frames are lost on the way,
            // their freshness limit. (With the bus up it takes two PCC periods; the fault
            // tests check that.)
            Self::PccNotOnline => (PCC_STATUS_TIMEOUT_MS, "PCC_STATUS_TIMEOUT_MS"),
            Self::Can1Off => (PCC_STATUS_TIMEOUT_MS, "PCC_STATUS_TIMEOUT_MS"),
        }
    }

    /// Whether the condition holds in `car` at `now_ms`.
    pub fn holds(self, car: &Car, now_ms: u32) -> bool {
        let plan = &car.plan;
        let calibration = car.sensors.calibration();
        match self {
            // What the sensors say (the lower one, as the CCM reads it): with both stuck
            // high and agreeing, a released pedal cannot be seen (that double fault is what
            // the APPS/brake check is for). With one faulty the implausibility and range
            // conditions apply (T.4.2 allows them 100 ms).
            Self::PedalReleased => {
                let [a, b] = car.pedal.travels(&calibration);
                a.min(b) < PEDAL_DEADBAND - MEASUREMENT_TOLERANCE
                    && !Self::PedalImplausible.holds(car, now_ms)
                    && !Self::PedalOutOfRange.holds(car, now_ms)
            }
            Self::PedalImplausible => {
                let [a, b] = car.pedal.travels(&calibration);
                (a - b).abs() > APPS_IMPLAUSIBLE + MEASUREMENT_TOLERANCE
            }
            Self::PedalOutOfRange => car.pedal.out_of_range(),
            Self::PedalSignalLost => plan.is_active(now_ms, Fault::PedalConverterLost),
            Self::BrakesWithThrottle => {
                let [a, b] = car.pedal.travels(&calibration);
                car.command.brake_psi > BRAKES_ENGAGED_PSI.0
                    && a.max(b) > APPS_BRAKE_TRIP + MEASUREMENT_TOLERANCE
            }
            Self::BrakeSensorFault => plan.is_active(now_ms, Fault::BrakeSensorNan),
            Self::SamplingStopped => plan.is_active(now_ms, Fault::SamplingStopped),
            Self::BmsLost => plan.is_active(now_ms, Fault::BmsSilent),
            // A stuck IFL100 repeats frames whose counters the CCM refuses: as good as silent.
            // A stuck DTI's packets carry no counter, so the CCM cannot tell (only the power
            // rule and the other conditions hold then).
            Self::InverterLost => {
                plan.is_active(now_ms, Fault::InverterSilent)
                    || (plan.is_active(now_ms, Fault::InverterStuck)
                        && car.params.inverter == InverterKind::Ifl100)
            }
            Self::InverterFaulted => plan.is_active(now_ms, Fault::InverterFaulted),
            Self::PccNotOnline => !car.pcc.relays().air_plus,
            Self::Can1Off => plan.is_active(now_ms, Fault::BusOff(0)),
            Self::Can2Off => plan.is_active(now_ms, Fault::BusOff(1)),
        }
    }
}

/// One condition's progress in a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
struct Track {
    /// When the condition began (while it holds).
    onset: Option<u32>,
    /// The command, and the inverter's, have been zero since the onset.
    command_cut: bool,
    inverter_cut: bool,
}

/// Which rule a run broke.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Broken {
    /// A 100 ms average above 80 kW (W).
    PowerAverage(f32),
    /// Torque while not DRIVING (state, Nm).
    TorqueOutsideDriving(State, f32),
    /// DRIVING without a fresh ONLINE from the PCC.
    DrivingWithoutPrecharge,
    /// A command above the monitor's allowance (command, allowed).
    AboveMonitor(f32, f32),
    /// Torque in the CCM's command after a condition's deadline (Nm).
    CommandNotCut(Condition, f32),
    /// Torque asked of the inverter after a condition's deadline (Nm).
    InverterNotCut(Condition, f32),
}

/// The first broken rule of a run, when it happened, and how many times rules broke.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Violation {
    /// When (ms).
    pub at_ms: u32,
    /// What.
    pub broken: Broken,
}

/// What a run measured.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Stats {
    /// Highest 100 ms average of accumulator power (W).
    pub worst_100ms_w: f32,
    /// Per condition (in [`Condition::ALL`] order): the longest time from its start to zero
    /// torque in the CCM's command and in the inverter's, among the times it happened long
    /// enough to see the cut (ms).
    pub cut_ms: [(Option<u32>, Option<u32>); CONDITIONS],
}

/// Checks a run.
#[derive(Debug, Clone)]
pub struct Rules {
    jitter_ms: u32,
    window: [f32; WINDOW],
    next: usize,
    filled: usize,
    tracks: [Track; CONDITIONS],
    /// The last time CAN2 was off.
    can2_off_until: Option<u32>,
    last_pcc: Option<(PrechargeState, u32)>,
    stats: Stats,
    first: Option<Violation>,
    count: u32,
}

impl Rules {
    /// Checks for a car whose frames may be `jitter_ms` late.
    pub fn new(jitter_ms: u32) -> Self {
        Self {
            jitter_ms,
            window: [0.0; WINDOW],
            next: 0,
            filled: 0,
            tracks: [Track::default(); CONDITIONS],
            can2_off_until: None,
            last_pcc: None,
            stats: Stats::default(),
            first: None,
            count: 0,
        }
    }

    /// Fresh checks and statistics from now on, for frames up to `jitter_ms` late,
    /// remembering the last PCC status the CCM received.
    pub fn restart(&self, jitter_ms: u32) -> Self {
        Self {
            last_pcc: self.last_pcc,
            ..Self::new(jitter_ms)
        }
    }

    /// The first violation, if any.
    pub fn first_violation(&self) -> Option<Violation> {
        self.first
    }

    /// How many times a rule broke.
    pub fn violations(&self) -> u32 {
        self.count
    }

    /// What the run measured.
    pub fn stats(&self) -> Stats {
        self.stats
    }

    /// A PCC status reached the CCM at `now_ms`.
    pub fn pcc_status(&mut self, state: PrechargeState, now_ms: u32) {
        self.last_pcc = Some((state, now_ms));
    }

    /// Every millisecond: the accumulator power and the conditions holding now, and the
    /// torque the inverter is asked for.
    pub fn millisecond(&mut self, now_ms: u32, car: &Car, inverter_nm: f32) {
        let power = car.power_w;
        if let Some(slot) = self.window.get_mut(self.next) {
            *slot = power;
        }
        self.next = (self.next + 1) % WINDOW;
        self.filled = (self.filled + 1).min(WINDOW);
        if self.filled == WINDOW {
            let average = self.window.iter().sum::<f32>() / WINDOW as f32;
            self.stats.worst_100ms_w = self.stats.worst_100ms_w.max(average);
            if average > car.params.limits.power_limit_w {
                self.broke(now_ms, Broken::PowerAverage(average));
            }
        }
        // While CAN2 is off, and until the next command after it is back, the CCM cannot
        // reach the inverter: only the inverter's own command timeout (the `Can2Off`
        // deadline) holds.
        let inverter = car.params.inverter;
        let can2_off = Condition::Can2Off.holds(car, now_ms);
        if can2_off {
            self.can2_off_until = Some(now_ms);
        }
        let inverter_reachable = self
            .can2_off_until
            .is_none_or(|until| now_ms.wrapping_sub(until) > inverter.command_period_ms());
        let mut late = None;
        let tracks = self.tracks.iter_mut().zip(self.stats.cut_ms.iter_mut());
        for (condition, (track, cut_ms)) in Condition::ALL.into_iter().zip(tracks) {
            match (condition.holds(car, now_ms), track.onset) {
                (true, None) => {
                    *track = Track {
                        onset: Some(now_ms),
                        ..Track::default()
                    };
                }
                (false, Some(_)) => track.onset = None,
                _ => {}
            }
            let Some(onset) = track.onset else { continue };
            let elapsed = now_ms.wrapping_sub(onset);
            if inverter_nm == 0.0 {
                if !track.inverter_cut {
                    track.inverter_cut = true;
                    record(&mut cut_ms.1, elapsed);
                }
            } else if elapsed > inverter_deadline(condition, self.jitter_ms, inverter)
                && (inverter_reachable || condition == Condition::Can2Off)
            {
                late = Some(Broken::InverterNotCut(condition, inverter_nm));
            }
        }
        if let Some(broken) = late {
            self.broke(now_ms, broken);
        }
    }

    /// Every control step: the CCM's outputs.
    pub fn control(&mut self, now_ms: u32, outputs: &ControlOutputs) {
        let torque = outputs.torque.torque_nm;
        let state = outputs.vehicle.state;
        if state != State::Driving && torque != 0.0 {
            self.broke(now_ms, Broken::TorqueOutsideDriving(state, torque));
        }
        if torque > outputs.torque.allowed_nm {
            self.broke(
                now_ms,
                Broken::AboveMonitor(torque, outputs.torque.allowed_nm),
            );
        }
        if state == State::Driving {
            let fresh_online = self.last_pcc.is_some_and(|(pcc, at)| {
                pcc == PrechargeState::Online && now_ms.wrapping_sub(at) <= PCC_STATUS_TIMEOUT_MS
            });
            if !fresh_online {
                self.broke(now_ms, Broken::DrivingWithoutPrecharge);
            }
        }
        let mut late = None;
        let tracks = self.tracks.iter_mut().zip(self.stats.cut_ms.iter_mut());
        for (condition, (track, cut_ms)) in Condition::ALL.into_iter().zip(tracks) {
            let Some(onset) = track.onset else { continue };
            let elapsed = now_ms.wrapping_sub(onset);
            if torque == 0.0 {
                if !track.command_cut {
                    track.command_cut = true;
                    record(&mut cut_ms.0, elapsed);
                }
            } else if elapsed > command_deadline(condition, self.jitter_ms) {
                late = Some(Broken::CommandNotCut(condition, torque));
            }
        }
        if let Some(broken) = late {
            self.broke(now_ms, broken);
        }
    }

    fn broke(&mut self, now_ms: u32, broken: Broken) {
        self.count += 1;
        if self.first.is_none() {
            self.first = Some(Violation {
                at_ms: now_ms,
                broken,
            });
        }
    }
}

/// Deadline (ms after a condition's onset) for the CCM's command, with frames up to
/// `jitter_ms` late.
pub fn command_deadline(condition: Condition, jitter_ms: u32) -> u32 {
    let (allowed, _) = condition.allowed();
    allowed + CONTROL_PERIOD_MS + SENSOR_SLACK_MS + jitter_ms
}

/// Deadline (ms after a condition's onset) for what the `inverter` is asked.
pub fn inverter_deadline(condition: Condition, jitter_ms: u32, inverter: InverterKind) -> u32 {
    use crate::params::powertrain::{DTI_COMMAND_TIMEOUT_MS, VCU1_TIMEOUT_MS};
    let period = inverter.command_period_ms();
    match (condition, inverter) {
        // The CCM cannot reach the inverter: the inverter's own command timeout stops it.
        (Condition::Can2Off, InverterKind::Ifl100) => VCU1_TIMEOUT_MS + period,
        (Condition::Can2Off, InverterKind::Dti) => DTI_COMMAND_TIMEOUT_MS + period,
        _ => command_deadline(condition, jitter_ms) + period,
    }
}

fn record(worst: &mut Option<u32>, elapsed: u32) {
    *worst = Some(worst.map_or(elapsed, |worst| worst.max(elapsed)));
}
