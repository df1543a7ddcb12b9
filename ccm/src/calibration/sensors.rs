//! The part of the calibration the bench measures, the sensors: the pedal sensors at rest and
//! at full travel, each brake pressure sensor with the brakes released, each shock sensor at
//! full extension and full compression. [`SensorCalibration::check`] is the one check they
//! pass everywhere: on the bench, at build time (`ccm/calibration.toml`), when a saved copy
//! loads and when a calibration tool writes them.

use super::Calibration;
use crate::constants::{
    APPS1_SUPPLY_V, APPS2_SUPPLY_V, BSE_ZERO_V, MIN_PEDAL_TRAVEL_V, MIN_SHOCK_SPAN_V, SHOCK_VALID_V,
};
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
    /// through `ccm/calibration.toml` or a saved copy.
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

/// The shock sensors by the corner the board table maps them to, in input order (1-4), as
/// the console and `ccm/calibration.toml` name them.
pub const SHOCK_CORNERS: [&str; 4] = ["fl", "fr", "rl", "rr"];

/// Each shock sensor's voltage at its travel's two ends (V at the sensor), in input order.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShockCalibration {
    /// Fully extended: zero travel.
    pub extended_v: [f32; 4],
    /// Fully compressed: the full travel.
    pub compressed_v: [f32; 4],
}

impl ShockCalibration {
    /// The schema's default: the team's documented 5.00 V extended, 4.86 V compressed.
    pub const DEFAULT: Self = SensorCalibration::of(&Calibration::DEFAULT).shocks;
}

