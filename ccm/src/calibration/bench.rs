//! The bring-up image's sensor calibration: `cal rest` and `cal full` record the pedal and
//! brake sensors, `cal shock <corner> extended|compressed` the shock sensors, each point
//! averaged over a second of the bench loop's samples. What is complete and checked is what
//! `cal save` saves and what the lines for `ccm/calibration.toml` say.

use super::Calibration;
use super::sensors::{
    AppsCalibration, BrakeCalibration, CalibrationError, SHOCK_CORNERS, SensorCalibration,
    ShockCalibration,
};
use core::fmt;

/// Samples averaged for one calibration point (1 s of the CCM bring-up loop, 1 kHz).
pub const CALIBRATION_SAMPLES: u32 = 1_000;

/// An end of a shock sensor's travel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ShockEnd {
    /// Fully extended: zero travel.
    Extended,
    /// Fully compressed: full travel.
    Compressed,
}

/// Which point the bench is recording.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BenchPoint {
    /// Pedal and brakes released: both pedal sensors' rest and both brake sensors' zero.
    Rest,
    /// Pedal fully pressed: both pedal sensors' full travel.
    Full,
    /// The shock sensors marked in `sensors` (input order) at one end of their travel.
    Shock {
        /// Which sensors.
        sensors: [bool; 4],
        /// Which end.
        end: ShockEnd,
    },
}

/// One sample of every sensor the bench calibrates (V at the sensors).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BenchSample {
    /// APPS1, APPS2 (`None`: no conversion this time).
    pub pedals: [Option<f32>; 2],
    /// BSE1 (front), BSE2 (rear).
    pub brakes: [f32; 2],
    /// The shock sensors, in input order.
    pub shocks: [f32; 4],
}

/// The recorder (see the module's description).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BenchRecorder {
    /// APPS1, APPS2, BSE1 (front), BSE2 (rear) at rest.
    rest: Option<[f32; 4]>,
    /// APPS1, APPS2 fully pressed.
    full: Option<[f32; 2]>,
    /// Each shock sensor extended.
    extended: [Option<f32>; 4],
    /// Each shock sensor compressed.
    compressed: [Option<f32>; 4],
    recording: Option<Recording>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Recording {
    point: BenchPoint,
    sums: [f32; 4],
    samples: u32,
}

/// What the pedal and brake recording has so far.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PedalResult {
    /// Neither point yet.
    Nothing,
    /// The rest point only.
    RestOnly([f32; 4]),
    /// The full point only.
    FullOnly([f32; 2]),
    /// Both: the calibration and its check.
    Complete(
        AppsCalibration,
        BrakeCalibration,
        Result<(), CalibrationError>,
    ),
}

/// What the shock recording has so far: each sensor's ends, and once all eight are in, the
/// calibration and its check.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShockResult {
    /// Each sensor extended (V).
    pub extended: [Option<f32>; 4],
    /// Each sensor compressed (V).
    pub compressed: [Option<f32>; 4],
}

impl ShockResult {
    /// The calibration and its check, once every end of every sensor is recorded.
    pub fn complete(&self) -> Option<(ShockCalibration, Result<(), CalibrationError>)> {
        let [Some(e1), Some(e2), Some(e3), Some(e4)] = self.extended else {
            return None;
        };
        let [Some(c1), Some(c2), Some(c3), Some(c4)] = self.compressed else {
            return None;
        };
        let calibration = ShockCalibration {
            extended_v: [e1, e2, e3, e4],
            compressed_v: [c1, c2, c3, c4],
        };
        Some((calibration, calibration.check()))
    }

    /// True when nothing is recorded.
    pub fn is_empty(&self) -> bool {
        self.extended
            .iter()
            .chain(&self.compressed)
            .all(Option::is_none)
    }
}

/// Why `cal save` saves nothing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum NothingToSave {
    /// Nothing complete this session.
    NothingMeasured,
    /// A complete measurement failed its check.
    Refused(CalibrationError),
}

