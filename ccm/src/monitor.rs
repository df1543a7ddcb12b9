//! The torque monitor: the last stage of the torque path.
//!
//! The automotive "level 2" idea: a second, deliberately simple computation of the torque
//! the car may have now, from the raw inputs and independent of launch control, traction
//! control and the power limiter's trim. The commanded torque never exceeds it, so a defect
//! in those controllers (or a state they wind up into) cannot make the car faster than the
//! driver, the rules or the inverter allow.

use crate::apps::AppsReading;
use crate::config::{
    DRIVETRAIN_EFFICIENCY, MOTOR_MAX_TORQUE_NM, PEDAL_DEADBAND, POWER_LIMIT_W, SOC_DERATE_END,
    SOC_DERATE_START,
};
use crate::faults::FaultMap;

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
    /// DC power into the inverter (W), from MCU3: the power limiter's trim needs it.
    pub dc_power_w: Option<f32>,
}

/// The most torque (Nm) the car may have now: 0 whenever a required input is stale or a
/// torque-stopping fault is active, otherwise the least of
/// - the driver's request from the lower of the two pedal sensors (one sensor failing high
///   cannot raise it; nothing within the rest deadband),
/// - the power limit at the highest drivetrain efficiency and the measured motor speed (the
///   main limiter aims below it and trims with the measured power),
/// - the SOC derating, the motor maximum and the inverter's reported maximum.
pub fn allowed_torque(inputs: &MonitorInputs) -> f32 {
    let apps = &inputs.apps;
    let pedal_sound = !(apps.signal_lost || apps.sensor_fault() || apps.brake_plausibility);
    if !(inputs.torque_enabled
        && pedal_sound
        && inputs.sensors_fresh
        && !inputs.faults.stops_torque())
    {
        return 0.0;
    }
    let (Some(motor_rad_s), Some(soc), Some(inverter_max), Some(_dc_power)) = (
        inputs.motor_rad_s,
        inputs.soc,
        inputs.inverter_max_nm,
        inputs.dc_power_w,
    ) else {
        return 0.0;
    };
    let pedal = (apps.apps1.min(apps.apps2) - PEDAL_DEADBAND) / (1.0 - PEDAL_DEADBAND);
    let soc_factor = (soc - SOC_DERATE_END) / (SOC_DERATE_START - SOC_DERATE_END);
    if !motor_rad_s.is_finite() {
        return 0.0;
    }
    // At standstill the power bound is far above the motor maximum: 1 rad/s keeps it finite.
    let power_bound =
        DRIVETRAIN_EFFICIENCY.1 * POWER_LIMIT_W / motor_rad_s.abs().max(1.0) / MOTOR_MAX_TORQUE_NM;
    let bounds = [
        pedal,
        soc_factor,
        power_bound,
        inverter_max / MOTOR_MAX_TORQUE_NM,
    ];
    // `f32::min` would skip a value that is not a number; such a value allows nothing.
    if bounds.iter().any(|bound| bound.is_nan()) {
        return 0.0;
    }
    let fraction = bounds.iter().fold(1.0f32, |least, bound| least.min(*bound));
    fraction.clamp(0.0, 1.0) * MOTOR_MAX_TORQUE_NM
}
