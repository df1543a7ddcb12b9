//! The fault bitmap (CCM_Status and the telemetry fault flags), what each fault makes the
//! car do, and the monitor that turns readings into faults.

use crate::apps::AppsReading;
use crate::brakes::BrakeReading;
use crate::bus::BusInputs;
use crate::constants::{
    MAX_TEMP_DEGC, MIN_CELL_V, PCC_TARGET_PERCENT, SENSOR_FAULT_PERSIST_MS, SOC_DERATE_END,
    TRACTIVE_MISMATCH_FRACTION, TRACTIVE_MISMATCH_LIVE_V, TRACTIVE_MISMATCH_MARGIN_V,
    TRACTIVE_MISMATCH_PERSIST_MS, TRACTIVE_OFF_V,
};
use aer::can::{PccStatus, PrechargeState};
use aer_control::Persist;

/// One fault bit. Bits 0-7 are the team's original bitmap (vehicle-facts.md); the rest are
/// the inputs the CCM lost or the inverter reported.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Fault {
    /// Pack current above the BMS's discharge limit for 100 ms.
    OverCurrent = 0,
    /// Lowest cell below 2.8 V for 100 ms.
    UnderVoltage = 1,
    /// Motor, inverter or pack over its temperature limit for 100 ms.
    OverTemperature = 2,
    /// APPS out of range or implausible for over 100 ms (T.4.2).
    Apps = 3,
    /// Brake pressure sensor out of range for over 100 ms (T.4.3).
    Bse = 4,
    /// Front and rear brake circuits implausible.
    Bpps = 5,
    /// Throttle with the brakes engaged (EV.4.7), until the throttle is released.
    AppsBrakePlausibility = 6,
    /// Accumulator SOC at or below 5 %: the end of the derating.
    LowBatteryVoltage = 7,
    /// The pedal converter delivered no conversion on a channel for 20 ms (T.4.2.10).
    PedalSignalLost = 8,
    /// The 1 kHz sensor sample is older than 10 ms: the sampling task stopped.
    SensorsStale = 9,
    /// A BMS frame the CCM acts on is older than its limit.
    BmsTimeout = 10,
    /// An inverter status frame is older than its limit.
    InverterTimeout = 11,
    /// The PCC's status is older than 100 ms.
    PccTimeout = 12,
    /// The inverter reports a fault: the IFL100's MCU2 fault bits or warning level HIGH; the
    /// DTI's fault code, a CAN map other than the schema's, or drive enable not as commanded.
    InverterFault = 13,
    /// The inverter reports a warning: the IFL100's low DC or 12 V, a sensor state, warning
    /// level LOW or MEDIUM; a DTI "limit active" bit.
    InverterWarning = 14,
    /// The PCC reports ERROR (or a state the schema does not know): the accumulator is
    /// disconnected; the PCC's own error bits say why.
    PccError = 15,
    /// The PCC's tractive-system reading and the inverter's DC link disagree (one at 60 V or
    /// more, apart by more than the two measurements can be) for 500 ms: they measure one
    /// node, so one of them is wrong, and the tractive system may be live where it reads dead.
    TractiveMismatch = 16,
}

/// What a fault makes the car do.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reaction {
    /// Reported only; the car keeps driving.
    Warn,
    /// Zero torque while it lasts; the car stays in DRIVING.
    CutTorque,
    /// Zero torque and the vehicle goes to FAULT; once it clears, STANDBY, and the driver
    /// needs the ready-to-drive procedure again.
    Stop,
}

impl Fault {
    /// Every fault, in bit order.
    pub const ALL: [Self; 17] = [
        Self::OverCurrent,
        Self::UnderVoltage,
        Self::OverTemperature,
        Self::Apps,
        Self::Bse,
        Self::Bpps,
        Self::AppsBrakePlausibility,
        Self::LowBatteryVoltage,
        Self::PedalSignalLost,
        Self::SensorsStale,
        Self::BmsTimeout,
        Self::InverterTimeout,
        Self::PccTimeout,
        Self::InverterFault,
        Self::InverterWarning,
        Self::PccError,
        Self::TractiveMismatch,
    ];

    /// The fault's bit.
    pub const fn mask(self) -> u32 {
        1 << self as u8
    }

    /// The reaction. EV.4.7 only asks that the motor stops while the pedals disagree, so the
    /// plausibility fault cuts torque and keeps DRIVING; an inverter warning is reported.
    pub const fn reaction(self) -> Reaction {
        match self {
            Self::AppsBrakePlausibility => Reaction::CutTorque,
            Self::InverterWarning => Reaction::Warn,
            _ => Reaction::Stop,
        }
    }
}