/// Everything the bench measures about the sensors.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorCalibration {
    /// The accelerator pedal's two sensors.
    pub pedals: AppsCalibration,
    /// The brake pressure sensors' zero.
    pub brakes: BrakeCalibration,
    /// The shock sensors' ends.
    pub shocks: ShockCalibration,
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
    /// A shock sensor's end lies outside [`SHOCK_VALID_V`] (an open input reads near 0 V).
    ShockOutOfBand {
        /// `fl`, `fr`, `rl` or `rr`.
        corner: &'static str,
        /// `extended` or `compressed`.
        point: &'static str,
        /// What was given (V).
        volts: f32,
    },
    /// A shock sensor's ends lie less than [`MIN_SHOCK_SPAN_V`] apart.
    ShockTooLittleTravel {
        /// `fl`, `fr`, `rl` or `rr`.
        corner: &'static str,
        /// Compressed minus extended (V).
        span_v: f32,
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
            Self::ShockOutOfBand {
                corner,
                point,
                volts,
            } => write!(
                f,
                "the {corner} shock sensor reads {volts:.3} V {point}, outside {:.2}-{:.2} V (an open or unpowered sensor reads near 0 V)",
                SHOCK_VALID_V.0, SHOCK_VALID_V.1
            ),
            Self::ShockTooLittleTravel { corner, span_v } => write!(
                f,
                "the {corner} shock sensor moves {:.3} V from extended to compressed, less than {MIN_SHOCK_SPAN_V:.2} V (was the damper really moved end to end?)",
                span_v.abs()
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
            Self::ShockOutOfBand { .. } => {
                "ccm/calibration.toml: a shock sensor end lies outside its band (`cargo test -p aer-ccm --test calibration` says which)"
            }
            Self::ShockTooLittleTravel { .. } => {
                "ccm/calibration.toml: a shock sensor's ends lie too close together (`cargo test -p aer-ccm --test calibration` says which)"
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
            shocks: ShockCalibration {
                extended_v: calibration.shock_extended_v,
                compressed_v: calibration.shock_compressed_v,
            },
        }
    }

    /// `calibration` with these sensors: what a firmware image starts with.
    pub const fn applied_to(self, calibration: Calibration) -> Calibration {
        Calibration {
            apps1_v: [self.pedals.apps1.0, self.pedals.apps1.1],
            apps2_v: [self.pedals.apps2.0, self.pedals.apps2.1],
            brake_zero_v: [self.brakes.front_zero_v, self.brakes.rear_zero_v],
            shock_extended_v: self.shocks.extended_v,
            shock_compressed_v: self.shocks.compressed_v,
            ..calibration
        }
    }

    /// Whether the CCM can run with this calibration: the pedal and brake sensors
    /// ([`Self::check_pedals`]) and the shock sensors ([`ShockCalibration::check`]). A
    /// `const fn`, so the firmware images' build refuses a bad file.
    pub const fn check(&self) -> Result<(), CalibrationError> {
        if let Err(error) = check_pedals(&self.pedals, &self.brakes) {
            return Err(error);
        }
        self.shocks.check()
    }

    /// The pedal and brake sensors' part of [`Self::check`].
    pub const fn check_pedals(&self) -> Result<(), CalibrationError> {
        check_pedals(&self.pedals, &self.brakes)
    }

    /// The pedal and brake sensors as the lines of `ccm/calibration.toml`.
    pub fn pedal_toml_lines(&self) -> [TomlLine; 6] {
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

/// Every pedal point inside its sensor's valid band (10-90 % of its supply), enough travel
/// on each sensor, each brake zero inside [`BSE_ZERO_V`].
const fn check_pedals(
    pedals: &AppsCalibration,
    brakes: &BrakeCalibration,
) -> Result<(), CalibrationError> {
    let sensors = [
        ("APPS1", pedals.apps1, APPS1_SUPPLY_V),
        ("APPS2", pedals.apps2, APPS2_SUPPLY_V),
    ];
    let mut index = 0;
    while index < sensors.len() {
        let (sensor, (rest, full), supply) = sensors[index];
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
        ("front (BSE1)", brakes.front_zero_v),
        ("rear (BSE2)", brakes.rear_zero_v),
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

impl ShockCalibration {
    /// Each end inside [`SHOCK_VALID_V`], and each sensor's ends at least
    /// [`MIN_SHOCK_SPAN_V`] apart (either way round: a sensor mounted the other way rises
    /// with compression).
    pub const fn check(&self) -> Result<(), CalibrationError> {
        let mut index = 0;
        while index < SHOCK_CORNERS.len() {
            let corner = SHOCK_CORNERS[index];
            let ends = [
                ("extended", self.extended_v[index]),
                ("compressed", self.compressed_v[index]),
            ];
            let mut end = 0;
            while end < ends.len() {
                let (point, volts) = ends[end];
                if !(volts >= SHOCK_VALID_V.0 && volts <= SHOCK_VALID_V.1) {
                    return Err(CalibrationError::ShockOutOfBand {
                        corner,
                        point,
                        volts,
                    });
                }
                end += 1;
            }
            let span_v = self.compressed_v[index] - self.extended_v[index];
            if !(span_v >= MIN_SHOCK_SPAN_V || span_v <= -MIN_SHOCK_SPAN_V) {
                return Err(CalibrationError::ShockTooLittleTravel { corner, span_v });
            }
            index += 1;
        }
        Ok(())
    }

    /// The shock sensors as the lines of `ccm/calibration.toml`.
    pub fn toml_lines(&self) -> [TomlLine; 5] {
        let corner = |index: usize| {
            let name = SHOCK_CORNERS.get(index).copied().unwrap_or("?");
            let extended = self.extended_v.get(index).copied().unwrap_or(f32::NAN);
            let compressed = self.compressed_v.get(index).copied().unwrap_or(f32::NAN);
            TomlLine::Shock(name, (extended, compressed))
        };
        [
            TomlLine::Section("shocks"),
            corner(0),
            corner(1),
            corner(2),
            corner(3),
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
    /// `name = { extended_v = .., compressed_v = .. }`.
    Shock(&'static str, (f32, f32)),
}

impl fmt::Display for TomlLine {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::Section(name) => write!(f, "[{name}]"),
            Self::Pedal(name, (rest, full)) => {
                write!(f, "{name} = {{ rest_v = {rest:.3}, full_v = {full:.3} }}")
            }
            Self::Volts(name, volts) => write!(f, "{name} = {volts:.3}"),
            Self::Shock(name, (extended, compressed)) => write!(
                f,
                "{name} = {{ extended_v = {extended:.3}, compressed_v = {compressed:.3} }}"
            ),
        }
    }
}
