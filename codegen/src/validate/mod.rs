//! Validate: a parsed schema -> the model, or diagnostics saying exactly what to fix.

pub mod dbc;
pub mod telemetry;