/// Active faults, one bit each (32 bits as in the team's design).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FaultMap(u32);

impl FaultMap {
    /// No fault.
    pub const NONE: Self = Self(0);

    /// Sets or clears `fault`.
    pub fn set(&mut self, fault: Fault, active: bool) {
        if active {
            self.0 |= fault.mask();
        } else {
            self.0 &= !fault.mask();
        }
    }

    /// Whether `fault` is active.
    pub const fn has(&self, fault: Fault) -> bool {
        self.0 & fault.mask() != 0
    }

    /// The raw bitmap.
    pub const fn bits(&self) -> u32 {
        self.0
    }

    /// Any fault at all, warnings included.
    pub const fn any(&self) -> bool {
        self.0 != 0
    }

    /// Any fault whose reaction includes zero torque.
    pub fn stops_torque(&self) -> bool {
        self.any_with(|reaction| reaction != Reaction::Warn)
    }

    /// Any fault that puts the vehicle in FAULT.
    pub fn stops_the_vehicle(&self) -> bool {
        self.any_with(|reaction| reaction == Reaction::Stop)
    }

    fn any_with(&self, wanted: impl Fn(Reaction) -> bool) -> bool {
        Fault::ALL
            .iter()
            .any(|fault| self.has(*fault) && wanted(fault.reaction()))
    }
}

/// Everything the fault checks read in one control step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FaultInputs<'a> {
    /// Free-running milliseconds.
    pub now_ms: u32,
    /// Fresh bus values and lost nodes.
    pub bus: &'a BusInputs,
    /// The pedal.
    pub apps: AppsReading,
    /// The brakes.
    pub brakes: BrakeReading,
    /// The last sensor sample is older than its limit.
    pub sensors_stale: bool,
}

/// Turns readings into the fault bitmap; readings-based faults must persist 100 ms.
#[derive(Debug, Clone, Default)]
pub struct FaultMonitor {
    over_current: Persist,
    under_voltage: Persist,
    over_temperature: Persist,
    tractive_mismatch: Persist,
}

impl FaultMonitor {
    /// Evaluates every fault.
    pub fn evaluate(&mut self, inputs: &FaultInputs<'_>) -> FaultMap {
        let now_ms = inputs.now_ms;
        let bus = inputs.bus;
        let persists = |persist: &mut Persist, condition: bool| {
            persist
                .update(condition, now_ms)
                .is_some_and(|held| held > SENSOR_FAULT_PERSIST_MS)
        };
        let mut map = FaultMap::NONE;

        let over_current = bus.pack.zip(bus.limits).is_some_and(|(pack, limits)| {
            pack.orion_pack_current > f64::from(limits.orion_pack_dcl)
        });
        map.set(
            Fault::OverCurrent,
            persists(&mut self.over_current, over_current),
        );
        let under_voltage = bus
            .cells
            .is_some_and(|cells| cells.orion_low_cell_voltage < f64::from(MIN_CELL_V));
        map.set(
            Fault::UnderVoltage,
            persists(&mut self.under_voltage, under_voltage),
        );
        let (motor_max, inverter_max, pack_max) = MAX_TEMP_DEGC;
        let hot = |degc: f32, max: f32| degc > max;
        let over_temperature = bus
            .inverter
            .temperatures_degc
            .is_some_and(|(inverter, motor)| hot(motor, motor_max) || hot(inverter, inverter_max))
            || bus
                .limits
                .is_some_and(|limits| hot(f32::from(limits.orion_high_temperature), pack_max));
        map.set(
            Fault::OverTemperature,
            persists(&mut self.over_temperature, over_temperature),
        );

        map.set(Fault::Apps, inputs.apps.sensor_fault());
        map.set(Fault::Bse, inputs.brakes.sensor_fault);
        map.set(Fault::Bpps, inputs.brakes.circuits_implausible);
        map.set(Fault::AppsBrakePlausibility, inputs.apps.brake_plausibility);
        let empty = bus
            .pack
            .is_some_and(|pack| pack.orion_pack_soc / 100.0 <= f64::from(SOC_DERATE_END));
        map.set(Fault::LowBatteryVoltage, empty);

        map.set(Fault::PedalSignalLost, inputs.apps.signal_lost);
        map.set(Fault::SensorsStale, inputs.sensors_stale);
        map.set(Fault::BmsTimeout, bus.lost.bms);
        map.set(Fault::InverterTimeout, bus.lost.inverter);
        map.set(Fault::PccTimeout, bus.lost.pcc);
        map.set(Fault::InverterFault, bus.inverter.fault);
        map.set(Fault::InverterWarning, bus.inverter.warning);
        let pcc_error = bus.pcc.is_some_and(|status| pcc_reports_error(&status));
        map.set(Fault::PccError, pcc_error);
        let mismatch = bus
            .pcc
            .zip(bus.inverter.dc_link)
            .is_some_and(|(pcc, (dti_v, _))| tractive_readings_disagree(&pcc, dti_v));
        let mismatch = self
            .tractive_mismatch
            .update(mismatch, now_ms)
            .is_some_and(|held| held >= TRACTIVE_MISMATCH_PERSIST_MS);
        map.set(Fault::TractiveMismatch, mismatch);
        map
    }
}

