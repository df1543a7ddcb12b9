//! Accelerator pedal position sensors (APPS): two sensors through the ADS1115, filtered,
//! calibrated to 0..1, checked for wiring faults and disagreement, and the APPS/brake
//! plausibility latch.

use crate::config::{
    ADS1115_FULL_SCALE_V, APPS_BRAKE_RESET, APPS_BRAKE_TRIP, APPS_IMPLAUSIBLE, APPS1_SUPPLY_V,
    APPS2_SUPPLY_V, PEDAL_FILTER_HZ, SENSOR_FAULT_PERSIST_MS,
};
use aer_control::{LowPass, Persist};

/// Raw ADS1115 counts at pedal rest and full travel, measured on the installed pedal.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AppsCalibration {
    /// APPS1 (3.3 V sensor) at rest and at full travel.
    pub apps1: (f32, f32),
    /// APPS2 (5 V sensor) at rest and at full travel.
    pub apps2: (f32, f32),
}

impl AppsCalibration {
    /// Placeholder calibration (assumed: 0.5-2.8 V and 0.75-4.2 V); measure the car's pedal.
    pub const DEFAULT: Self = Self {
        apps1: (volts_to_counts(0.5), volts_to_counts(2.8)),
        apps2: (volts_to_counts(0.75), volts_to_counts(4.2)),
    };
}

/// ADS1115 counts for `volts` at the configured full-scale range.
pub const fn volts_to_counts(volts: f32) -> f32 {
    volts * 32_768.0 / ADS1115_FULL_SCALE_V
}

/// Volts for ADS1115 counts.
pub fn counts_to_volts(counts: f32) -> f32 {
    counts * ADS1115_FULL_SCALE_V / 32_768.0
}

/// What the pedal reads this sample.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct AppsReading {
    /// Pedal travel 0..1: the average of both sensors.
    pub travel: f32,
    /// Sensor 1 travel 0..1.
    pub apps1: f32,
    /// Sensor 2 travel 0..1.
    pub apps2: f32,
    /// A sensor's voltage has been outside 10-90 % of its supply for over 100 ms.
    pub out_of_range: bool,
    /// The sensors have disagreed by over 10 % for over 100 ms.
    pub implausible: bool,
    /// Throttle above 25 % with the brake pressed; held until the throttle is below 5 %.
    pub brake_plausibility: bool,
}

impl AppsReading {
    /// True when a sensor fault (range or disagreement) is active: the APPS fault bit.
    pub fn sensor_fault(&self) -> bool {
        self.out_of_range || self.implausible
    }
}

/// The APPS channel.
#[derive(Debug, Clone)]
pub struct Apps {
    calibration: AppsCalibration,
    filter1: LowPass,
    filter2: LowPass,
    range: Persist,
    disagreement: Persist,
    brake_plausibility: bool,
    reading: AppsReading,
}

impl Apps {
    /// A channel sampled every `period_ms`.
    pub fn new(calibration: AppsCalibration, period_ms: u32) -> Self {
        let period_s = period_ms as f32 / 1_000.0;
        Self {
            calibration,
            filter1: LowPass::new(PEDAL_FILTER_HZ, period_s),
            filter2: LowPass::new(PEDAL_FILTER_HZ, period_s),
            range: Persist::default(),
            disagreement: Persist::default(),
            brake_plausibility: false,
            reading: AppsReading::default(),
        }
    }

    /// The last reading.
    pub fn reading(&self) -> AppsReading {
        self.reading
    }

    /// Feeds one pair of raw ADS1115 samples.
    pub fn update(
        &mut self,
        raw1: i16,
        raw2: i16,
        brake_pressed: bool,
        now_ms: u32,
    ) -> AppsReading {
        let counts1 = self.filter1.update(f32::from(raw1));
        let counts2 = self.filter2.update(f32::from(raw2));
        let apps1 = map(counts1, self.calibration.apps1);
        let apps2 = map(counts2, self.calibration.apps2);
        let in_range = |counts: f32, supply: f32| {
            let volts = counts_to_volts(counts);
            (0.1 * supply..=0.9 * supply).contains(&volts)
        };
        let bad_range = !(in_range(counts1, APPS1_SUPPLY_V) && in_range(counts2, APPS2_SUPPLY_V));
        let out_of_range = self
            .range
            .update(bad_range, now_ms)
            .is_some_and(|held| held > SENSOR_FAULT_PERSIST_MS);
        let implausible = self
            .disagreement
            .update((apps1 - apps2).abs() > APPS_IMPLAUSIBLE, now_ms)
            .is_some_and(|held| held > SENSOR_FAULT_PERSIST_MS);
        let travel = (apps1 + apps2) / 2.0;
        if travel > APPS_BRAKE_TRIP && brake_pressed {
            self.brake_plausibility = true;
        } else if travel < APPS_BRAKE_RESET {
            self.brake_plausibility = false;
        }
        self.reading = AppsReading {
            travel,
            apps1,
            apps2,
            out_of_range,
            implausible,
            brake_plausibility: self.brake_plausibility,
        };
        self.reading
    }
}

/// Linear map of `counts` from (rest, full) to 0..1, clamped.
fn map(counts: f32, (rest, full): (f32, f32)) -> f32 {
    let span = full - rest;
    if span == 0.0 {
        return 0.0;
    }
    ((counts - rest) / span).clamp(0.0, 1.0)
}
