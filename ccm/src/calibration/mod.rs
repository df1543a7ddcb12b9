//! The car's calibration: every tuned number, declared in `schema/calibration.yaml` and
//! generated as [`Calibration`] (its defaults, limits and change conditions), and the part of
//! it the bench measures, the sensors ([`SensorCalibration`]): the pedal sensors at rest and at
//! full travel, each brake pressure sensor with the brakes released, each shock sensor at both
//! ends of its travel. The bench measures them with the bring-up image ([`bench`](mod@bench));
//! `ccm/calibration.toml` records them and the firmware images' build reads them
//! ([`measured`]); [`SensorCalibration::check`] checks them everywhere.
//!
//! Which calibration a race image runs is one rule ([`store::Loaded::or_measured`]): the
//! newest good saved copy in flash, else the schema's defaults with `ccm/calibration.toml`'s
//! sensors. The tests and the car model keep [`Calibration::DEFAULT`]: a measured pedal
//! changes the car, not the proofs.

pub mod bench;
pub mod sensors;
pub mod state;
pub mod store;
pub mod why;

pub use aer::calibration::Calibration;
pub use bench::{BenchPoint, BenchRecorder, BenchSample, CALIBRATION_SAMPLES, ShockEnd};
pub use sensors::{
    AppsCalibration, BrakeCalibration, CalibrationError, SHOCK_CORNERS, SensorCalibration,
    ShockCalibration, TomlLine,
};

/// The ECU program identifier (the schema's layouts, `aer::calibration::xcp::EPK`): what the
/// saved copies carry and XCP masters compare with their A2L.
pub const EPK: &[u8] = aer::calibration::xcp::EPK.as_bytes();

const _: () = assert!(
    EPK.len() <= store::EPK_FIELD_LEN,
    "the EPK must fit the saved record"
);

/// The car's measured calibration, from `ccm/calibration.toml` (read by the build): what the
/// firmware images run while no good copy is saved.
pub mod measured {
    use super::{AppsCalibration, BrakeCalibration, SensorCalibration, ShockCalibration};
    include!(concat!(env!("OUT_DIR"), "/measured_calibration.rs"));
}
