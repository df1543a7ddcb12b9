//! Traction control: reduces torque when the driven wheels spin faster than the front wheels.
//!
//! slip = (rear average - front average) / front average, front speeds filtered; above the
//! calibration's threshold (10 %) a PID (state kept between steps, fixed 100 Hz, the
//! calibration's gains) removes torque. It never adds torque: the
//! result is within 0..driver torque. The integral never goes below zero, so a long stretch
//! without slip cannot store up a negative reduction that would delay the next intervention.

use crate::calibration::Calibration;
use crate::constants::{MIN_SLIP_SPEED_RAD_S, MOTOR_MAX_TORQUE_NM};
use aer_control::{LowPass, Pid, PidGains};

/// The gains with the calibration's `kp` and `ki` (at the defaults, 30 % slip over the
/// threshold takes away about 150 Nm at once).
const fn gains(kp: f32, ki: f32) -> PidGains {
    PidGains {
        kp,
        ki,
        kd: 0.0,
        integral_range: (0.0, MOTOR_MAX_TORQUE_NM),
        output_range: (0.0, MOTOR_MAX_TORQUE_NM),
    }
}

/// Traction control.
#[derive(Debug, Clone)]
pub struct TractionControl {
    pid: Pid,
    front: LowPass,
    rear: LowPass,
    slip: f32,
}

impl TractionControl {
    /// A controller stepped every `period_ms`.
    pub fn new(period_ms: u32) -> Self {
        let period_s = period_ms as f32 / 1_000.0;
        Self {
            pid: Pid::new(
                gains(
                    Calibration::DEFAULT.traction_kp,
                    Calibration::DEFAULT.traction_ki,
                ),
                period_s,
            ),
            front: LowPass::new(10.0, period_s),
            rear: LowPass::new(10.0, period_s),
            slip: 0.0,
        }
    }

    /// Slip ratio of the last step.
    pub fn slip(&self) -> f32 {
        self.slip
    }

    /// One 100 Hz step on average front and rear wheel speeds (rad/s), with the
    /// `calibration`'s threshold and gains as they are now.
    pub fn step(
        &mut self,
        calibration: &Calibration,
        front_rad_s: f32,
        rear_rad_s: f32,
        driver_torque_nm: f32,
    ) -> f32 {
        self.pid
            .set_gains(gains(calibration.traction_kp, calibration.traction_ki));
        let front = self.front.update(front_rad_s);
        let rear = self.rear.update(rear_rad_s);
        let demand = driver_torque_nm.clamp(0.0, MOTOR_MAX_TORQUE_NM);
        if front.is_nan() || front < MIN_SLIP_SPEED_RAD_S {
            self.slip = 0.0;
            self.pid.reset();
            return demand;
        }
        self.slip = (rear - front) / front;
        // Only the excess over the threshold counts; once slip is back under it the integral
        // bleeds off to zero (negative error) and the driver gets the torque back.
        let reduction = self
            .pid
            .step(self.slip - calibration.traction_slip_threshold);
        (demand - reduction).max(0.0).min(demand)
    }
}
