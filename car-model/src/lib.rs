//! A closed-loop model of the car for tests and the demo session.
//!
//! The CCM logic (`aer_ccm::Ccm`) and the PCC logic (`aer_pcc::Precharge`) run exactly as on
//! the Teensys, driven through the same APIs the firmware uses; around them the model
//! provides:
//! - the car ([`car`]): motor and inverter (torque follows VCU1, which must carry a valid
//!   checksum and counter; power through the drivetrain's efficiency), longitudinal dynamics
//!   with a tyre slip curve, drag and brakes ([`chassis`]), an accumulator whose voltage
//!   sags with current ([`pack`]), the precharge circuit ([`precharge`]);
//! - the other nodes' frames at their DBC cycle times and resolutions, with the measurement's
//!   lag and the BMS's delay ([`nodes`]), and the CCM's sensors ([`sensors`]);
//! - a driver who starts the car and follows a drive cycle ([`driver`]);
//! - fault injection ([`faults`]);
//! - the FSAE rules as invariants, checked every millisecond ([`rules`]);
//! - the CCM's XCP slave around the loop, for calibration tools ([`xcp_car`]).
//!
//! [`ClosedLoop`] ties them together. `no_std` and allocation-free, so the same run also
//! executes on the emulated Cortex-M7 (`cargo xtask m7-check`).
#![no_std]

pub mod car;
pub mod chassis;
mod closed_loop;
pub mod driver;
pub mod faults;
pub mod nodes;
pub mod pack;
pub mod params;
pub mod powertrain;
pub mod precharge;
pub mod rng;
pub mod rules;
pub mod sensors;
pub mod xcp_car;

pub use closed_loop::{BusTap, ClosedLoop, NoTap};
pub use params::ModelParams;
pub use xcp_car::XcpCar;
