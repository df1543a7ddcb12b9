//! Brake system encoders (BSE): front and rear pressure sensors, their range check, the
//! front/rear circuit plausibility check, and whether the brakes are engaged, which is what
//! the brake light shows and what the APPS/brake plausibility check and launch control use.

use crate::calibration::BrakeCalibration;
use crate::constants::{
    BRAKE_CIRCUITS_IMPLAUSIBLE, BRAKES_ENGAGED_PSI, BSE_FULL_SCALE_PSI, BSE_SPAN_V, BSE_VALID_V,
    PEDAL_FILTER_HZ, SENSOR_FAULT_PERSIST_MS,
};
use aer_control::{LowPass, Persist};

/// What the brakes read this sample.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BrakeReading {
    /// Front sensor voltage (filtered).
    pub front_v: f32,
    /// Rear sensor voltage (filtered).
    pub rear_v: f32,
    /// Front circuit pressure (psi).
    pub front_psi: f32,
    /// Rear circuit pressure (psi).
    pub rear_psi: f32,
    /// The brakes are engaged: the highest circuit rose above the engaged pressure and has
    /// not fallen below the released pressure since. Drives the brake light.
    pub engaged: bool,
    /// A sensor has been outside 0.5-4.5 V for over 100 ms (the BSE fault bit).
    pub sensor_fault: bool,
    /// One circuit is pressurised while the other is not (the BPPS fault bit).
    pub circuits_implausible: bool,
}

/// The brake channel.
#[derive(Debug, Clone)]
pub struct Brakes {
    front: LowPass,
    rear: LowPass,
    range: Persist,
    circuits: Persist,
    engaged: bool,
    reading: BrakeReading,
}

impl Brakes {
    /// A channel sampled every `period_ms`.
    pub fn new(period_ms: u32) -> Self {
        let period_s = period_ms as f32 / 1_000.0;
        Self {
            front: LowPass::new(PEDAL_FILTER_HZ, period_s),
            rear: LowPass::new(PEDAL_FILTER_HZ, period_s),
            range: Persist::default(),
            circuits: Persist::default(),
            engaged: false,
            reading: BrakeReading::default(),
        }
    }

    /// The last reading.
    pub fn reading(&self) -> BrakeReading {
        self.reading
    }

    /// Feeds one pair of sensor voltages (after the board's divider). A voltage that is not
    /// a number reads as 0 V: out of range, so it becomes a sensor fault. The pressures are
    /// measured from the `calibration`'s zero as it is now.
    pub fn update(
        &mut self,
        calibration: &BrakeCalibration,
        front_v: f32,
        rear_v: f32,
        now_ms: u32,
    ) -> BrakeReading {
        let number = |volts: f32| if volts.is_finite() { volts } else { 0.0 };
        let front_v = self.front.update(number(front_v));
        let rear_v = self.rear.update(number(rear_v));
        let valid = |v: f32| (BSE_VALID_V.0..=BSE_VALID_V.1).contains(&v);
        let sensor_fault = self
            .range
            .update(!(valid(front_v) && valid(rear_v)), now_ms)
            .is_some_and(|held| held > SENSOR_FAULT_PERSIST_MS);
        let front_psi = pressure(front_v, calibration.front_zero_v);
        let rear_psi = pressure(rear_v, calibration.rear_zero_v);
        let (high, low, persist_ms) = BRAKE_CIRCUITS_IMPLAUSIBLE;
        let one_sided =
            (front_psi > high && rear_psi < low) || (rear_psi > high && front_psi < low);
        let circuits_implausible = self
            .circuits
            .update(one_sided, now_ms)
            .is_some_and(|held| held > persist_ms);
        // The highest circuit counts, so one failed sensor cannot hide braking.
        let highest = front_psi.max(rear_psi);
        let (engage, release) = BRAKES_ENGAGED_PSI;
        if highest > engage {
            self.engaged = true;
        } else if highest < release {
            self.engaged = false;
        }
        self.reading = BrakeReading {
            front_v,
            rear_v,
            front_psi,
            rear_psi,
            engaged: self.engaged,
            sensor_fault,
            circuits_implausible,
        };
        self.reading
    }
}

/// Pressure for a sensor voltage: `zero_v` = 0 psi, `zero_v` + [`BSE_SPAN_V`] = full scale,
/// clamped.
pub fn pressure(volts: f32, zero_v: f32) -> f32 {
    ((volts - zero_v) / BSE_SPAN_V * BSE_FULL_SCALE_PSI).clamp(0.0, BSE_FULL_SCALE_PSI)
}

/// The voltage of a nominal sensor (zero at 0.5 V) for a pressure (for tests and
/// simulations).
pub fn volts_for(psi: f32) -> f32 {
    BSE_VALID_V.0 + psi / BSE_FULL_SCALE_PSI * BSE_SPAN_V
}
