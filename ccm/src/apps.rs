//! Accelerator pedal position sensors (APPS): two sensors, read in volts at the sensor
//! whichever front-end the board has (the on-chip ADC, [`crate::analog`], or an ADS1115,
//! [`crate::ads1115`]),
//! filtered, calibrated to 0..1, checked for wiring faults, disagreement and lost conversions,
//! and the APPS/brake plausibility latch.

use crate::calibration::AppsCalibration;
use crate::constants::{
    APPS_BRAKE_RESET, APPS_BRAKE_TRIP, APPS_IMPLAUSIBLE, APPS1_SUPPLY_V, APPS2_SUPPLY_V,
    PEDAL_CONVERSION_TIMEOUT_MS, PEDAL_FILTER_HZ, SENSOR_FAULT_GAP_MS, SENSOR_FAULT_PERSIST_MS,
};
use aer_control::{LowPass, Persist};

/// New readings of APPS1 and APPS2 (volts at the sensor) delivered by one sample; `None`
/// where nothing new arrived (the front-end is slower than the sample rate, or lost).
pub type PedalVolts = [Option<f32>; 2];

/// What the pedal reads this sample.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct AppsReading {
    /// Pedal travel 0..1 as the torque request reads it: the lower of the two sensors, so
    /// one sensor reading high (stuck, drifting, shorted) never asks for torque; 0 while a
    /// channel is lost.
    pub travel: f32,
    /// Sensor 1 travel 0..1.
    pub apps1: f32,
    /// Sensor 2 travel 0..1.
    pub apps2: f32,
    /// A sensor's voltage has been outside 10-90 % of its supply for over 100 ms.
    pub out_of_range: bool,
    /// The sensors have disagreed by over 10 % for over 100 ms.
    pub implausible: bool,
    /// A channel has delivered no new conversion for over
    /// [`PEDAL_CONVERSION_TIMEOUT_MS`]: the converter or its bus is lost.
    pub signal_lost: bool,
    /// Throttle above 25 % on either sensor with the brakes engaged; held until both are
    /// below 5 %.
    pub brake_plausibility: bool,
}

impl AppsReading {
    /// True when a sensor fault (range or disagreement) is active: the APPS fault bit.
    pub fn sensor_fault(&self) -> bool {
        self.out_of_range || self.implausible
    }
}

/// One sensor's converter channel: its filter and when it last delivered a conversion.
#[derive(Debug, Clone)]
struct Channel {
    filter: LowPass,
    /// Time of the last conversion (ms), or of the first update before any arrived.
    converted_ms: Option<u32>,
}

impl Channel {
    fn new(period_s: f32) -> Self {
        Self {
            filter: LowPass::new(PEDAL_FILTER_HZ, period_s),
            converted_ms: None,
        }
    }

    /// Filters a new reading, if any; returns the filtered volts.
    fn update(&mut self, volts: Option<f32>, now_ms: u32) -> f32 {
        match volts {
            Some(volts) => {
                self.converted_ms = Some(now_ms);
                self.filter.update(volts)
            }
            None => {
                self.converted_ms.get_or_insert(now_ms);
                self.filter.value()
            }
        }
    }

    fn lost(&self, now_ms: u32) -> bool {
        self.converted_ms
            .is_none_or(|at| now_ms.wrapping_sub(at) > PEDAL_CONVERSION_TIMEOUT_MS)
    }
}

/// The APPS channel.
#[derive(Debug, Clone)]
pub struct Apps {
    sensors: [Channel; 2],
    range: Persist,
    disagreement: Persist,
    brake_plausibility: bool,
    reading: AppsReading,
}

impl Apps {
    /// A channel sampled every `period_ms`.
    pub fn new(period_ms: u32) -> Self {
        let period_s = period_ms as f32 / 1_000.0;
        Self {
            sensors: [Channel::new(period_s), Channel::new(period_s)],
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

    /// Feeds the readings that arrived this sample (`None`: nothing new on that channel),
    /// mapped to travel with the pedal's `calibration` as it is now.
    pub fn update(
        &mut self,
        calibration: &AppsCalibration,
        readings: PedalVolts,
        brakes_engaged: bool,
        now_ms: u32,
    ) -> AppsReading {
        let [new1, new2] = readings;
        let [sensor1, sensor2] = &mut self.sensors;
        let volts1 = sensor1.update(new1, now_ms);
        let volts2 = sensor2.update(new2, now_ms);
        let signal_lost = sensor1.lost(now_ms) || sensor2.lost(now_ms);
        let apps1 = map(volts1, calibration.apps1);
        let apps2 = map(volts2, calibration.apps2);
        let in_range = |volts: f32, supply: f32| (0.1 * supply..=0.9 * supply).contains(&volts);
        let bad_range = !(in_range(volts1, APPS1_SUPPLY_V) && in_range(volts2, APPS2_SUPPLY_V));
        // A sample or two back inside the limits (noise, the filter gliding through) does not
        // restart the 100 ms: only a clean stretch does.
        let out_of_range = self
            .range
            .update_bridging(bad_range, now_ms, SENSOR_FAULT_GAP_MS)
            .is_some_and(|held| held > SENSOR_FAULT_PERSIST_MS);
        let implausible = self
            .disagreement
            .update_bridging(
                (apps1 - apps2).abs() > APPS_IMPLAUSIBLE,
                now_ms,
                SENSOR_FAULT_GAP_MS,
            )
            .is_some_and(|held| held > SENSOR_FAULT_PERSIST_MS);
        // A lost channel says nothing about the pedal: the request is zero, not the last value.
        let (travel, highest) = if signal_lost {
            (0.0, 0.0)
        } else {
            (apps1.min(apps2), apps1.max(apps2))
        };
        if highest > APPS_BRAKE_TRIP && brakes_engaged {
            self.brake_plausibility = true;
        } else if highest < APPS_BRAKE_RESET {
            self.brake_plausibility = false;
        }
        self.reading = AppsReading {
            travel,
            apps1,
            apps2,
            out_of_range,
            implausible,
            signal_lost,
            brake_plausibility: self.brake_plausibility,
        };
        self.reading
    }
}

/// Linear map of `volts` from (rest, full) to 0..1, clamped.
fn map(volts: f32, (rest, full): (f32, f32)) -> f32 {
    let span = full - rest;
    if span == 0.0 {
        return 0.0;
    }
    ((volts - rest) / span).clamp(0.0, 1.0)
}
