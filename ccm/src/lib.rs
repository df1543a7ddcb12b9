//! Central computer (CCM) logic: hardware-free, `no_std`, tested on the host and on an
//! emulated Cortex-M7. The firmware images (`src/bin/`) only move data between [`Ccm`] and
//! the hardware, which `hw` (feature `firmware`) sets up one way for both.
//!
//! Data flow: 1 kHz sensor samples ([`apps`], [`brakes`], [`chassis`]) and CAN frames
//! ([`bus`], every value kept with its arrival time) -> 100 Hz control ([`faults`],
//! [`vehicle`], [`torque_path`]: [`launch`] or [`traction`], [`power`], then the independent
//! [`monitor`]; [`thermal`]) -> inverter frames ([`inverter`]), the CCM's own messages
//! ([`own_frames`]), and the telemetry
//! packet over ISO-TP ([`telemetry`]); [`watchdog`] supervises the tasks.
//!
//! State is split by writer so the firmware locks each part at its own priority: the wheel
//! pulse timers ([`chassis::PulseTimer`], lock-free), [`sensors::Sensors`], the
//! [`telemetry::TelemetryLink`] and [`control::Control`]; [`Ccm`] drives all four together.
//!
//! The bring-up image's bench ([`bench`](mod@bench)) is here too, over a hardware trait, so the bench
//! day's transcripts are what the image does.
#![no_std]

pub mod ads1115;
pub mod analog;
pub mod apps;
pub mod bench;
pub mod brakes;
pub mod bus;
pub mod calibration;
mod ccm;
pub mod chassis;
pub mod console;
pub mod constants;
pub mod control;
pub mod faults;
#[cfg(feature = "firmware")]
pub mod hw;
pub mod inverter;
mod io;
pub mod launch;
pub mod monitor;
pub mod own_frames;
pub mod power;
pub mod sensors;
pub mod stop;
pub mod telemetry;
pub mod thermal;
pub mod torque_path;
pub mod traction;
pub mod vehicle;
pub mod watchdog;
pub mod xcp;

pub use ccm::Ccm;
pub use inverter::{InverterKind, OutFrame, OutFrames};
pub use io::{BusHealth, ControlOutputs, DriverCounters, DriverInputs, SensorSample};
