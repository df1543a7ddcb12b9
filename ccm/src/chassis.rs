//! Shock travel (linear potentiometers) and wheel speed (gear-tooth pulses).

use crate::constants::{
    MIN_SHOCK_SPAN_V, SHOCK_ADC_FULL, SHOCK_TRAVEL_MAX_MM, WHEEL_STOP_TIMEOUT_US,
};
use core::sync::atomic::{AtomicU8, AtomicU32, Ordering};

/// A shock sensor's voltage for a raw 12-bit ADC reading.
pub fn shock_volts(raw: u16) -> f32 {
    let (full_counts, full_volts) = SHOCK_ADC_FULL;
    f32::from(raw.min(full_counts)) * full_volts / f32::from(full_counts)
}

/// Shock travel in mm for a raw 12-bit ADC reading, from the sensor's calibration: its
/// voltage at full extension (zero travel) and at full compression
/// ([`SHOCK_TRAVEL_MAX_MM`]), measured on the bench (team documentation: 5.00 V and 4.86 V).
/// Linear between the two, either way round, clamped to the travel; a calibration whose ends
/// are not at least [`MIN_SHOCK_SPAN_V`] apart (the calibration check refuses it) reads 0.
pub fn shock_travel_mm(raw: u16, extended_v: f32, compressed_v: f32) -> f32 {
    let span_v = compressed_v - extended_v;
    if !span_v.is_finite() || span_v.abs() < MIN_SHOCK_SPAN_V {
        return 0.0;
    }
    let travel = (shock_volts(raw) - extended_v) / span_v * SHOCK_TRAVEL_MAX_MM;
    if travel.is_finite() {
        travel.clamp(0.0, SHOCK_TRAVEL_MAX_MM)
    } else {
        0.0
    }
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

/// One wheel's pulse times, written by the pin interrupt and read by the control step
/// without a lock: the interrupt is the only writer and each value is one atomic word, so
/// the edge interrupt is never masked (a reader may see a period one pulse newer than the
/// time stamp, both real).
#[derive(Debug, Default)]
pub struct PulseTimer {
    last_pulse_us: AtomicU32,
    period_us: AtomicU32,
    /// 0: no pulse yet; 1: one pulse (no period); 2: a period is known.
    pulses: AtomicU8,
}

/// A copy holds the pulse times as they are now.
impl Clone for PulseTimer {
    fn clone(&self) -> Self {
        let copy = Self::new();
        copy.last_pulse_us.store(
            self.last_pulse_us.load(Ordering::Relaxed),
            Ordering::Relaxed,
        );
        copy.period_us
            .store(self.period_us.load(Ordering::Relaxed), Ordering::Relaxed);
        copy.pulses
            .store(self.pulses.load(Ordering::Acquire), Ordering::Relaxed);
        copy
    }
}

impl PulseTimer {
    pub const fn new() -> Self {
        Self {
            last_pulse_us: AtomicU32::new(0),
            period_us: AtomicU32::new(0),
            pulses: AtomicU8::new(0),
        }
    }

    /// Records a pulse at `now_us` (the pin interrupt; the only writer).
    pub fn on_pulse(&self, now_us: u32) {
        let seen = self.pulses.load(Ordering::Relaxed);
        if seen > 0 {
            let last = self.last_pulse_us.load(Ordering::Relaxed);
            self.period_us
                .store(now_us.wrapping_sub(last), Ordering::Relaxed);
        }
        self.last_pulse_us.store(now_us, Ordering::Relaxed);
        // Published last: a reader that sees the count sees the times it counts.
        self.pulses
            .store(seen.saturating_add(1).min(2), Ordering::Release);
    }

    /// The speed sensor's state as of now, for a gear with `teeth` teeth.
    pub fn speed(&self, teeth: u32) -> WheelSpeed {
        let pulses = self.pulses.load(Ordering::Acquire);
        WheelSpeed {
            teeth,
            last_pulse_us: (pulses > 0).then(|| self.last_pulse_us.load(Ordering::Relaxed)),
            period_us: (pulses > 1).then(|| self.period_us.load(Ordering::Relaxed)),
        }
    }
}
