//! The CCM's sensors as the firmware reads them: the pedal converter's alternating
//! conversions (the ADS1115 front-end: the slower of the board's two pedal options, whose
//! conversions can stop arriving), the brake pressure sensors, the shock potentiometers and the front
//! wheel-speed gear teeth, with the injected faults applied.

use crate::faults::{Fault, FaultPlan};
use crate::rng::Rng;
use aer_ccm::SensorSample;
use aer_ccm::ads1115::{counts_to_volts, volts_to_counts};
use aer_ccm::calibration::AppsCalibration;
use aer_ccm::chassis::shock_raw_for_volts;
use aer_ccm::constants::{
    APPS1_SUPPLY_V, APPS2_SUPPLY_V, BSE_FULL_SCALE_PSI, BSE_VALID_V, SHOCK_TRAVEL_MAX_MM,
    WHEEL_TEETH,
};

/// ADS1115 conversions per millisecond (860 samples/s, alternating between the channels).
const CONVERSIONS_PER_MS: f32 = 0.86;

/// The sensors and their faults' memory.
#[derive(Debug, Clone)]
pub struct Sensors {
    calibration: AppsCalibration,
    /// Conversions owed to the pedal channels (the converter runs at its own rate).
    conversion_phase: f32,
    next_channel: usize,
    /// Counts a stuck pedal sensor keeps reading.
    stuck: [Option<i16>; 2],
    /// Front wheels' angle in teeth (fractional).
    wheel_teeth: [f32; 2],
    rng: Rng,
}

/// What a pedal sensor's signal is (before the converter).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PedalSignals {
    /// ADS1115 counts of APPS1 and APPS2.
    pub counts: [i16; 2],
}

impl PedalSignals {
    /// The travel (0..1) each sensor says, through `calibration`.
    pub fn travels(&self, calibration: &AppsCalibration) -> [f32; 2] {
        let [a, b] = self.counts;
        let map = |counts: i16, (rest, full): (f32, f32)| {
            ((counts_to_volts(counts) - rest) / (full - rest)).clamp(0.0, 1.0)
        };
        [map(a, calibration.apps1), map(b, calibration.apps2)]
    }

    /// Whether either signal is outside 10-90 % of its supply (a wiring fault).
    pub fn out_of_range(&self) -> bool {
        let [a, b] = self.counts;
        let outside = |counts: i16, supply: f32| {
            !(0.1 * supply..=0.9 * supply).contains(&counts_to_volts(counts))
        };
        outside(a, APPS1_SUPPLY_V) || outside(b, APPS2_SUPPLY_V)
    }
}

impl Sensors {
    /// Sensors on the car's pedal calibration; `seed` drives the signal noise.
    pub fn new(calibration: AppsCalibration, seed: u32) -> Self {
        Self {
            calibration,
            conversion_phase: 0.0,
            next_channel: 0,
            stuck: [None; 2],
            wheel_teeth: [0.0; 2],
            rng: Rng::new(seed ^ 0x5EED),
        }
    }

    /// The pedal calibration.
    pub fn calibration(&self) -> AppsCalibration {
        self.calibration
    }

    /// The pedal sensors' signals for `pedal` travel at `now_ms`, faults applied.
    pub fn pedal_signals(&mut self, pedal: f32, plan: &FaultPlan, now_ms: u32) -> PedalSignals {
        let calibration = self.calibration;
        let ideal = |(rest, full): (f32, f32)| volts_to_counts(rest + pedal * (full - rest));
        let mut counts = [ideal(calibration.apps1), ideal(calibration.apps2)];
        let supplies = [APPS1_SUPPLY_V, APPS2_SUPPLY_V];
        for (sensor, (count, supply)) in counts.iter_mut().zip(supplies).enumerate() {
            if plan.is_active(now_ms, Fault::PedalSensorOpen(sensor)) {
                *count = 0;
            } else if plan.is_active(now_ms, Fault::PedalSensorShorted(sensor)) {
                *count = volts_to_counts(supply);
            }
            let stuck = self.stuck.get_mut(sensor);
            if plan.is_active(now_ms, Fault::PedalSensorStuck(sensor)) {
                if let Some(stuck) = stuck {
                    *count = *stuck.get_or_insert(*count);
                }
            } else if let Some(stuck) = stuck {
                *stuck = None;
            }
        }
        PedalSignals { counts }
    }