impl fmt::Display for NothingToSave {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::NothingMeasured => f.write_str(
                "not saved: nothing measured this session (`cal rest` and `cal full`, or `cal shock` for every sensor's two ends, first)",
            ),
            Self::Refused(error) => write!(
                f,
                "not saved: the measurement was REFUSED ({error}); measure again"
            ),
        }
    }
}

/// The checked measurements of this session, ready to go over a calibration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measured {
    /// The pedal and brake sensors, if both points are in.
    pub pedals: Option<(AppsCalibration, BrakeCalibration)>,
    /// The shock sensors, if every end is in.
    pub shocks: Option<ShockCalibration>,
}

impl Measured {
    /// `base` with what was measured; every other value as it was.
    pub fn applied_to(&self, base: Calibration) -> Calibration {
        let mut sensors = SensorCalibration::of(&base);
        if let Some((pedals, brakes)) = self.pedals {
            sensors.pedals = pedals;
            sensors.brakes = brakes;
        }
        if let Some(shocks) = self.shocks {
            sensors.shocks = shocks;
        }
        sensors.applied_to(base)
    }

    /// What was measured, in words: `pedals and brakes`, `shocks`, or both.
    pub fn what(&self) -> &'static str {
        match (self.pedals.is_some(), self.shocks.is_some()) {
            (true, true) => "pedal, brake and shock sensors",
            (true, false) => "pedal and brake sensors",
            (false, true) => "shock sensors",
            (false, false) => "nothing",
        }
    }
}

impl BenchRecorder {
    /// Starts recording `point` (again, if it was recorded before).
    pub fn start(&mut self, point: BenchPoint) {
        self.recording = Some(Recording {
            point,
            sums: [0.0; 4],
            samples: 0,
        });
    }

    /// True while a point is being recorded.
    pub fn recording(&self) -> bool {
        self.recording.is_some()
    }

    /// Feeds one sample (a missing or non-finite reading of what is recorded skips it).
    /// Returns the point that just completed.
    pub fn sample(&mut self, sample: &BenchSample) -> Option<BenchPoint> {
        let recording = self.recording.as_mut()?;
        let values = match recording.point {
            BenchPoint::Rest | BenchPoint::Full => {
                let [Some(apps1), Some(apps2)] = sample.pedals else {
                    return None;
                };
                let [front, rear] = sample.brakes;
                [apps1, apps2, front, rear]
            }
            BenchPoint::Shock { .. } => sample.shocks,
        };
        if !values.iter().all(|value| value.is_finite()) {
            return None;
        }
        for (sum, value) in recording.sums.iter_mut().zip(values) {
            *sum += value;
        }
        recording.samples += 1;
        if recording.samples < CALIBRATION_SAMPLES {
            return None;
        }
        let n = recording.samples as f32;
        let mean = recording.sums.map(|sum| sum / n);
        let point = recording.point;
        match point {
            BenchPoint::Rest => self.rest = Some(mean),
            BenchPoint::Full => self.full = Some([mean[0], mean[1]]),
            BenchPoint::Shock { sensors, end } => {
                let ends = match end {
                    ShockEnd::Extended => &mut self.extended,
                    ShockEnd::Compressed => &mut self.compressed,
                };
                for ((slot, volts), recorded) in ends.iter_mut().zip(mean).zip(sensors) {
                    if recorded {
                        *slot = Some(volts);
                    }
                }
            }
        }
        self.recording = None;
        Some(point)
    }

    /// What the pedal and brake recording has.
    pub fn pedals(&self) -> PedalResult {
        match (self.rest, self.full) {
            (None, None) => PedalResult::Nothing,
            (Some(rest), None) => PedalResult::RestOnly(rest),
            (None, Some(full)) => PedalResult::FullOnly(full),
            (Some([rest1, rest2, front, rear]), Some([full1, full2])) => {
                let pedals = AppsCalibration {
                    apps1: (rest1, full1),
                    apps2: (rest2, full2),
                };
                let brakes = BrakeCalibration {
                    front_zero_v: front,
                    rear_zero_v: rear,
                };
                let check = SensorCalibration {
                    pedals,
                    brakes,
                    shocks: ShockCalibration::DEFAULT,
                }
                .check_pedals();
                PedalResult::Complete(pedals, brakes, check)
            }
        }
    }

