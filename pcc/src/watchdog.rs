//! The hardware watchdog (WDOG1) policy: when the control loop may service it, and what a
//! restart after it expired means.
//!
//! The watchdog is serviced only from the control loop, and only when the loop ran on
//! schedule: a loop that hangs (in PRECHARGE, say, with AIR- and the precharge relay closed
//! and the too-slow timer dead), is starved by an interrupt storm, or panics stops servicing
//! it, and the PCC restarts with every relay open. After such a restart the PCC starts in
//! ERROR ([`Precharge::after_watchdog_reset`](crate::Precharge::after_watchdog_reset)).

/// SRC_SRSR bits that say the last reset came from a watchdog: WDOG1 (`wdog_rst_b`, bit 4)
/// or RTWDOG (`wdog3_rst_b`, bit 7). i.MX RT1060 reference manual, SRC chapter.
pub const SRSR_WATCHDOG_RESETS: u32 = 1 << 4 | 1 << 7;

/// Whether the reset status register `srsr` reports a watchdog reset.
pub const fn reset_by_watchdog(srsr: u32) -> bool {
    srsr & SRSR_WATCHDOG_RESETS != 0
}

/// Decides, step by step, whether the control loop is healthy enough to service the
/// watchdog.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LoopMonitor {
    period_us: u32,
    last_step_us: Option<u32>,
}

impl LoopMonitor {
    /// A loop meant to run every `period_ms`.
    pub const fn new(period_ms: u32) -> Self {
        Self {
            period_us: period_ms.saturating_mul(1_000),
            last_step_us: None,
        }
    }

    /// Records a completed control step at `now_us`; true if the watchdog may be serviced:
    /// the step came at most two periods after the previous one (the first step always
    /// may). A late step is not serviced, and the next on-time one is measured from it.
    pub fn step_completed(&mut self, now_us: u32) -> bool {
        let on_time = self
            .last_step_us
            .is_none_or(|last| now_us.wrapping_sub(last) <= self.period_us.saturating_mul(2));
        self.last_step_us = Some(now_us);
        on_time
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_on_time_steps_may_service_the_watchdog() {
        let mut monitor = LoopMonitor::new(10);
        assert!(monitor.step_completed(5_000), "first step");
        assert!(monitor.step_completed(15_000));
        assert!(
            monitor.step_completed(35_000),
            "two periods late is still on time"
        );
        assert!(!monitor.step_completed(55_001), "a stall");
        assert!(monitor.step_completed(65_000), "back on schedule");
        let mut wrapping = LoopMonitor::new(10);
        wrapping.step_completed(u32::MAX - 4_000);
        assert!(
            wrapping.step_completed(5_000),
            "the microsecond clock wraps"
        );
    }

    #[test]
    fn watchdog_resets_are_told_apart_from_power_on() {
        assert!(reset_by_watchdog(1 << 4));
        assert!(reset_by_watchdog(1 << 7 | 1));
        assert!(!reset_by_watchdog(1), "power-on reset (ipp_reset_b)");
        assert!(
            !reset_by_watchdog(1 << 3),
            "reset button (ipp_user_reset_b)"
        );
    }
}
