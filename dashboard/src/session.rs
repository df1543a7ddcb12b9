//! A recorded session (a candump log of the car) as the telemetry the Pi publishes: decoded
//! by the Pi service's own ingest code (ISO-TP, fingerprint check, generated unpacker), so a
//! screenshot shows exactly what the car sent.

use aer::mqtt::{Metrics, Sample, ServiceCounters, Status, TelemetryRecord};
use aer_raspi::candump::parse_line;
use aer_raspi::ingest::{Ingest, Record};
use aer_raspi::metrics::Counters;
use aer_raspi::publish;
use std::collections::HashMap;
use std::sync::Arc;

/// What a log holds.
#[derive(Debug, Clone)]
pub struct Session {
    /// Every telemetry packet, as published on the telemetry topic.
    pub samples: Vec<Sample<TelemetryRecord>>,
    /// The Pi's status after the session.
    pub status: Status,
    /// The Pi's metrics over the session's last whole second. Decoding a log stores nothing,
    /// and the live store's lag at the time is not in the log, so `store_lag` is 0.
    pub metrics: Metrics,
    /// Lines that were not CAN frames.
    pub bad_lines: u64,
}

/// Decodes `log` (candump `-l`/`-L` lines) as the Pi service would, for car `car_id`.
pub fn load(log: &str, car_id: &str) -> Session {
    let counters = Arc::new(Counters::default());
    let mut ingest = Ingest::new(counters.clone());
    let mut buses: HashMap<String, u8> = HashMap::new();
    let mut samples = Vec::new();
    let mut bad_lines = 0;
    // Counters at the last two whole seconds of the log, for the metrics' packet rate.
    let mut seconds: (Option<u64>, ServiceCounters, ServiceCounters) =
        (None, ServiceCounters::default(), ServiceCounters::default());
    for line in log.lines().filter(|l| !l.trim().is_empty()) {
        let parsed = parse_line(line, |name| {
            let next = u8::try_from(buses.len()).unwrap_or(u8::MAX);
            *buses.entry(name.to_owned()).or_insert(next)
        });
        let Ok(frame) = parsed else {
            bad_lines += 1;
            continue;
        };
        let second = frame.ts_us / 1_000_000;
        if seconds.0.is_some_and(|s| s != second) {
            seconds.1 = seconds.2;
            seconds.2 = counters.snapshot();
        }
        seconds.0 = Some(second);
        ingest.on_frame(
            &frame,
            |record| {
                if let Record::Telemetry {
                    ts_us,
                    header,
                    telemetry,
                    ..
                } = record
                {
                    samples.push(Sample {
                        ts: publish::seconds(ts_us),
                        value: TelemetryRecord {
                            header,
                            telemetry: *telemetry,
                        },
                    });
                }
            },
            |_, _| {},
        );
    }
    Session {
        samples,
        status: publish::status(car_id, &counters),
        metrics: Metrics {
            store_lag: 0,
            ..publish::metrics(seconds.2, seconds.1)
        },
        bad_lines,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bundled_session_decodes_completely() {
        let session = load(crate::screenshot::BUNDLED_SESSION, "car1");
        assert_eq!(session.bad_lines, 0);
        assert_eq!(session.samples.len(), 4_500, "45 s at 100 Hz");
        assert_eq!(session.status.fingerprint_match, Some(true));
        assert_eq!(session.metrics.packets_per_s, 100.0);
        assert_eq!(session.metrics.counters.isotp_errors, 0);
    }

    #[test]
    fn broken_lines_are_counted_and_skipped() {
        let log = "garbage\n(1.000000) can0 666#\n(1.000000) can0 1A0#00\n";
        let session = load(log, "car1");
        assert!(session.bad_lines >= 1, "{}", session.bad_lines);
        assert!(session.samples.is_empty());
    }
}
