//! Timestamps: microseconds since the Unix epoch inside the service, seconds on the topics
//! (PlotJuggler's `ts`).

use std::time::{SystemTime, UNIX_EPOCH};

/// Microseconds since the Unix epoch, now.
pub fn now_us() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_micros()).unwrap_or(u64::MAX))
}

/// Seconds since the epoch for a time in microseconds, as the topics carry `ts`.
pub fn seconds(ts_us: u64) -> f64 {
    ts_us as f64 / 1e6
}
