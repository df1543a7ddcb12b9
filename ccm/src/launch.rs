//! Launch control: slip-ratio control on the driven wheels for standing starts.
//!
//! The team's design, with the defects its documentation lists fixed (the PID keeps its state
//! between steps and runs at a fixed 100 Hz; activation needs the launch button, not just a
//! held brake) and two safety changes over its test plan:
//! - launch control only takes torque away from the driver's request, never adds to it
//!   (the plan's case 4 adds torque up to 260 Nm when slip is below the target; with the
//!   pedal released that kept pushing the car);
//! - an active launch ends when the pedal drops below 5 % or the brakes are engaged (the plan
//!   ends it on the brake only).
//!
//! Slip = (driven - free rolling) / free rolling, with the slower front wheel as the
//! free-rolling reference. The calibration sets the slip target over the front wheels' speed
//! (7 % by default) and the band around it (5-10 %): above the band torque is taken away,
//! aiming at the target; inside the band the reduction holds; below it the reduction bleeds
//! off back to the driver's request. The calibration's gains apply from the next step.

use crate::calibration::Calibration;
use crate::constants::{MIN_SLIP_SPEED_RAD_S, MOTOR_MAX_TORQUE_NM, PEDAL_RELEASED, WHEEL_RADIUS_M};
use aer_control::{Pid, PidGains};

/// Where the launch sequence is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LaunchState {
    /// Torque passes through unchanged.
    Off,
    /// Button pressed while stopped with the brakes engaged: ready, torque passes through.
    Armed,
    /// Brakes released and the pedal pressed: slip control active.
    Active,
}

/// What launch control reads each step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LaunchInputs {
    /// The launch button.
    pub button: bool,
    /// The brakes are engaged (the brake light's threshold).
    pub brakes_engaged: bool,
    /// Pedal travel 0..1.
    pub pedal: f32,
    /// Front-left and front-right wheel speeds (rad/s).
    pub front_rad_s: (f32, f32),
    /// Driven (rear) wheel speed, from the motor speed and gear ratio (rad/s).
    pub driven_rad_s: f32,
    /// The driver's torque request (Nm).
    pub driver_torque_nm: f32,
}

/// The motor counts as stopped below this (rad/s).
pub const STOPPED_RAD_S: f32 = 0.5;

/// The torque reduction's gains with the calibration's `kp` and `ki` (at the defaults, 30 %
/// slip above the target takes away about 60 Nm at once).
const fn gains(kp: f32, ki: f32) -> PidGains {
    PidGains {
        kp,
        ki,
        kd: 0.0,
        integral_range: (0.0, 60.0),
        output_range: (0.0, MOTOR_MAX_TORQUE_NM),
    }
}

/// Launch control.
#[derive(Debug, Clone)]
pub struct LaunchControl {
    state: LaunchState,
    reduction: Pid,
    slip: f32,
    target: f32,
}

impl LaunchControl {
    /// Off, with the controller stepped every `period_ms`.
    pub fn new(period_ms: u32) -> Self {
        Self {
            state: LaunchState::Off,
            reduction: Pid::new(
                gains(
                    Calibration::DEFAULT.launch_kp,
                    Calibration::DEFAULT.launch_ki,
                ),
                period_ms as f32 / 1_000.0,
            ),
            slip: 0.0,
            target: 0.0,
        }
    }

    /// Current state.
    pub fn state(&self) -> LaunchState {
        self.state
    }

    /// Slip ratio of the last active step.
    pub fn slip(&self) -> f32 {
        self.slip
    }

    /// The slip target of the last active step (from the calibration's curve at the speed
    /// then), 0 before the first.
    pub fn target(&self) -> f32 {
        self.target
    }

    /// One 100 Hz step: the torque to command, never above the driver's request, with the
    /// `calibration`'s slip target, band and gains as they are now.
    pub fn step(&mut self, calibration: &Calibration, inputs: &LaunchInputs) -> f32 {
        let driver = inputs.driver_torque_nm.clamp(0.0, MOTOR_MAX_TORQUE_NM);
        let stopped = inputs.driven_rad_s.abs() < STOPPED_RAD_S;
        let released = inputs.pedal.is_nan() || inputs.pedal < PEDAL_RELEASED;
        match self.state {
            LaunchState::Off => {
                if inputs.button && stopped && inputs.brakes_engaged {
                    self.state = LaunchState::Armed;
                }
                driver
            }
            LaunchState::Armed => {
                if !inputs.brakes_engaged && !released {
                    self.state = LaunchState::Active;
                    self.reduction.reset();
                    return self.active(calibration, inputs, driver);
                }
                if !stopped {
                    // Rolled away without launching.
                    self.state = LaunchState::Off;
                }
                driver
            }
            LaunchState::Active => {
                if inputs.brakes_engaged || released {
                    self.state = LaunchState::Off;
                    self.reduction.reset();
                    return driver;
                }
                self.active(calibration, inputs, driver)
            }
        }
    }

    fn active(&mut self, calibration: &Calibration, inputs: &LaunchInputs, driver: f32) -> f32 {
        let free = inputs.front_rad_s.0.min(inputs.front_rad_s.1);
        if free.is_nan() || free < MIN_SLIP_SPEED_RAD_S {
            // Rolling off the line: slip is not defined yet, pass the driver's torque.
            self.slip = 0.0;
            return driver;
        }
        self.slip = (inputs.driven_rad_s - free) / free;
        let target = calibration.launch_slip_target_at(free * WHEEL_RADIUS_M);
        self.target = target;
        let [below, above] = calibration.launch_slip_band;
        self.reduction
            .set_gains(gains(calibration.launch_kp, calibration.launch_ki));
        // Inside the band the reduction holds; outside it the error moves it.
        let error = self.slip - target;
        let error = if (-below..=above).contains(&error) {
            0.0
        } else {
            error
        };
        let reduction = self.reduction.step(error);
        (driver - reduction).clamp(0.0, driver)
    }
}
