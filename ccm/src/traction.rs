//! Traction control: reduces torque when the driven wheels spin faster than the front wheels.
//!
//! slip = (rear average - front average) / front average, front speeds filtered; above 10 %
//! a PID (state kept between steps, fixed 100 Hz) removes torque. It never adds torque: the
//! result is within 0..driver torque. The integral never goes below zero, so a long stretch
//! without slip cannot store up a negative reduction that would delay the next intervention.

use crate::constants::{MIN_SLIP_SPEED_RAD_S, MOTOR_MAX_TORQUE_NM, TRACTION_SLIP};
use aer_control::{LowPass, Pid, PidGains};

/// Gains: 30 % slip over the threshold takes away about 100 Nm at once.
pub const TRACTION_GAINS: PidGains = PidGains {
    kp: 500.0,
    ki: 200.0,
    kd: 0.0,
    integral_range: (0.0, MOTOR_MAX_TORQUE_NM),
    output_range: (0.0, MOTOR_MAX_TORQUE_NM),
};

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
            pid: Pid::new(TRACTION_GAINS, period_s),
            front: LowPass::new(10.0, period_s),
            rear: LowPass::new(10.0, period_s),
            slip: 0.0,
        }
    }

    /// Slip ratio of the last step.
    pub fn slip(&self) -> f32 {
        self.slip
    }

    /// One 100 Hz step on average front and rear wheel speeds (rad/s).
    pub fn step(&mut self, front_rad_s: f32, rear_rad_s: f32, driver_torque_nm: f32) -> f32 {
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
        let reduction = self.pid.step(self.slip - TRACTION_SLIP);
        (demand - reduction).max(0.0).min(demand)
    }
}
