//! Lap marks from the dashboards to the Pi: the driver's L key (or the pit's) ends the lap in
//! progress on the display and is published here; the Pi stores it in the running session's
//! events, where the run report times laps with it.
//!
//! ```text
//! aer-pit/<car>/marks    a dashboard -> the Pi: a Mark (JSON)
//! ```

use serde::{Deserialize, Serialize};
use thiserror::Error;

/// The largest mark payload the Pi reads.
pub const MAX_MARK: usize = 256;
/// The longest name of who marked.
pub const MAX_BY: usize = 40;

/// Where dashboards publish marks for the car below `car_prefix` (`aer/car1` ->
/// `aer-pit/car1/marks`).
pub fn topic(car_prefix: &str) -> String {
    format!("{}/marks", crate::formats::pit_stream::pit_root(car_prefix))
}

/// One mark.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Mark {
    /// When the lap ended, on the data's time base: seconds since the epoch (the `ts` of the
    /// telemetry the dashboard showed).
    pub ts: f64,
    /// Who marked: `driver` or `pit`.
    pub by: String,
}

/// Why a payload is no mark.
#[derive(Debug, Error, PartialEq)]
pub enum MarkError {
    #[error("a mark of {0} bytes (at most {MAX_MARK})")]
    TooLong(usize),
    #[error("not a mark: {0}")]
    Malformed(String),
    #[error("a mark at {0} s: not a time")]
    BadTime(f64),
    #[error("a mark by a name of {0} characters (at most {MAX_BY})")]
    BadName(usize),
}

impl Mark {
    /// Reads a payload a client sent: untrusted, checked.
    pub fn parse(payload: &[u8]) -> Result<Self, MarkError> {
        if payload.len() > MAX_MARK {
            return Err(MarkError::TooLong(payload.len()));
        }
        let mark: Self =
            serde_json::from_slice(payload).map_err(|e| MarkError::Malformed(e.to_string()))?;
        if !(mark.ts.is_finite() && mark.ts > 0.0 && mark.ts < 1e11) {
            return Err(MarkError::BadTime(mark.ts));
        }
        let chars = mark.by.chars().count();
        if chars == 0 || chars > MAX_BY || mark.by.chars().any(char::is_control) {
            return Err(MarkError::BadName(chars));
        }
        Ok(mark)
    }

    /// The payload a dashboard publishes.
    pub fn to_payload(&self) -> Vec<u8> {
        serde_json::to_vec(self).unwrap_or_default()
    }

    /// Its time in microseconds since the epoch.
    pub fn at_us(&self) -> i64 {
        (self.ts * 1e6).round() as i64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_mark_reads_back_and_bad_ones_are_refused_with_why() {
        let mark = Mark {
            ts: 1_764_000_000.25,
            by: "driver".into(),
        };
        assert_eq!(Mark::parse(&mark.to_payload()), Ok(mark.clone()));
        assert_eq!(mark.at_us(), 1_764_000_000_250_000);
        assert_eq!(topic("aer/car1"), "aer-pit/car1/marks");
        assert!(matches!(Mark::parse(b"{}"), Err(MarkError::Malformed(_))));
        assert!(matches!(
            Mark::parse(br#"{"ts":-1,"by":"pit"}"#),
            Err(MarkError::BadTime(_))
        ));
        assert!(matches!(
            Mark::parse(br#"{"ts":1e9,"by":""}"#),
            Err(MarkError::BadName(0))
        ));
        assert!(matches!(
            Mark::parse(&[b' '; 300]),
            Err(MarkError::TooLong(300))
        ));
    }
}
