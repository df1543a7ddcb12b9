//! The torque monitor: the last stage of the torque path.
//!
//! The automotive "level 2" idea: a second, deliberately simple computation of the torque
//! the car may have now, from the raw inputs and independent of launch control, traction
//! control and the power limiter's trim. The commanded torque never exceeds it, so a defect
//! in those controllers (or a state they wind up into) cannot make the car faster than the
//! driver, the rules or the inverter allow.

use crate::apps::AppsReading;
use crate::constants::{
    DRIVETRAIN_EFFICIENCY, EFFICIENCY_MEASURABLE_SHARE, EFFICIENCY_RELAX_S,
    EFFICIENCY_RISE_PER_STEP, EFFICIENCY_SETTLED_SHARE, MONITOR_MARGIN, PEDAL_DEADBAND,
    POWER_LIMIT_MARGIN,
};

// The limiter aims further below the rule than the monitor bounds, so in normal driving the
// limiter's ceiling binds first and the monitor stays out of the way.
const _: () = assert!(MONITOR_MARGIN < POWER_LIMIT_MARGIN);
use crate::faults::FaultMap;
use crate::power::PowerLimits;

/// What the monitor reads; every bus value is `None` unless fresh.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MonitorInputs {
    /// The vehicle state machine allows torque (DRIVING, precharge complete and fresh).
    pub torque_enabled: bool,
    /// Active faults.
    pub faults: FaultMap,
    /// The pedal: both sensors, range, plausibility, freshness.
    pub apps: AppsReading,
    /// The sensor sample is fresh.
    pub sensors_fresh: bool,
    /// Motor speed (rad/s), from MCU1.
    pub motor_rad_s: Option<f32>,
    /// Pack state of charge (0..1), from the BMS.
    pub soc: Option<f32>,
    /// The torque the inverter says it can deliver now (Nm), from MCU1.
    pub inverter_max_nm: Option<f32>,
    /// DC power out of the accumulator (W): the higher of the inverter's DC link and the
    /// BMS's pack power.
    pub dc_power_w: Option<f32>,
    /// The drivetrain efficiency to bound the power with ([`EfficiencyBound`]).
    pub efficiency: f32,
}

/// The drivetrain efficiency the monitor bounds the power with, from the inverter's and the
/// BMS's own readings (shaft power over DC power), never from what the limiter commanded, so a
/// limiter aiming wrong cannot raise it. It starts at the lowest efficiency the drivetrain can
/// have and never leaves [`DRIVETRAIN_EFFICIENCY`]. A reading below it lowers it at once. A
/// reading above it raises it only while the DC power reading has settled (it moved by less
/// than [`EFFICIENCY_SETTLED_SHARE`] of the limit since the last step), and by at most
/// [`EFFICIENCY_RISE_PER_STEP`]: the DC readings lag the torque (the BMS's and the inverter's
/// own filtering), and while they catch up after the torque rose, shaft over DC reads too high.
/// While the power is too small to measure the efficiency (under
/// [`EFFICIENCY_MEASURABLE_SHARE`] of the limit), it returns to the lowest, so the next full
/// power starts safe at whatever speed.
#[derive(Debug, Clone, PartialEq)]
pub struct EfficiencyBound {
    efficiency: f32,
    /// The DC power reading of the last step (W).
    last_dc_w: f32,
    /// Share of the way back to the lowest efficiency per step while unmeasurable.
    relax: f32,
}

impl EfficiencyBound {
    /// At the lowest efficiency, stepped every `period_ms`.
    pub fn new(period_ms: u32) -> Self {
        Self {
            efficiency: DRIVETRAIN_EFFICIENCY.0,
            last_dc_w: f32::NAN,
            relax: (period_ms as f32 / 1_000.0 / EFFICIENCY_RELAX_S).min(1.0),
        }
    }

    /// The efficiency to bound with now.
    pub fn efficiency(&self) -> f32 {
        self.efficiency
    }

