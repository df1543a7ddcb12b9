//! Load: bytes on disk -> parsed schema plus where each item was written, for diagnostics.

pub(crate) mod dbc;
pub(crate) mod telemetry;
