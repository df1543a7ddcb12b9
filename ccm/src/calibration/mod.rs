//! The car's calibration: every tuned number, declared in `schema/calibration.yaml` and
//! generated as [`Calibration`] (its defaults, limits and change conditions), and the part of
//! it the bench measures, the sensors ([`SensorCalibration`]): the pedal sensors at rest and at
//! full travel and each brake pressure sensor with the brakes released. The bench measures
//! them with the bring-up image ([`BenchRecorder`]); `ccm/calibration.toml` keeps them, the
//! firmware images' build reads them and [`SensorCalibration::check`] checks them, on the bench
//! and at build time. The tests and the car model keep [`Calibration::DEFAULT`]: a measured
//! pedal changes the car, not the proofs.

pub mod state;
pub mod store;

pub use aer::calibration::Calibration;

/// The ECU program identifier (the schema's layouts, `aer::calibration::xcp::EPK`): what the
/// saved copies carry and XCP masters compare with their A2L.
pub const EPK: &[u8] = aer::calibration::xcp::EPK.as_bytes();

const _: () = assert!(
    EPK.len() <= store::EPK_FIELD_LEN,
    "the EPK must fit the saved record"
);

use crate::constants::{APPS1_SUPPLY_V, APPS2_SUPPLY_V, BSE_ZERO_V, MIN_PEDAL_TRAVEL_V};
use core::fmt;

/// Sensor voltages at pedal rest and full travel, measured on the installed pedal (the
/// bring-up image's pedal calibration step prints them).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AppsCalibration {
    /// APPS1 (3.3 V sensor) at rest and at full travel (V).
    pub apps1: (f32, f32),
    /// APPS2 (5 V sensor) at rest and at full travel (V).
    pub apps2: (f32, f32),
}

impl AppsCalibration {
    /// The schema's placeholder calibration (assumed: 0.5-2.8 V and 0.75-4.2 V), what the
    /// tests and the car model use; the car's measured values reach the firmware images
    /// through `ccm/calibration.toml`.
    pub const DEFAULT: Self = SensorCalibration::of(&Calibration::DEFAULT).pedals;
}

/// Each brake pressure sensor's reading with the brakes released (V at the sensor): the
/// pressure the CCM computes is measured from it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BrakeCalibration {
    /// BSE1, the front circuit.
    pub front_zero_v: f32,
    /// BSE2, the rear circuit.
    pub rear_zero_v: f32,
}

impl BrakeCalibration {
    /// The schema's default: the sensors' nominal 0.5 V at 0 psi.
    pub const DEFAULT: Self = SensorCalibration::of(&Calibration::DEFAULT).brakes;
}

/// Everything the bench measures about the sensors.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorCalibration {
    /// The accelerator pedal's two sensors.
    pub pedals: AppsCalibration,
    /// The brake pressure sensors' zero.
    pub brakes: BrakeCalibration,
}

/// A calibration the CCM must not run with, and why.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CalibrationError {
    /// A pedal sensor's rest or full-travel voltage lies outside the band the CCM's range
    /// check accepts (10-90 % of its supply): that pedal position would be a sensor fault.
    PedalOutOfBand {
        /// `APPS1` or `APPS2`.
        sensor: &'static str,
        /// `at rest` or `at full travel`.
        point: &'static str,
        /// What was given (V).
        volts: f32,
        /// The band (V).
        band: (f32, f32),
    },
    /// A pedal sensor moves less than [`MIN_PEDAL_TRAVEL_V`] over the pedal's travel: noise
    /// would be a large share of the torque request.
    TooLittleTravel {
        /// `APPS1` or `APPS2`.
        sensor: &'static str,
        /// Full minus rest (V).
        travel_v: f32,
    },
    /// A brake sensor's released reading lies outside [`BSE_ZERO_V`].
    BrakeZeroOutOfBand {
        /// `front (BSE1)` or `rear (BSE2)`.
        circuit: &'static str,
        /// What was given (V).
        volts: f32,
    },
}

impl fmt::Display for CalibrationError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::PedalOutOfBand {
                sensor,
                point,
                volts,
                band: (low, high),
            } => write!(
                f,
                "{sensor} {point} reads {volts:.3} V, outside its valid band {low:.3}-{high:.3} V (a sensor fault there)"
            ),
            Self::TooLittleTravel { sensor, travel_v } => write!(
                f,
                "{sensor} moves {travel_v:.3} V over the pedal's travel, less than {MIN_PEDAL_TRAVEL_V:.1} V"
            ),
            Self::BrakeZeroOutOfBand { circuit, volts } => write!(
                f,
                "the {circuit} brake sensor reads {volts:.3} V released, outside {:.2}-{:.2} V (below is a BSE fault at rest, above is pressure or a wrong sensor)",
                BSE_ZERO_V.0, BSE_ZERO_V.1
            ),
        }
    }
}