/// The PCC's tractive-system reading (its converter silent counts as 0 V: what it reports as
/// the voltage) and the inverter's DC link measure one node, whatever the AIRs do: they
/// disagree when either reads 60 V or more and they differ by more than
/// [`TRACTIVE_MISMATCH_FRACTION`] of the higher plus [`TRACTIVE_MISMATCH_MARGIN_V`] (the two
/// filters' lag while the tractive system rises or falls), and whenever one reads it dead
/// (below 60 V) and the other [`TRACTIVE_MISMATCH_LIVE_V`] or more.
pub fn tractive_readings_disagree(pcc: &PccStatus, dti_v: f32) -> bool {
    let pcc_v = if pcc.pcc_tractive_no_pulses || pcc.pcc_error_tractive_silent {
        0.0
    } else {
        pcc.pcc_tractive_voltage as f32
    };
    if !dti_v.is_finite() {
        return false;
    }
    let (lower, higher) = (pcc_v.min(dti_v), pcc_v.max(dti_v));
    let apart =
        (pcc_v - dti_v).abs() > higher * TRACTIVE_MISMATCH_FRACTION + TRACTIVE_MISMATCH_MARGIN_V;
    let dead_and_live = lower < TRACTIVE_OFF_V && higher >= TRACTIVE_MISMATCH_LIVE_V;
    higher >= TRACTIVE_OFF_V && (apart || dead_and_live)
}

