//! What the 1 kHz sensor task writes: pedal, brakes and shock travel, with the sample times
//! the control step judges freshness by. Its own value, so the firmware can give it a lock of
//! its own (ceiling: the sensor task's priority).

use crate::apps::{Apps, AppsReading};
use crate::brakes::{BrakeReading, Brakes};
use crate::calibration::SensorCalibration;
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

impl Sensors {
    /// Nothing sampled yet, with the sensors' `calibration`.
    pub fn new(calibration: SensorCalibration) -> Self {
        Self {
            apps: Apps::new(calibration.pedals, ADC_PERIOD_MS),
            brakes: Brakes::new(ADC_PERIOD_MS, calibration.brakes),
            shock_mm: [0.0; 4],
            first_ms: None,
            sampled_ms: None,
        }
    }

    /// The 1 kHz sensor step.
    pub fn sample(&mut self, sample: &SensorSample, now_ms: u32) {
        self.first_ms.get_or_insert(now_ms);
        self.sampled_ms = Some(now_ms);
        let brakes = self
            .brakes
            .update(sample.brake_v.0, sample.brake_v.1, now_ms);
        self.apps.update(sample.apps_v, brakes.engaged, now_ms);
        self.shock_mm = sample.shock_raw.map(shock_travel_mm);
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
