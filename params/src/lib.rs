//! The car's parameters: one definition of each number that more than one tier needs (the
//! CCM's limits, the dashboard's speed and power readouts, the closed-loop car model).
//!
//! `no_std`, no dependencies, plain constants. Values marked "assumed" are this project's
//! choices and must be checked on the car before they are trusted.
#![no_std]

// --- Tractive system ---------------------------------------------------------------------

/// Below this the tractive system counts as discharged (V DC): the rules' low-voltage limit,
/// which the PCC's hand-over and discharge check and the CCM's guards use alike.
pub const TRACTIVE_LOW_VOLTAGE_V: f32 = 60.0;
/// The precharge target (% of the accumulator voltage) at which the PCC closes AIR+: the
/// team's design. A PCC that reports ONLINE or CHARGING below it reports what it cannot be.
pub const PRECHARGE_TARGET_PERCENT: f32 = 90.0;

// --- Powertrain --------------------------------------------------------------------------

/// Motor torque the car is built for (Nm); also the inverter's 100 % torque reference.
pub const MOTOR_MAX_TORQUE_NM: f32 = 260.0;
/// Tractive power drawn from the accumulator may not exceed this (W, EV.3.3.1).
pub const POWER_LIMIT_W: f32 = 80_000.0;
/// Lowest and highest efficiency from accumulator DC to motor shaft over the operating
/// range (inverter and motor together, assumed): the power limiter must hold the limit for
/// any efficiency in this range.
pub const DRIVETRAIN_EFFICIENCY: (f32, f32) = (0.85, 0.97);
/// Motor pole pairs: the DTI reports electrical rpm, motor rpm x pole pairs (assumed: an
/// EMRAX 228, 20 poles; the team's code does not name the comp car's motor).
pub const MOTOR_POLE_PAIRS: f32 = 10.0;
/// Motor torque per ampere of peak AC (phase) current, the unit the DTI commands and reports
/// (Nm/A, assumed: an EMRAX 228 HV's 1.06 Nm per A rms over sqrt 2). The CCM commands the DTI
/// in amperes through it, so a wrong value scales the torque; measure it on the dyno.
pub const MOTOR_TORQUE_PER_PEAK_A: f32 = 0.75;
/// Motor revolutions per wheel revolution (assumed).
pub const GEAR_RATIO: f32 = 3.5;

// --- Accumulator -------------------------------------------------------------------------

/// SOC (0..1) below which torque is derated linearly...
pub const SOC_DERATE_START: f32 = 0.20;
/// ...down to zero at this SOC.
pub const SOC_DERATE_END: f32 = 0.05;

// --- Chassis -----------------------------------------------------------------------------

/// Wheel radius (m), as in the team's launch-control test plan.
pub const WHEEL_RADIUS_M: f32 = 0.35;
/// Mass of the car with its driver (kg, assumed).
pub const VEHICLE_MASS_KG: f32 = 300.0;

/// Road speed (m/s) for a motor speed (rpm).
pub fn road_speed_m_s(motor_rpm: f32) -> f32 {
    motor_rpm / GEAR_RATIO * core::f32::consts::TAU / 60.0 * WHEEL_RADIUS_M
}

/// Motor speed (rad/s) for a motor speed in rpm.
pub fn motor_rad_s(motor_rpm: f32) -> f32 {
    motor_rpm * core::f32::consts::TAU / 60.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn speeds_follow_the_gear_ratio_and_wheel_radius() {
        // 3,500 rpm at the motor is 1,000 rpm at the wheel: 2 pi x 0.35 m x 1,000 / 60 s.
        let expected = core::f32::consts::TAU * 0.35 * 1_000.0 / 60.0;
        assert!((road_speed_m_s(3_500.0) - expected).abs() < 1e-4);
        assert!((motor_rad_s(60.0) - core::f32::consts::TAU).abs() < 1e-6);
    }
}
