//! Cooling: pump and fan duty from temperatures.

use crate::calibration::Calibration;

/// PWM duty cycles (0..1).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Cooling {
    /// Coolant pump.
    pub pump: f32,
    /// Radiator fan.
    pub fan: f32,
}

/// Duties for the inverter and motor temperatures (degC), with the `calibration`'s ramps.
/// The pump runs at its base duty whenever the tractive system is live and ramps to full
/// over its ramp (40-60 degC of inverter temperature by default); the fan ramps with the
/// hottest of motor and inverter. A temperature that is not a number runs both at full.
pub fn cooling(
    calibration: &Calibration,
    tractive_live: bool,
    inverter_degc: f32,
    motor_degc: f32,
) -> Cooling {
    if !(inverter_degc.is_finite() && motor_degc.is_finite()) {
        return Cooling {
            pump: 1.0,
            fan: 1.0,
        };
    }
    let base = calibration.pump_base_duty;
    let [pump_from, pump_full] = calibration.pump_ramp_degc;
    let [fan_from, fan_full] = calibration.fan_ramp_degc;
    let pump_ramp = ramp(inverter_degc, pump_from, pump_full);
    Cooling {
        pump: if tractive_live {
            base.max(pump_ramp)
        } else {
            pump_ramp
        },
        fan: ramp(inverter_degc.max(motor_degc), fan_from, fan_full),
    }
}

fn ramp(value: f32, from: f32, full: f32) -> f32 {
    ((value - from) / (full - from)).clamp(0.0, 1.0)
}
