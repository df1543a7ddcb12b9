//! The driver and pit dashboard as a library: the binary (`aer-dashboard`), the headless UI
//! tests, the end-to-end test and the benchmark use the same code.
//!
//! Data flow: [`link`] (MQTT: the generated typed topics on the Pi's broker) -> [`model`] (the
//! latest packet, alarms, plots, laps, link health; no UI types) -> [`ui`] (iced: the driver
//! and pit views). [`session`] and [`screenshot`] render the views from a recorded session
//! without a display.

pub mod config;
pub mod link;
pub mod model;
pub mod screenshot;
pub mod session;
pub mod ui;
