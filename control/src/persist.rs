//! How long a condition has held: debouncing, "fault after 100 ms", settle times.

/// Tracks since when a condition has been continuously true, on a wrapping millisecond clock.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Persist {
    since_ms: Option<u32>,
}

impl Persist {
    /// A condition that has not held yet.
    pub const fn new() -> Self {
        Self { since_ms: None }
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
}
