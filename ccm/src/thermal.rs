//! Cooling: pump and fan duty from temperatures.

use crate::constants::{FAN_RAMP_DEGC, PUMP_DUTY};

/// PWM duty cycles (0..1).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Cooling {
    /// Coolant pump.
    pub pump: f32,
    /// Radiator fan.
    pub fan: f32,
}

/// Duties for the inverter and motor temperatures (degC). The pump runs at its base duty
/// whenever the tractive system is live and ramps to full between 40 and 60 degC of
/// inverter temperature; the fan ramps with the hottest of motor and inverter. A temperature
/// that is not a number runs both at full.
pub fn cooling(tractive_live: bool, inverter_degc: f32, motor_degc: f32) -> Cooling {
    if !(inverter_degc.is_finite() && motor_degc.is_finite()) {
        return Cooling {
            pump: 1.0,
            fan: 1.0,
        };
    }
    let (base, pump_from, pump_full) = PUMP_DUTY;
    let pump_ramp = ramp(inverter_degc, pump_from, pump_full);
    Cooling {
        pump: if tractive_live {
            base.max(pump_ramp)
        } else {
            pump_ramp
        },
        fan: ramp(
            inverter_degc.max(motor_degc),
            FAN_RAMP_DEGC.0,
            FAN_RAMP_DEGC.1,
        ),
    }
}

fn ramp(value: f32, from: f32, full: f32) -> f32 {
    ((value - from) / (full - from)).clamp(0.0, 1.0)
}
