//! PID controller with state that persists between steps and a fixed step, the two defects
//! the team's documentation lists for its launch and traction control.

/// Gains and limits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PidGains {
    /// Proportional gain.
    pub kp: f32,
    /// Integral gain (per second).
    pub ki: f32,
    /// Derivative gain (seconds).
    pub kd: f32,
    /// The integral term's contribution is kept within (low, high) (anti-windup).
    pub integral_range: (f32, f32),
    /// The output is kept within (low, high).
    pub output_range: (f32, f32),
}

/// A PID controller stepped at a fixed period.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pid {
    gains: PidGains,
    period_s: f32,
    integral: f32,
    previous_error: Option<f32>,
}

impl Pid {
    /// A controller stepped every `period_s` seconds.
    pub const fn new(gains: PidGains, period_s: f32) -> Self {
        Self {
            gains,
            period_s,
            integral: 0.0,
            previous_error: None,
        }
    }

    /// One step on `error` (setpoint - measurement); returns the correction.
    pub fn step(&mut self, error: f32) -> f32 {
        let PidGains {
            kp,
            ki,
            kd,
            integral_range,
            output_range,
        } = self.gains;
        if !error.is_finite() {
            return 0.0;
        }
        self.integral = (self.integral + ki * error * self.period_s)
            .max(integral_range.0)
            .min(integral_range.1);
        let derivative = self
            .previous_error
            .map_or(0.0, |previous| kd * (error - previous) / self.period_s);
        self.previous_error = Some(error);
        (kp * error + self.integral + derivative)
            .max(output_range.0)
            .min(output_range.1)
    }

    /// New gains from the next step on (a calibration change). The integral is kept as the
    /// contribution it has built up, so a new integral gain does not make the output jump.
    pub fn set_gains(&mut self, gains: PidGains) {
        self.gains = gains;
    }

    /// Clears the integral and derivative history.
    pub fn reset(&mut self) {
        self.integral = 0.0;
        self.previous_error = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const GAINS: PidGains = PidGains {
        kp: 2.0,
        ki: 10.0,
        kd: 0.0,
        integral_range: (-5.0, 5.0),
        output_range: (-100.0, 100.0),
    };

    #[test]
    fn the_integral_persists_between_steps_and_is_limited() {
        let mut pid = Pid::new(GAINS, 0.01);
        let first = pid.step(1.0);
        let second = pid.step(1.0);
        assert!((first - 2.1).abs() < 1e-6, "{first}");
        assert!(
            (second - 2.2).abs() < 1e-6,
            "state kept between steps: {second}"
        );
        for _ in 0..1_000 {
            pid.step(1.0);
        }
        assert!((pid.step(1.0) - 7.0).abs() < 1e-5, "integral capped at 5");
        pid.reset();
        assert!((pid.step(1.0) - 2.1).abs() < 1e-6);
    }

    #[test]
    fn a_one_sided_integral_bleeds_to_its_floor_and_no_further() {
        // A controller that only ever removes something: a long negative error must not
        // store up a negative integral that would delay the next positive correction.
        let mut pid = Pid::new(
            PidGains {
                integral_range: (0.0, 5.0),
                output_range: (0.0, 100.0),
                ..GAINS
            },
            0.01,
        );
        for _ in 0..1_000 {
            assert_eq!(pid.step(-1.0), 0.0);
        }
        assert!((pid.step(1.0) - 2.1).abs() < 1e-6, "starts from zero");
    }

    #[test]
    fn the_derivative_uses_the_fixed_period_and_output_is_limited() {
        let mut pid = Pid::new(
            PidGains {
                kp: 0.0,
                ki: 0.0,
                kd: 0.1,
                ..GAINS
            },
            0.01,
        );
        assert_eq!(pid.step(0.0), 0.0);
        assert!((pid.step(1.0) - 10.0).abs() < 1e-4);
        let mut saturating = Pid::new(
            PidGains {
                kp: 1_000.0,
                ..GAINS
            },
            0.01,
        );
        assert_eq!(saturating.step(1.0), 100.0);
        assert_eq!(saturating.step(f32::NAN), 0.0);
    }
}
