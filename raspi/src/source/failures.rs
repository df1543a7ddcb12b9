//! When a failure that is retried every second deserves a log line: a CAN interface that is
//! missing (the hat not probed, a cable out) would otherwise write three lines a second into
//! the journal for as long as it lasts, burying everything else.

use std::time::{Duration, Instant};

/// How often a failure that goes on is reported again.
pub(crate) const REPORT_EVERY: Duration = Duration::from_secs(60);

/// Failures of one retried operation since it last worked.
#[derive(Debug)]
pub struct Failures {
    every: Duration,
    /// Since it last worked.
    total: u64,
    /// Since the last report.
    unreported: u64,
    last_report: Option<Instant>,
}

impl Failures {
    pub fn new(every: Duration) -> Self {
        Self {
            every,
            total: 0,
            unreported: 0,
            last_report: None,
        }
    }

    /// Counts a failure at `now`. Returns the failures to report (this one and those not yet
    /// reported) for the first failure and then at most once every `every`; `None` otherwise.
    pub fn failed(&mut self, now: Instant) -> Option<u64> {
        self.total += 1;
        self.unreported += 1;
        let due = self
            .last_report
            .is_none_or(|at| now.saturating_duration_since(at) >= self.every);
        if !due {
            return None;
        }
        self.last_report = Some(now);
        Some(std::mem::take(&mut self.unreported))
    }

    /// It works again: returns how many failures there were, if any (to report the
    /// recovery), and starts afresh, so the next failure is reported at once.
    pub(crate) fn recovered(&mut self) -> Option<u64> {
        let total = self.total;
        *self = Self::new(self.every);
        (total > 0).then_some(total)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_failure_is_reported_then_one_report_a_minute_with_the_count() {
        let start = Instant::now();
        let mut failures = Failures::new(REPORT_EVERY);
        assert_eq!(failures.failed(start), Some(1));
        // One a second for a minute: nothing until the minute is up, then all 60 at once.
        let reports: Vec<(u64, u64)> = (1..=150)
            .filter_map(|s| {
                failures
                    .failed(start + Duration::from_secs(s))
                    .map(|n| (s, n))
            })
            .collect();
        assert_eq!(reports, [(60, 60), (120, 60)]);
        assert_eq!(failures.recovered(), Some(151));
    }

    #[test]
    fn a_recovery_is_reported_once_and_the_next_failure_at_once() {
        let start = Instant::now();
        let mut failures = Failures::new(REPORT_EVERY);
        assert_eq!(failures.recovered(), None, "nothing failed");
        assert_eq!(failures.failed(start), Some(1));
        assert_eq!(failures.failed(start + Duration::from_secs(1)), None);
        assert_eq!(failures.recovered(), Some(2));
        assert_eq!(failures.recovered(), None);
        assert_eq!(failures.failed(start + Duration::from_secs(2)), Some(1));
    }
}