    /// The 1 kHz sample at `now_ms`: the pedal converter's new conversions (with a count of
    /// noise), the brake sensor voltages, the shock potentiometers.
    pub fn sample(
        &mut self,
        pedal: &PedalSignals,
        brake_psi: f32,
        accel_m_s2: f32,
        plan: &FaultPlan,
        now_ms: u32,
    ) -> SensorSample {
        let mut apps_v = [None, None];
        self.conversion_phase += CONVERSIONS_PER_MS;
        if self.conversion_phase >= 1.0 {
            self.conversion_phase -= 1.0;
            let channel = self.next_channel;
            self.next_channel = (channel + 1) % 2;
            if !plan.is_active(now_ms, Fault::PedalConverterLost) {
                let noise = self.rng.below(3) as i16 - 1;
                if let (Some(slot), Some(counts)) =
                    (apps_v.get_mut(channel), pedal.counts.get(channel))
                {
                    *slot = Some(counts_to_volts(counts.saturating_add(noise)));
                }
            }
        }
        let volts = |psi: f32| {
            let (low, high) = BSE_VALID_V;
            low + psi.clamp(0.0, BSE_FULL_SCALE_PSI) / BSE_FULL_SCALE_PSI * (high - low)
        };
        let brake_v = if plan.is_active(now_ms, Fault::BrakeSensorNan) {
            (f32::NAN, f32::NAN)
        } else {
            (
                volts(brake_psi),
                volts(brake_psi * crate::params::chassis::REAR_BRAKE_SHARE),
            )
        };
        // Squat under acceleration: rear shocks compress, fronts extend (2 mm per m/s^2).
        // The potentiometers are the nominal ones the calibration's defaults describe.
        let nominal = aer_ccm::calibration::Calibration::DEFAULT;
        let travel = |mm: f32| {
            let mm = mm.clamp(0.0, SHOCK_TRAVEL_MAX_MM);
            let [extended_v, ..] = nominal.shock_extended_v;
            let [compressed_v, ..] = nominal.shock_compressed_v;
            shock_raw_for_volts(extended_v + mm / SHOCK_TRAVEL_MAX_MM * (compressed_v - extended_v))
        };
        let front = 25.0 - 2.0 * accel_m_s2;
        let rear = 25.0 + 2.0 * accel_m_s2;
        SensorSample {
            apps_v,
            brake_v,
            shock_raw: [travel(front), travel(front), travel(rear), travel(rear)],
        }
    }

    /// Advances both front wheels by `dt_ms` at `front_rad_s` and reports each gear tooth
    /// that passes, with its time (us), to `pulse(wheel, at_us)`.
    pub fn wheel_pulses(
        &mut self,
        front_rad_s: f32,
        now_ms: u32,
        dt_ms: u32,
        mut pulse: impl FnMut(usize, u32),
    ) {
        let teeth_per_ms = front_rad_s / core::f32::consts::TAU * WHEEL_TEETH as f32 / 1_000.0;
        let start_us = now_ms.wrapping_sub(dt_ms).wrapping_mul(1_000);
        let delta = teeth_per_ms * dt_ms as f32;
        if delta.is_nan() || delta <= 0.0 {
            return;
        }
        for (wheel, angle) in self.wheel_teeth.iter_mut().enumerate() {
            // `angle` is the fraction of a tooth past the last pulse; each whole tooth crossed
            // in this step is a pulse, timed where it falls in the step.
            let before = *angle;
            let mut next = 1.0;
            while before + delta >= next {
                let fraction = (next - before) / delta;
                let at_us = start_us.wrapping_add((fraction * dt_ms as f32 * 1_000.0) as u32);
                pulse(wheel, at_us);
                next += 1.0;
            }
            *angle = before + delta - (next - 1.0);
        }
    }
}
