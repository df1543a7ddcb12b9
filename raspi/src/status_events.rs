//! The status's changes as session events, so a run's record says what went wrong and when
//! long after the retained status moved on: each `problems` entry as it appears, changes and
//! clears, each drop or fault counter as it grows (once a second at most), and a looping
//! replay's loop points.

use crate::store::events::{Event, Kind};
use aer_host::reports::counters::ServiceCounters;
use aer_host::reports::status::Problems;
use serde_json::{Map, Value};

/// The counters whose growth is an event: frames or rows lost, and the car's traffic failing
/// its checks.
pub const WATCHED: [&str; 20] = [
    "bad_lines",
    "can_error_frames",
    "can_rx_overflows",
    "isotp_errors",
    "fingerprint_mismatches",
    "packet_errors",
    "decode_errors",
    "unknown_ids",
    "checksum_failures",
    "counter_repeats",
    "counter_jumps",
    "late_frames",
    "publish_dropped",
    "pit_dropped",
    "store_dropped",
    "raw_dropped",
    "mqtt_client_dropped",
    "xcp_dropped",
    "calibration_unrecorded",
    "events_unrecorded",
];

/// The counter a looping replay bumps at each loop point.
const LOOP_COUNTER: &str = "replay_passes";

/// What the status said last.
#[derive(Debug, Default)]
pub struct StatusWatch {
    problems: Map<String, Value>,
    counters: Map<String, Value>,
}

impl StatusWatch {
    /// Starts from the counters as they are (what came before the session is not its event).
    pub fn new(counters: &ServiceCounters) -> Self {
        Self {
            problems: Map::new(),
            counters: as_map(counters),
        }
    }

    /// The events between the last status and this one, stamped `at_us` (a loop point with
    /// `loop_at_us`, when the replay started again).
    pub fn update(
        &mut self,
        problems: &Problems,
        counters: &ServiceCounters,
        at_us: i64,
        loop_at_us: i64,
    ) -> Vec<Event> {
        let event = |kind, name: &str, text: String| Event {
            at_us,
            kind,
            name: name.to_owned(),
            text,
        };
        let mut events = Vec::new();
        let now = as_map(problems);
        for (name, value) in &now {
            let before = self.problems.get(name).filter(|v| !v.is_null());
            match (before, value.is_null()) {
                (Some(_), true) => events.push(event(Kind::Cleared, name, String::new())),
                (before, false) if before != Some(value) => {
                    events.push(event(Kind::Problem, name, text_of(value)));
                }
                _ => {}
            }
        }
        self.problems = now;
        let now = as_map(counters);
        let count = |map: &Map<String, Value>, name: &str| {
            map.get(name).and_then(Value::as_u64).unwrap_or(0)
        };
        for name in WATCHED {
            let grew = count(&now, name).saturating_sub(count(&self.counters, name));
            if grew > 0 {
                let total = count(&now, name);
                events.push(event(
                    Kind::Counted,
                    name,
                    format!("+{grew} ({total} in all)"),
                ));
            }
        }
        let passes = count(&now, LOOP_COUNTER);
        if passes > count(&self.counters, LOOP_COUNTER) {
            events.push(Event {
                at_us: if loop_at_us > 0 { loop_at_us } else { at_us },
                kind: Kind::Loop,
                name: "loop".to_owned(),
                text: format!(
                    "the looped log starts again (pass {}): its counters and telemetry sequence start over",
                    passes + 1
                ),
            });
        }
        self.counters = now;
        events
    }
}

fn as_map(value: &impl serde::Serialize) -> Map<String, Value> {
    match serde_json::to_value(value) {
        Ok(Value::Object(map)) => map,
        _ => Map::new(),
    }
}

fn text_of(value: &Value) -> String {
    match value {
        Value::String(text) => text.clone(),
        other => other.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use aer_host::reports::counters::Counters;
    use std::sync::atomic::Ordering;

    #[test]
    fn problems_appear_change_and_clear_and_counters_that_grow_are_named() {
        let counters = Counters::default();
        let mut watch = StatusWatch::new(&counters.snapshot());
        let mut problems = Problems::default();
        assert!(
            watch
                .update(&problems, &counters.snapshot(), 1, 0)
                .is_empty()
        );

        problems.can = Some("can1: No such device".into());
        counters.store_dropped.fetch_add(12, Ordering::Relaxed);
        let events = watch.update(&problems, &counters.snapshot(), 2, 0);
        assert_eq!(
            events,
            vec![
                Event {
                    at_us: 2,
                    kind: Kind::Problem,
                    name: "can".into(),
                    text: "can1: No such device".into()
                },
                Event {
                    at_us: 2,
                    kind: Kind::Counted,
                    name: "store_dropped".into(),
                    text: "+12 (12 in all)".into()
                },
            ]
        );
        // The same again is no event; a changed text is.
        assert!(
            watch
                .update(&problems, &counters.snapshot(), 3, 0)
                .is_empty()
        );
        problems.can = Some("can1: bus-off".into());
        let events = watch.update(&problems, &counters.snapshot(), 4, 0);
        assert_eq!(events.len(), 1);
        assert_eq!(events[0].text, "can1: bus-off");
        problems.can = None;
        counters.replay_passes.fetch_add(1, Ordering::Relaxed);
        let events = watch.update(&problems, &counters.snapshot(), 5, 4);
        let kinds: Vec<Kind> = events.iter().map(|e| e.kind).collect();
        assert_eq!(kinds, vec![Kind::Cleared, Kind::Loop], "{events:?}");
        assert_eq!(
            events[1].at_us, 4,
            "the loop point when the replay started again"
        );
    }

    #[test]
    fn every_watched_counter_is_a_counter() {
        let names = as_map(&Counters::default().snapshot());
        for name in WATCHED.iter().chain([&LOOP_COUNTER]) {
            assert!(names.contains_key(*name), "{name}");
        }
    }
}