/// The PCC reports a fault, or a status no working PCC sends: its ERROR or UNDEFINED state
/// (or one the schema does not name), any cause in any state, or, while it says the tractive
/// system is connected (ONLINE, CHARGING), a converter without pulses (a voltage it cannot
/// know), progress below the precharge target or a tractive system below 60 V (AIR+ cannot
/// be closed on that).
pub fn pcc_reports_error(status: &PccStatus) -> bool {
    let latched = status.pcc_error_too_fast
        || status.pcc_error_too_slow
        || status.pcc_error_bms_timeout
        || status.pcc_error_shutdown
        || status.pcc_error_air_plus_open
        || status.pcc_error_converters_disagree
        || status.pcc_error_bypassed
        || status.pcc_error_resistor_hot
        || status.pcc_error_accumulator_silent
        || status.pcc_error_tractive_silent
        || status.pcc_error_no_discharge
        || status.pcc_error_undefined_state;
    let connected = matches!(
        status.pcc_state,
        PrechargeState::Online | PrechargeState::Charging
    );
    let blind = status.pcc_accumulator_no_pulses || status.pcc_tractive_no_pulses;
    let contradicted = status.pcc_precharge_progress < f64::from(PCC_TARGET_PERCENT)
        || status.pcc_tractive_voltage < f64::from(TRACTIVE_OFF_V);
    matches!(
        status.pcc_state,
        PrechargeState::Error | PrechargeState::Undefined | PrechargeState::Unknown(_)
    ) || latched
        || (connected && (blind || contradicted))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn status(state: PrechargeState) -> PccStatus {
        PccStatus {
            pcc_state: state,
            pcc_error_air_plus_open: false,
            pcc_error_converters_disagree: false,
            pcc_error_bypassed: false,
            pcc_error_resistor_hot: false,
            pcc_accumulator_no_pulses: false,
            pcc_tractive_no_pulses: false,
            pcc_error_too_fast: false,
            pcc_error_too_slow: false,
            pcc_error_bms_timeout: false,
            pcc_error_shutdown: false,
            pcc_error_accumulator_silent: false,
            pcc_error_tractive_silent: false,
            pcc_error_no_discharge: false,
            pcc_error_undefined_state: false,
            pcc_accumulator_voltage: 392.0,
            pcc_tractive_voltage: 392.0,
            pcc_precharge_progress: 100.0,
        }
    }

    #[test]
    fn a_working_pcc_online_or_at_rest_is_no_error() {
        assert!(!pcc_reports_error(&status(PrechargeState::Online)));
        // At rest an LM331 gives no pulses at 0 V: no pulses is not a fault there.
        let rest = PccStatus {
            pcc_accumulator_no_pulses: true,
            pcc_tractive_no_pulses: true,
            pcc_tractive_voltage: 0.0,
            ..status(PrechargeState::Standby)
        };
        assert!(!pcc_reports_error(&rest));
        // DISCHARGE (the pack's reading lost while energised): AIR+ open, no cause latched.
        let discharge = PccStatus {
            pcc_tractive_voltage: 200.0,
            pcc_precharge_progress: 50.0,
            ..status(PrechargeState::Discharge)
        };
        assert!(!pcc_reports_error(&discharge));
    }

    #[test]
    fn online_with_readings_it_cannot_have_is_an_error() {
        for state in [PrechargeState::Online, PrechargeState::Charging] {
            let below_target = PccStatus {
                pcc_precharge_progress: 89.0,
                ..status(state)
            };
            assert!(pcc_reports_error(&below_target), "{state:?} at 89 %");
            let dead = PccStatus {
                pcc_tractive_voltage: 0.0,
                pcc_accumulator_voltage: 0.0,
                pcc_precharge_progress: 0.0,
                ..status(state)
            };
            assert!(pcc_reports_error(&dead), "{state:?} at 0 V");
        }
    }

    #[test]
    fn error_undefined_and_unnamed_states_are_errors() {
        for state in [
            PrechargeState::Error,
            PrechargeState::Undefined,
            PrechargeState::Unknown(9),
        ] {
            assert!(pcc_reports_error(&status(state)), "{state:?}");
        }
    }

    #[test]
    fn every_latched_cause_is_an_error_whatever_the_state_says() {
        let latched: [fn(&mut PccStatus); 12] = [
            |s| s.pcc_error_too_fast = true,
            |s| s.pcc_error_too_slow = true,
            |s| s.pcc_error_bms_timeout = true,
            |s| s.pcc_error_shutdown = true,
            |s| s.pcc_error_air_plus_open = true,
            |s| s.pcc_error_converters_disagree = true,
            |s| s.pcc_error_bypassed = true,
            |s| s.pcc_error_resistor_hot = true,
            |s| s.pcc_error_accumulator_silent = true,
            |s| s.pcc_error_tractive_silent = true,
            |s| s.pcc_error_no_discharge = true,
            |s| s.pcc_error_undefined_state = true,
        ];
        for (index, set) in latched.iter().enumerate() {
            for state in [PrechargeState::Online, PrechargeState::Standby] {
                let mut lying = status(state);
                set(&mut lying);
                assert!(pcc_reports_error(&lying), "cause {index} in {state:?}");
            }
        }
    }

    #[test]
    fn the_pcc_and_the_inverter_disagree_only_beyond_what_two_readings_can() {
        let reading = |volts: f64| PccStatus {
            pcc_tractive_voltage: volts,
            ..status(PrechargeState::Standby)
        };
        // Both dead, both live and close, a discharge's lag: agreed.
        assert!(!tractive_readings_disagree(&reading(0.0), 2.0));
        assert!(!tractive_readings_disagree(&reading(392.0), 385.0));
        assert!(!tractive_readings_disagree(&reading(300.0), 240.0));
        // The PCC reads dead where the inverter reads live, or the reverse.
        assert!(tractive_readings_disagree(&reading(8.0), 392.0));
        assert!(tractive_readings_disagree(&reading(392.0), 5.0));
        // Dead on one side, live on the other, however close the numbers.
        for (pcc, dti) in [(59.0, 70.0), (40.0, 99.0), (50.0, 80.0)] {
            assert!(
                tractive_readings_disagree(&reading(pcc), dti),
                "{pcc} V / {dti} V"
            );
            assert!(
                tractive_readings_disagree(&reading(f64::from(dti)), pcc as f32),
                "{dti} V / {pcc} V"
            );
        }
        assert!(
            !tractive_readings_disagree(&reading(59.0), 65.0),
            "both near the limit"
        );
        // A PCC converter without pulses reports 0 V, whatever the frame's number says.
        let silent = PccStatus {
            pcc_tractive_no_pulses: true,
            ..reading(392.0)
        };
        assert!(tractive_readings_disagree(&silent, 392.0));
        // An inverter reading that is not a number proves nothing either way.
        assert!(!tractive_readings_disagree(&reading(0.0), f32::NAN));
    }

    #[test]
    fn connected_without_pulses_is_an_error() {
        for state in [PrechargeState::Online, PrechargeState::Charging] {
            for (accumulator, tractive) in [(true, false), (false, true)] {
                let blind = PccStatus {
                    pcc_accumulator_no_pulses: accumulator,
                    pcc_tractive_no_pulses: tractive,
                    ..status(state)
                };
                assert!(pcc_reports_error(&blind), "{state:?}");
            }
        }
    }
}