    /// What the shock recording has.
    pub fn shocks(&self) -> ShockResult {
        ShockResult {
            extended: self.extended,
            compressed: self.compressed,
        }
    }

    /// What `cal save` saves: every complete group, each having passed its check; refused
    /// if a complete group failed it, or nothing is complete.
    pub fn measured(&self) -> Result<Measured, NothingToSave> {
        let pedals = match self.pedals() {
            PedalResult::Complete(pedals, brakes, Ok(())) => Some((pedals, brakes)),
            PedalResult::Complete(_, _, Err(error)) => return Err(NothingToSave::Refused(error)),
            _ => None,
        };
        let shocks = match self.shocks().complete() {
            Some((shocks, Ok(()))) => Some(shocks),
            Some((_, Err(error))) => return Err(NothingToSave::Refused(error)),
            None => None,
        };
        if pedals.is_none() && shocks.is_none() {
            return Err(NothingToSave::NothingMeasured);
        }
        Ok(Measured { pedals, shocks })
    }
}

impl fmt::Display for PedalResult {
    /// The first line of the result; a complete one is followed by its
    /// [`SensorCalibration::pedal_toml_lines`].
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Nothing => f.write_str("calibration: `cal rest` (pedal and brakes released), then `cal full` (pedal fully pressed)"),
            Self::RestOnly([apps1, apps2, front, rear]) => write!(
                f,
                "calibration: at rest APPS1 {apps1:.3} V, APPS2 {apps2:.3} V, brakes front {front:.3} V, rear {rear:.3} V; now `cal full` with the pedal pressed"
            ),
            Self::FullOnly([apps1, apps2]) => write!(
                f,
                "calibration: at full travel APPS1 {apps1:.3} V, APPS2 {apps2:.3} V; now `cal rest` with the pedal and brakes released"
            ),
            Self::Complete(_, _, Ok(())) => f.write_str(
                "calibration: check passed; `cal save` puts it in the saved copy the race image loads; also replace the [pedals] and [brakes] sections of ccm/calibration.toml with these lines",
            ),
            Self::Complete(_, _, Err(error)) => write!(
                f,
                "calibration: REFUSED, {error}; check the sensor and repeat (`cal save` and the firmware's build refuse these values too)"
            ),
        }
    }
}

/// One sensor end, or `-` when not recorded yet.
struct End(Option<f32>);

impl fmt::Display for End {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.0 {
            Some(volts) => write!(f, "{volts:.3} V"),
            None => f.write_str("-"),
        }
    }
}

impl fmt::Display for ShockResult {
    /// The first line of the result; a complete, checked one is followed by its
    /// [`ShockCalibration::toml_lines`].
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.complete() {
            Some((_, Ok(()))) => {
                return f.write_str(
                    "shocks: check passed; `cal save` puts them in the saved copy the race image loads; also replace the [shocks] section of ccm/calibration.toml with these lines",
                );
            }
            Some((_, Err(error))) => {
                return write!(
                    f,
                    "shocks: REFUSED, {error}; check the sensor and repeat that end (`cal save` and the firmware's build refuse these values too)"
                );
            }
            None => {}
        }
        f.write_str("shocks:")?;
        for (index, corner) in SHOCK_CORNERS.iter().enumerate() {
            let extended = self.extended.get(index).copied().flatten();
            let compressed = self.compressed.get(index).copied().flatten();
            write!(
                f,
                " {corner} {} / {}{}",
                End(extended),
                End(compressed),
                if index + 1 < SHOCK_CORNERS.len() {
                    ","
                } else {
                    ""
                }
            )?;
        }
        f.write_str(" (extended / compressed); each still `-` needs its `cal shock`")
    }
}
