//! A recorded session (a candump log of the car) as the telemetry the Pi publishes: decoded
//! by the Pi service's own ingest code (`aer_host::decode`: ISO-TP, fingerprint check,
//! generated unpacker), so a screenshot shows exactly what the car sent.

use aer::mqtt::{Sample, TelemetryRecord};
use aer_host::clock::seconds;
use aer_host::decode::decode_log;
use aer_host::reports::status::{Metrics, Problems, Status, status};

/// The session the Pi's demo replays (recorded from the CCM's own logic).
pub const BUNDLED_SESSION: &str = include_str!("../../raspi/data/session.log");

/// What a log holds.
#[derive(Debug, Clone)]
pub struct Session {
    /// Every telemetry packet, as published on the telemetry topic.
    pub samples: Vec<Sample<TelemetryRecord>>,
    /// The Pi's status after the session.
    pub status: Status,
    /// The Pi's metrics at the session's end, with the packet rate of its last second.
    /// Decoding a log stores nothing, and the live store's lag at the time is not in the log,
    /// so `store_lag` is 0.
    pub metrics: Metrics,
}

/// Decodes `log` (candump `-l`/`-L` lines) as the Pi service would, for car `car_id`.
pub fn load(log: &str, car_id: &str) -> Session {
    let decoded = decode_log(log);
    let samples: Vec<Sample<TelemetryRecord>> = decoded
        .packets
        .into_iter()
        .map(|(ts_us, header, telemetry)| Sample {
            ts: seconds(ts_us),
            value: TelemetryRecord { header, telemetry },
        })
        .collect();
    let end = samples.last().map_or(0.0, |s| s.ts);
    let last_second = samples
        .iter()
        .rev()
        .take_while(|s| s.ts > end - 1.0)
        .count();
    Session {
        metrics: Metrics {
            ts: end,
            packets_per_s: last_second as f64,
            store_lag: 0,
            counters: decoded.counters.snapshot(),
        },
        status: status(car_id, &decoded.counters, Problems::default()),
        samples,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bundled_session_decodes_completely() {
        let session = load(BUNDLED_SESSION, "car1");
        assert_eq!(session.metrics.counters.bad_lines, 0);
        assert_eq!(session.samples.len(), 4_500, "45 s at 100 Hz");
        assert_eq!(session.status.fingerprint_match, Some(true));
        assert_eq!(session.metrics.packets_per_s, 100.0);
        assert_eq!(session.metrics.counters.isotp_errors, 0);
    }

    #[test]
    fn broken_lines_are_counted_and_skipped() {
        let log = "garbage\n(1.000000) can0 666#\n(1.000000) can0 1A0#00\n";
        let session = load(log, "car1");
        assert!(session.metrics.counters.bad_lines >= 1);
        assert!(session.samples.is_empty());
    }
}
