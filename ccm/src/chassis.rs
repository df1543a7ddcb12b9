//! Shock travel (linear potentiometers) and wheel speed (gear-tooth pulses).

use crate::config::{SHOCK_ADC_FULL, SHOCK_SPAN_V, SHOCK_TRAVEL_MAX_MM, WHEEL_STOP_TIMEOUT_US};

/// Shock travel in mm for a raw 12-bit ADC reading (team documentation: the signal rests at
/// 5 V and drops 0.14 V over the full travel, so the drop below full scale is the travel).
pub fn shock_travel_mm(raw: u16) -> f32 {
    let (full_counts, full_volts) = SHOCK_ADC_FULL;
    let drop_counts = full_counts.saturating_sub(raw.min(full_counts));
    let drop_volts = f32::from(drop_counts) * full_volts / f32::from(full_counts);
    (drop_volts / SHOCK_SPAN_V * SHOCK_TRAVEL_MAX_MM).clamp(0.0, SHOCK_TRAVEL_MAX_MM)
}

/// The raw reading for a sensor voltage (for tests and simulations).
pub fn shock_raw_for_volts(volts: f32) -> u16 {
    let (full_counts, full_volts) = SHOCK_ADC_FULL;
    (volts / full_volts * f32::from(full_counts)).clamp(0.0, f32::from(full_counts)) as u16
}

/// One wheel's speed from the time between gear-tooth pulses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WheelSpeed {
    teeth: u32,
    last_pulse_us: Option<u32>,
    period_us: Option<u32>,
}

impl WheelSpeed {
    /// A sensor reading a gear with `teeth` teeth.
    pub const fn new(teeth: u32) -> Self {
        Self {
            teeth,
            last_pulse_us: None,
            period_us: None,
        }
    }

    /// Records a pulse at `now_us` (call from the pin interrupt).
    pub fn on_pulse(&mut self, now_us: u32) {
        if let Some(last) = self.last_pulse_us {
            self.period_us = Some(now_us.wrapping_sub(last));
        }
        self.last_pulse_us = Some(now_us);
    }

    /// Wheel speed in rpm: 60,000,000 / (dt_us x teeth); 0 after 0.5 s without a pulse.
    pub fn rpm(&self, now_us: u32) -> f32 {
        let (Some(last), Some(period)) = (self.last_pulse_us, self.period_us) else {
            return 0.0;
        };
        if now_us.wrapping_sub(last) > WHEEL_STOP_TIMEOUT_US || period == 0 {
            return 0.0;
        }
        60_000_000.0 / (period as f32 * self.teeth as f32)
    }

    /// Wheel speed in rad/s.
    pub fn rad_per_s(&self, now_us: u32) -> f32 {
        self.rpm(now_us) * core::f32::consts::TAU / 60.0
    }
}
