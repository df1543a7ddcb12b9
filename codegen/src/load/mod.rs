//! Load: bytes on disk -> parsed schema plus where each item was written, for diagnostics.

pub mod dbc;
pub mod telemetry;
