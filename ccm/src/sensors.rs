//! What the 1 kHz sensor task writes: pedal, brakes and shock travel, with the sample times
//! the control step judges freshness by. Its own value, so the firmware can give it a lock of
//! its own (ceiling: the sensor task's priority).

use crate::apps::{Apps, AppsReading};
use crate::brakes::{BrakeReading, Brakes};
use crate::calibration::{Calibration, SensorCalibration};
use crate::chassis::shock_travel_mm;
use crate::constants::ADC_PERIOD_MS;
use crate::io::SensorSample;

/// The sensors as last sampled.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorReading {
    pub apps: AppsReading,
    pub brakes: BrakeReading,
    /// Shock travel (mm): FL, FR, RL, RR.
    pub shock_mm: [f32; 4],
    /// When the first sample arrived (ms).
    pub first_ms: Option<u32>,
    /// When the last sample arrived (ms).
    pub sampled_ms: Option<u32>,
}

/// The pedal, brake and shock channels.
#[derive(Debug, Clone)]
pub struct Sensors {
    apps: Apps,
    brakes: Brakes,
    shock_mm: [f32; 4],
    first_ms: Option<u32>,
    sampled_ms: Option<u32>,
}

impl Default for Sensors {
    fn default() -> Self {
        Self::new()
    }
}

impl Sensors {
    /// Nothing sampled yet.
    pub fn new() -> Self {
        Self {
            apps: Apps::new(ADC_PERIOD_MS),
            brakes: Brakes::new(ADC_PERIOD_MS),
            shock_mm: [0.0; 4],
            first_ms: None,
            sampled_ms: None,
        }
    }

    /// The 1 kHz sensor step, with the `calibration` as it is now.
    pub fn sample(&mut self, calibration: &Calibration, sample: &SensorSample, now_ms: u32) {
        self.first_ms.get_or_insert(now_ms);
        self.sampled_ms = Some(now_ms);
        let sensors = SensorCalibration::of(calibration);
        let brakes =
            self.brakes
                .update(&sensors.brakes, sample.brake_v.0, sample.brake_v.1, now_ms);
        self.apps
            .update(&sensors.pedals, sample.apps_v, brakes.engaged, now_ms);
        for (((travel, raw), extended_v), compressed_v) in self
            .shock_mm
            .iter_mut()
            .zip(sample.shock_raw)
            .zip(calibration.shock_extended_v)
            .zip(calibration.shock_compressed_v)
        {
            *travel = shock_travel_mm(raw, extended_v, compressed_v);
        }
    }

    pub fn reading(&self) -> SensorReading {
        SensorReading {
            apps: self.apps.reading(),
            brakes: self.brakes.reading(),
            shock_mm: self.shock_mm,
            first_ms: self.first_ms,
            sampled_ms: self.sampled_ms,
        }
    }
}
