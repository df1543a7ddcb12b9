//! One-pole low-pass: alpha = 1 / (1 + (1 / (2 pi fc)) / dt), the team's filter.

/// A one-pole low-pass filter for samples at a fixed period.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LowPass {
    alpha: f32,
    value: Option<f32>,
}

impl LowPass {
    /// A filter with cut-off `cutoff_hz` for samples every `period_s` seconds.
    pub fn new(cutoff_hz: f32, period_s: f32) -> Self {
        let time_constant = 1.0 / (2.0 * core::f32::consts::PI * cutoff_hz);
        Self {
            alpha: 1.0 / (1.0 + time_constant / period_s),
            value: None,
        }
    }

    /// Feeds one sample and returns the filtered value; the first sample passes unchanged so
    /// the output does not crawl up from zero. A sample that is not a number is skipped.
    pub fn update(&mut self, sample: f32) -> f32 {
        if !sample.is_finite() {
            return self.value.unwrap_or(0.0);
        }
        let value = match self.value {
            None => sample,
            Some(previous) => previous + self.alpha * (sample - previous),
        };
        self.value = Some(value);
        value
    }

    /// The last output (0 before the first sample).
    pub fn value(&self) -> f32 {
        self.value.unwrap_or(0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn alpha_follows_the_team_formula() {
        // fc = 100 Hz at dt = 1 ms (the APPS filter): alpha = 1 / (1 + 1.5915) = 0.3859.
        let mut filter = LowPass::new(100.0, 0.001);
        assert_eq!(filter.update(10.0), 10.0);
        let next = filter.update(0.0);
        assert!((next - 10.0 * (1.0 - 0.385_869)).abs() < 1e-3, "{next}");
    }

    #[test]
    fn a_step_settles_and_nan_is_skipped() {
        let mut filter = LowPass::new(100.0, 0.001);
        filter.update(0.0);
        for _ in 0..50 {
            filter.update(1.0);
        }
        assert!((filter.value() - 1.0).abs() < 1e-6);
        assert_eq!(filter.update(f32::NAN), filter.value());
    }
}