impl CalibrationError {
    /// One line for a compile-time refusal (a `const` panic cannot format the values; the
    /// `calibration` test prints them).
    pub const fn summary(&self) -> &'static str {
        match self {
            Self::PedalOutOfBand { .. } => {
                "ccm/calibration.toml: a pedal sensor point lies outside its valid band (`cargo test -p aer-ccm --test calibration` says which)"
            }
            Self::TooLittleTravel { .. } => {
                "ccm/calibration.toml: a pedal sensor moves too little over the travel (`cargo test -p aer-ccm --test calibration` says which)"
            }
            Self::BrakeZeroOutOfBand { .. } => {
                "ccm/calibration.toml: a brake sensor zero lies outside its band (`cargo test -p aer-ccm --test calibration` says which)"
            }
        }
    }
}

impl SensorCalibration {
    /// The schema's defaults (placeholders until measured): what the tests and the car
    /// model use.
    pub const DEFAULT: Self = Self::of(&Calibration::DEFAULT);

    /// The sensors' part of `calibration`.
    pub const fn of(calibration: &Calibration) -> Self {
        let [apps1_rest, apps1_full] = calibration.apps1_v;
        let [apps2_rest, apps2_full] = calibration.apps2_v;
        let [front_zero_v, rear_zero_v] = calibration.brake_zero_v;
        Self {
            pedals: AppsCalibration {
                apps1: (apps1_rest, apps1_full),
                apps2: (apps2_rest, apps2_full),
            },
            brakes: BrakeCalibration {
                front_zero_v,
                rear_zero_v,
            },
        }
    }

    /// `calibration` with these sensors: what a firmware image starts with.
    pub const fn applied_to(self, calibration: Calibration) -> Calibration {
        Calibration {
            apps1_v: [self.pedals.apps1.0, self.pedals.apps1.1],
            apps2_v: [self.pedals.apps2.0, self.pedals.apps2.1],
            brake_zero_v: [self.brakes.front_zero_v, self.brakes.rear_zero_v],
            ..calibration
        }
    }

    /// Whether the CCM can run with this calibration: every pedal point inside its sensor's
    /// valid band, enough travel on each sensor, each brake zero inside [`BSE_ZERO_V`]. A
    /// `const fn`, so the firmware images' build refuses a bad file.
    pub const fn check(&self) -> Result<(), CalibrationError> {
        let pedals = [
            ("APPS1", self.pedals.apps1, APPS1_SUPPLY_V),
            ("APPS2", self.pedals.apps2, APPS2_SUPPLY_V),
        ];
        let mut index = 0;
        while index < pedals.len() {
            let (sensor, (rest, full), supply) = pedals[index];
            let band = (0.1 * supply, 0.9 * supply);
            let points = [("at rest", rest), ("at full travel", full)];
            let mut point = 0;
            while point < points.len() {
                let (name, volts) = points[point];
                if !(volts >= band.0 && volts <= band.1) {
                    return Err(CalibrationError::PedalOutOfBand {
                        sensor,
                        point: name,
                        volts,
                        band,
                    });
                }
                point += 1;
            }
            let travel_v = (full - rest).abs();
            if travel_v < MIN_PEDAL_TRAVEL_V {
                return Err(CalibrationError::TooLittleTravel { sensor, travel_v });
            }
            index += 1;
        }
        let zeros = [
            ("front (BSE1)", self.brakes.front_zero_v),
            ("rear (BSE2)", self.brakes.rear_zero_v),
        ];
        let mut index = 0;
        while index < zeros.len() {
            let (circuit, volts) = zeros[index];
            if !(volts >= BSE_ZERO_V.0 && volts <= BSE_ZERO_V.1) {
                return Err(CalibrationError::BrakeZeroOutOfBand { circuit, volts });
            }
            index += 1;
        }
        Ok(())
    }

    /// The calibration as the lines of `ccm/calibration.toml` (without `source`).
    pub fn toml_lines(&self) -> [TomlLine; 6] {
        [
            TomlLine::Section("pedals"),
            TomlLine::Pedal("apps1", self.pedals.apps1),
            TomlLine::Pedal("apps2", self.pedals.apps2),
            TomlLine::Section("brakes"),
            TomlLine::Volts("front_zero_v", self.brakes.front_zero_v),
            TomlLine::Volts("rear_zero_v", self.brakes.rear_zero_v),
        ]
    }
}

