//! The run as the data shows it: the channels derived from the telemetry by the car's
//! parameters ([`derived`]) and the laps ([`laps`]), one rule for the driver's display and
//! the Pi's run report.

pub mod derived;
pub mod laps;
