//! The wall clock every stored time comes from. A Pi has no clock of its own unless a battery
//! is fitted to its RTC: at a track without a network it starts from the time it last saved,
//! which can be days off, until someone sets it (docs/test-day.md, "Before"). So each session
//! records whether the clock was synchronized when it began, and every step the clock takes
//! while it is open (set by hand, or synchronized late): with both, an analyst knows which of
//! a session's times to trust and by how much to move the others.

use std::path::Path;
use std::time::{Instant, SystemTime, UNIX_EPOCH};

/// Every step of the wall clock while a session was open (written and read by
/// [`super::session`], which owns the sessions' tables).
pub(crate) const SESSION_CLOCK_TABLE: &str = "CREATE TABLE IF NOT EXISTS \"session_clock\" (\"session_id\" INTEGER NOT NULL, \"at_us\" INTEGER NOT NULL, \"step_us\" INTEGER NOT NULL)";

/// systemd-timesyncd makes this file once it has synchronized the clock (and removes it at
/// boot).
const TIMESYNCD_SYNCHRONIZED: &str = "/run/systemd/timesync/synchronized";

/// A step smaller than this is drift or scheduling, not a step (us).
const STEP_MIN_US: i64 = 1_000_000;

/// The clock's state as a session records it when it begins.
pub fn state() -> String {
    state_from(Path::new(TIMESYNCD_SYNCHRONIZED))
}

fn state_from(marker: &Path) -> String {
    if marker.exists() {
        "synchronized (network time)".into()
    } else {
        "NOT synchronized (the RTC, or the time saved at the last shutdown)".into()
    }
}

/// Watches the wall clock against the monotonic one: a change in their difference is a step.
#[derive(Debug)]
pub struct StepWatch {
    base: Instant,
    offset_us: Option<i64>,
}

impl Default for StepWatch {
    fn default() -> Self {
        Self::new()
    }
}

impl StepWatch {
    /// Starts watching now.
    pub fn new() -> Self {
        Self {
            base: Instant::now(),
            offset_us: None,
        }
    }

    /// The step since the last check, if the clock stepped: (the wall time now, the step),
    /// microseconds.
    pub fn check(&mut self) -> Option<(i64, i64)> {
        let wall_us = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| i64::try_from(d.as_micros()).unwrap_or(i64::MAX));
        let mono_us = i64::try_from(self.base.elapsed().as_micros()).unwrap_or(i64::MAX);
        self.observe(wall_us, mono_us)
    }

    fn observe(&mut self, wall_us: i64, mono_us: i64) -> Option<(i64, i64)> {
        let offset = wall_us.saturating_sub(mono_us);
        let previous = self.offset_us.replace(offset)?;
        let step = offset.saturating_sub(previous);
        (step.abs() >= STEP_MIN_US).then_some((wall_us, step))
    }
}

/// A step as text: `+3 d 2 h 5 min 10.5 s at 2026-11-26T10:00:00Z`.
pub fn describe_step(at_us: i64, step_us: i64) -> String {
    let sign = if step_us < 0 { '-' } else { '+' };
    let mut rest = step_us.unsigned_abs();
    let mut text = String::new();
    for (unit, size) in [
        ("d", 86_400_000_000u64),
        ("h", 3_600_000_000),
        ("min", 60_000_000),
    ] {
        if rest >= size {
            text.push_str(&format!("{} {unit} ", rest / size));
            rest %= size;
        }
    }
    text.push_str(&format!("{:.1} s", rest as f64 / 1e6));
    format!("{sign}{text} at {}", super::utc(at_us))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_step_is_a_change_between_the_wall_and_the_monotonic_clock() {
        let mut watch = StepWatch::new();
        assert_eq!(watch.observe(1_000_000_000, 0), None, "the first look");
        assert_eq!(
            watch.observe(1_001_000_000, 1_000_000),
            None,
            "time passing"
        );
        assert_eq!(
            watch.observe(1_001_500_000, 1_500_000),
            None,
            "drift under a second"
        );
        // Set forward by three days from the pit.
        let three_days = 3 * 86_400_000_000;
        assert_eq!(
            watch.observe(1_002_000_000 + three_days, 2_000_000),
            Some((1_002_000_000 + three_days, three_days))
        );
        assert_eq!(watch.observe(1_003_000_000 + three_days, 3_000_000), None);
    }

    #[test]
    fn steps_read_as_days_hours_and_seconds() {
        assert_eq!(
            describe_step(1_795_687_200_000_000, 3 * 86_400_000_000 + 7_210_500_000),
            "+3 d 2 h 10.5 s at 2026-11-26T10:00:00.000000Z"
        );
        assert_eq!(
            describe_step(0, -1_500_000),
            "-1.5 s at 1970-01-01T00:00:00.000000Z"
        );
    }

    #[test]
    fn the_state_says_whether_network_time_synchronized_the_clock() {
        let dir = tempfile::tempdir().expect("dir");
        let marker = dir.path().join("synchronized");
        assert!(state_from(&marker).starts_with("NOT synchronized"));
        std::fs::write(&marker, "").expect("write");
        assert!(state_from(&marker).starts_with("synchronized"));
    }
}