    /// One step with this step's readings: shaft power (the inverter's torque times the motor
    /// speed) and DC power (W).
    pub fn update(
        &mut self,
        shaft_power_w: Option<f32>,
        dc_power_w: Option<f32>,
        limits: &PowerLimits,
    ) -> f32 {
        let (lowest, highest) = DRIVETRAIN_EFFICIENCY;
        let limit = limits.power_limit_w;
        let dc = dc_power_w.unwrap_or(f32::NAN);
        let settled = (dc - self.last_dc_w).abs() <= EFFICIENCY_SETTLED_SHARE * limit;
        self.last_dc_w = dc;
        let measured = match (shaft_power_w, dc_power_w) {
            (Some(shaft), Some(dc))
                if dc >= EFFICIENCY_MEASURABLE_SHARE * limit
                    && shaft.is_finite()
                    && shaft > 0.0 =>
            {
                Some((shaft / dc).clamp(lowest, highest))
            }
            _ => None,
        };
        match measured {
            Some(measured) if measured < self.efficiency => self.efficiency = measured,
            Some(measured) if settled => {
                self.efficiency = measured.min(self.efficiency + EFFICIENCY_RISE_PER_STEP);
            }
            Some(_) => {}
            None => self.efficiency += (lowest - self.efficiency) * self.relax,
        }
        self.efficiency = self.efficiency.clamp(lowest, highest);
        self.efficiency
    }
}

/// The most torque (Nm) the car may have now: 0 whenever a required input is stale or a
/// torque-stopping fault is active, otherwise the least of
/// - the driver's request from the lower of the two pedal sensors (one sensor failing high
///   cannot raise it; nothing within the rest deadband),
/// - the torque that draws the rule's power limit, less [`MONITOR_MARGIN`], from the
///   accumulator at the measured motor speed and the [`EfficiencyBound`]: the rule
///   itself, held without the limiter (which aims [`POWER_LIMIT_MARGIN`] below it, so the
///   two do not meet in normal driving),
/// - the SOC derating, the motor maximum and the inverter's reported maximum, all from the
///   one set of `limits` the limiter uses too.
pub fn allowed_torque(inputs: &MonitorInputs, limits: &PowerLimits) -> f32 {
    let apps = &inputs.apps;
    let pedal_sound = !(apps.signal_lost || apps.sensor_fault() || apps.brake_plausibility);
    if !(inputs.torque_enabled
        && pedal_sound
        && inputs.sensors_fresh
        && !inputs.faults.stops_torque())
    {
        return 0.0;
    }
    let (Some(motor_rad_s), Some(soc), Some(inverter_max), Some(_)) = (
        inputs.motor_rad_s,
        inputs.soc,
        inputs.inverter_max_nm,
        inputs.dc_power_w,
    ) else {
        return 0.0;
    };
    let pedal = (apps.apps1.min(apps.apps2) - PEDAL_DEADBAND) / (1.0 - PEDAL_DEADBAND);
    if !(motor_rad_s.is_finite() && soc.is_finite()) {
        return 0.0;
    }
    let efficiency = inputs
        .efficiency
        .clamp(DRIVETRAIN_EFFICIENCY.0, DRIVETRAIN_EFFICIENCY.1);
    let max_nm = limits.max_torque_nm;
    // At standstill the power bound is far above the motor maximum: 1 rad/s keeps it finite.
    let bounded_w = limits.power_limit_w * (1.0 - MONITOR_MARGIN);
    let power_bound = efficiency * bounded_w / motor_rad_s.abs().max(1.0) / max_nm;
    let bounds = [
        pedal,
        limits.soc_factor(soc),
        power_bound,
        inverter_max / max_nm,
    ];
    // `f32::min` would skip a value that is not a number; such a value allows nothing.
    if bounds.iter().any(|bound| bound.is_nan()) {
        return 0.0;
    }
    let fraction = bounds.iter().fold(1.0f32, |least, bound| least.min(*bound));
    fraction.clamp(0.0, 1.0) * max_nm
}
