//! Validate: a parsed schema -> the model, or diagnostics saying exactly what to fix.

pub(crate) mod calibration;
pub(crate) mod dbc;
pub(crate) mod names;
pub(crate) mod telemetry;
pub(crate) mod xcp;
