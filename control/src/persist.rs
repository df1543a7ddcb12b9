//! How long a condition has held: debouncing, "fault after 100 ms", settle times.

/// Tracks since when a condition has been continuously true, on a wrapping millisecond clock.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Persist {
    since_ms: Option<u32>,
    last_true_ms: Option<u32>,
}

impl Persist {
    /// A condition that has not held yet.
    pub const fn new() -> Self {
        Self {
            since_ms: None,
            last_true_ms: None,
        }
    }

    /// Like [`update`](Self::update), but a false spell of at most `gap_ms` does not end the
    /// condition: a fault seen through a filter and noise near its threshold (a reading that
    /// dips back for a sample or two) still counts as continuous.
    pub fn update_bridging(&mut self, condition: bool, now_ms: u32, gap_ms: u32) -> Option<u32> {
        if condition {
            self.last_true_ms = Some(now_ms);
        }
        let bridged = self
            .last_true_ms
            .is_some_and(|at| now_ms.wrapping_sub(at) <= gap_ms);
        self.update(condition || bridged, now_ms)
    }

    /// Feeds the condition at `now_ms`; returns for how long it has held (`None` while false).
    pub fn update(&mut self, condition: bool, now_ms: u32) -> Option<u32> {
        if !condition {
            self.since_ms = None;
            return None;
        }
        let since = *self.since_ms.get_or_insert(now_ms);
        Some(now_ms.wrapping_sub(since))
    }

    /// Forgets the condition (as if it had been false).
    pub fn reset(&mut self) {
        self.since_ms = None;
        self.last_true_ms = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_from_the_first_true_sample_and_resets_on_false() {
        let mut persist = Persist::default();
        assert_eq!(persist.update(false, 0), None);
        assert_eq!(persist.update(true, 10), Some(0));
        assert_eq!(persist.update(true, 110), Some(100));
        assert_eq!(persist.update(false, 111), None);
        assert_eq!(persist.update(true, 112), Some(0));
        let mut wrapping = Persist::default();
        wrapping.update(true, u32::MAX - 5);
        assert_eq!(wrapping.update(true, 4), Some(10));
    }

    #[test]
    fn bridging_keeps_a_condition_through_short_false_spells_only() {
        let mut persist = Persist::default();
        assert_eq!(persist.update_bridging(true, 0, 10), Some(0));
        assert_eq!(persist.update_bridging(false, 5, 10), Some(5), "a 5 ms dip");
        assert_eq!(persist.update_bridging(true, 50, 10), Some(50));
        assert_eq!(
            persist.update_bridging(false, 61, 10),
            None,
            "11 ms without it"
        );
        assert_eq!(
            persist.update_bridging(true, 62, 10),
            Some(0),
            "starts again"
        );
    }
}
