//! The torque path: pedal -> launch or traction control -> power and SOC limits, and zero
//! whenever the vehicle may not drive.

use crate::apps::AppsReading;
use crate::config::MOTOR_MAX_TORQUE_NM;
use crate::faults::FaultMap;
use crate::launch::{LaunchControl, LaunchInputs, LaunchState};
use crate::power::PowerLimits;
use crate::traction::TractionControl;

/// Everything the torque path reads in one 100 Hz step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TorqueInputs {
    /// The pedal.
    pub apps: AppsReading,
    /// The vehicle state machine allows torque (DRIVING, sound finished, precharge done).
    pub torque_enabled: bool,
    /// Active faults.
    pub faults: FaultMap,
    /// Pack SOC (0..1), voltage (V) and current (A, positive discharging).
    pub pack: (f32, f32, f32),
    /// Front-left and front-right wheel speeds (rad/s).
    pub front_rad_s: (f32, f32),
    /// Driven wheel speed from the motor (rad/s).
    pub driven_rad_s: f32,
    /// Front brake pressure (psi).
    pub brake_psi: f32,
    /// Launch button.
    pub launch_button: bool,
}

/// The step's result.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TorqueCommand {
    /// Torque to command (Nm), 0..260.
    pub torque_nm: f32,
    /// Launch control state.
    pub launch: LaunchState,
    /// Slip the active controller saw.
    pub slip: f32,
}

/// Launch and traction control plus the limits.
#[derive(Debug, Clone)]
pub struct TorquePath {
    launch: LaunchControl,
    traction: TractionControl,
    limits: PowerLimits,
}

impl TorquePath {
    /// A torque path stepped every `period_ms`.
    pub fn new(limits: PowerLimits, period_ms: u32) -> Self {
        Self {
            launch: LaunchControl::new(period_ms),
            traction: TractionControl::new(period_ms),
            limits,
        }
    }

    /// One step.
    pub fn step(&mut self, inputs: &TorqueInputs) -> TorqueCommand {
        let may_drive = inputs.torque_enabled
            && !inputs.faults.any()
            && !inputs.apps.brake_plausibility
            && !inputs.apps.sensor_fault();
        let driver = if may_drive {
            (inputs.apps.travel * MOTOR_MAX_TORQUE_NM).clamp(0.0, MOTOR_MAX_TORQUE_NM)
        } else {
            0.0
        };
        let launch_torque = self.launch.step(&LaunchInputs {
            button: inputs.launch_button && may_drive,
            brake_psi: inputs.brake_psi,
            front_rad_s: inputs.front_rad_s,
            driven_rad_s: inputs.driven_rad_s,
            driver_torque_nm: driver,
        });
        let front_average = (inputs.front_rad_s.0 + inputs.front_rad_s.1) / 2.0;
        let traction_torque = self
            .traction
            .step(front_average, inputs.driven_rad_s, driver);
        let (controlled, slip) = if self.launch.state() == LaunchState::Active {
            (launch_torque, self.launch.slip())
        } else {
            (traction_torque, self.traction.slip())
        };
        let (soc, voltage, current) = inputs.pack;
        let limited = self.limits.limit_torque(soc, voltage, current, controlled);
        TorqueCommand {
            // Launch control may add torque, but never beyond what the driver may have.
            torque_nm: if may_drive { limited } else { 0.0 },
            launch: self.launch.state(),
            slip,
        }
    }
}