/// One line of `ccm/calibration.toml`, as the bring-up image prints it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TomlLine {
    /// `[name]`.
    Section(&'static str),
    /// `name = { rest_v = .., full_v = .. }`.
    Pedal(&'static str, (f32, f32)),
    /// `name = ..`.
    Volts(&'static str, f32),
}

impl fmt::Display for TomlLine {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::Section(name) => write!(f, "[{name}]"),
            Self::Pedal(name, (rest, full)) => {
                write!(f, "{name} = {{ rest_v = {rest:.3}, full_v = {full:.3} }}")
            }
            Self::Volts(name, volts) => write!(f, "{name} = {volts:.3}"),
        }
    }
}

/// Samples averaged for one calibration point (1 s at 1 kHz).
pub const CALIBRATION_SAMPLES: u32 = 1_000;

/// Which point the bench is recording.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BenchPoint {
    /// Pedal and brakes released: both pedal sensors' rest and both brake sensors' zero.
    Rest,
    /// Pedal fully pressed: both pedal sensors' full travel.
    Full,
}

/// The bring-up image's `cal rest` / `cal full`: each averages a second of samples.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BenchRecorder {
    /// APPS1, APPS2, BSE1 (front), BSE2 (rear) at rest (V at the sensors).
    rest: Option<[f32; 4]>,
    /// APPS1, APPS2 fully pressed.
    full: Option<[f32; 2]>,
    recording: Option<Recording>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Recording {
    point: BenchPoint,
    sums: [f32; 4],
    samples: u32,
}

/// What [`BenchRecorder`] has so far.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BenchResult {
    /// Neither point yet.
    Nothing,
    /// The rest point only.
    RestOnly([f32; 4]),
    /// The full point only.
    FullOnly([f32; 2]),
    /// Both: the calibration and its check.
    Complete(SensorCalibration, Result<(), CalibrationError>),
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

    /// Feeds one sample: both pedal sensors (a missing or non-finite reading skips the
    /// sample) and both brake sensors (V at the sensors). Returns true when the point just
    /// completed.
    pub fn sample(&mut self, pedals: [Option<f32>; 2], brakes: [f32; 2]) -> bool {
        let Some(recording) = self.recording.as_mut() else {
            return false;
        };
        let [Some(apps1), Some(apps2)] = pedals else {
            return false;
        };
        let values = [apps1, apps2, brakes[0], brakes[1]];
        if !values.iter().all(|value| value.is_finite()) {
            return false;
        }
        for (sum, value) in recording.sums.iter_mut().zip(values) {
            *sum += value;
        }
        recording.samples += 1;
        if recording.samples < CALIBRATION_SAMPLES {
            return false;
        }
        let n = recording.samples as f32;
        let mean = recording.sums.map(|sum| sum / n);
        match recording.point {
            BenchPoint::Rest => self.rest = Some(mean),
            BenchPoint::Full => self.full = Some([mean[0], mean[1]]),
        }
        self.recording = None;
        true
    }

    /// What has been measured.
    pub fn result(&self) -> BenchResult {
        match (self.rest, self.full) {
            (None, None) => BenchResult::Nothing,
            (Some(rest), None) => BenchResult::RestOnly(rest),
            (None, Some(full)) => BenchResult::FullOnly(full),
            (Some([rest1, rest2, front, rear]), Some([full1, full2])) => {
                let calibration = SensorCalibration {
                    pedals: AppsCalibration {
                        apps1: (rest1, full1),
                        apps2: (rest2, full2),
                    },
                    brakes: BrakeCalibration {
                        front_zero_v: front,
                        rear_zero_v: rear,
                    },
                };
                BenchResult::Complete(calibration, calibration.check())
            }
        }
    }
}

impl fmt::Display for BenchResult {
    /// The first line of the result; a complete one is followed by its
    /// [`SensorCalibration::toml_lines`].
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
            Self::Complete(_, Ok(())) => f.write_str(
                "calibration: check passed; put these lines in ccm/calibration.toml, then `cargo xtask firmware` and flash ccm.hex",
            ),
            Self::Complete(_, Err(error)) => write!(
                f,
                "calibration: REFUSED, {error}; check the sensor and repeat (the firmware's build refuses these values too)"
            ),
        }
    }
}

/// The car's measured calibration, from `ccm/calibration.toml` (read by the build): what the
/// firmware images start with.
pub mod measured {
    use super::{AppsCalibration, BrakeCalibration, SensorCalibration};
    include!(concat!(env!("OUT_DIR"), "/measured_calibration.rs"));
}
