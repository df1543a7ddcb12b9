//! The torque path: pedal -> launch or traction control (which only take torque away) ->
//! SOC derating -> power ceiling -> the torque monitor, which alone has the last word.

use crate::apps::AppsReading;
use crate::calibration::Calibration;
use crate::constants::{GEAR_RATIO, MOTOR_MAX_TORQUE_NM, PEDAL_DEADBAND};
use crate::faults::FaultMap;
use crate::launch::{LaunchControl, LaunchInputs, LaunchState};
use crate::monitor::{EfficiencyBound, MonitorInputs, allowed_torque};
use crate::power::{PowerLimiter, PowerLimits};
use crate::traction::TractionControl;
use aer::calibration::Internals;

/// Everything the torque path reads in one 100 Hz step; bus values are `None` unless fresh.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TorqueInputs {
    /// The pedal.
    pub apps: AppsReading,
    /// The brakes are engaged.
    pub brakes_engaged: bool,
    /// The sensor sample is fresh.
    pub sensors_fresh: bool,
    /// The vehicle state machine allows torque (DRIVING, sound finished, precharge done).
    pub torque_enabled: bool,
    /// Active faults.
    pub faults: FaultMap,
    /// Pack SOC (0..1), from the BMS.
    pub soc: Option<f32>,
    /// Motor speed (rad/s), from MCU1.
    pub motor_rad_s: Option<f32>,
    /// The inverter's available torque (Nm), from MCU1.
    pub inverter_max_nm: Option<f32>,
    /// DC power into the inverter (W), from MCU3, or the BMS's pack power if that is higher.
    pub dc_power_w: Option<f32>,
    /// Shaft power (W): the torque the inverter reports times the motor speed.
    pub shaft_power_w: Option<f32>,
    /// Front-left and front-right wheel speeds (rad/s).
    pub front_rad_s: (f32, f32),
    /// Launch button.
    pub launch_button: bool,
}

/// The step's result.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TorqueCommand {
    /// Torque to command (Nm), 0..260, never above `allowed_nm`.
    pub torque_nm: f32,
    /// What the torque monitor allows (Nm).
    pub allowed_nm: f32,
    /// Launch control state.
    pub launch: LaunchState,
    /// Slip the active controller saw.
    pub slip: f32,
}

impl TorqueCommand {
    /// No torque, launch off.
    pub const ZERO: Self = Self {
        torque_nm: 0.0,
        allowed_nm: 0.0,
        launch: LaunchState::Off,
        slip: 0.0,
    };
}

/// Launch and traction control, the limits and the monitor.
#[derive(Debug, Clone)]
pub struct TorquePath {
    launch: LaunchControl,
    traction: TractionControl,
    limits: PowerLimits,
    power: PowerLimiter,
    /// The monitor's own efficiency, from the readings.
    efficiency: EfficiencyBound,
    /// The last step's intermediate values, for calibration tools.
    internals: Internals,
}

impl TorquePath {
    /// A torque path stepped every `period_ms`.
    pub fn new(limits: PowerLimits, period_ms: u32) -> Self {
        Self {
            launch: LaunchControl::new(period_ms),
            traction: TractionControl::new(period_ms),
            limits,
            power: PowerLimiter::new(period_ms, limits.power_target_w),
            efficiency: EfficiencyBound::new(period_ms),
            internals: Internals::default(),
        }
    }

    /// The last step's intermediate values (what XCP samples at the control event).
    pub fn internals(&self) -> Internals {
        self.internals
    }

    /// One step, with the `calibration` as it is now.
    pub fn step(&mut self, calibration: &Calibration, inputs: &TorqueInputs) -> TorqueCommand {
        let apps = &inputs.apps;
        let may_drive = inputs.torque_enabled
            && !inputs.faults.stops_torque()
            && !apps.brake_plausibility
            && !apps.sensor_fault()
            && !apps.signal_lost;
        let driver = if may_drive {
            torque_request(apps.travel)
        } else {
            0.0
        };
        let motor_rad_s = inputs.motor_rad_s.unwrap_or(0.0);
        let driven_rad_s = motor_rad_s / GEAR_RATIO;
        let launch_torque = self.launch.step(
            calibration,
            &LaunchInputs {
                button: inputs.launch_button && may_drive,
                brakes_engaged: inputs.brakes_engaged,
                pedal: apps.travel,
                front_rad_s: inputs.front_rad_s,
                driven_rad_s,
                driver_torque_nm: driver,
            },
        );
        let front_average = (inputs.front_rad_s.0 + inputs.front_rad_s.1) / 2.0;
        // The power bounds divide by the motor speed: they take the larger of the reported
        // one and what the front wheels prove (under drive the driven wheels turn at least as
        // fast), so a frozen or low reading cannot raise the torque they allow.
        let power_rad_s = inputs.motor_rad_s.map(|motor| {
            let proven = front_average * GEAR_RATIO;
            if proven.is_finite() {
                motor.abs().max(proven)
            } else {
                motor
            }
        });
        let traction_torque = self
            .traction
            .step(calibration, front_average, driven_rad_s, driver);
        let (controlled, slip) = if self.launch.state() == LaunchState::Active {
            (launch_torque, self.launch.slip())
        } else {
            (traction_torque, self.traction.slip())
        };
        let derated = self
            .limits
            .soc_limited(inputs.soc.unwrap_or(f32::NAN), controlled.min(driver));
        let allowed = allowed_torque(
            &MonitorInputs {
                torque_enabled: inputs.torque_enabled,
                faults: inputs.faults,
                apps: *apps,
                sensors_fresh: inputs.sensors_fresh,
                motor_rad_s: power_rad_s,
                soc: inputs.soc,
                inverter_max_nm: inputs.inverter_max_nm,
                dc_power_w: inputs.dc_power_w,
                efficiency: self.efficiency.update(
                    inputs.shaft_power_w,
                    inputs.dc_power_w,
                    &self.limits,
                ),
            },
            &self.limits,
        );
        // The limiter sees what the monitor leaves: where the monitor binds, the ceiling does
        // not, and the trim neither winds up behind it nor overshoots once it lets go.
        let power_ceiling = self.power.step(
            calibration.power_trim_gain,
            power_rad_s.unwrap_or(0.0),
            inputs.dc_power_w.unwrap_or(f32::NAN),
            derated.min(allowed),
        );
        let torque = derated.min(power_ceiling).min(allowed);
        let torque_nm = if may_drive && torque.is_finite() {
            torque.max(0.0)
        } else {
            0.0
        };
        self.internals = Internals {
            driver_torque_nm: driver,
            launch_torque_nm: launch_torque,
            launch_slip_target: self.launch.target(),
            // The launch slip target curve's input, as launch control looks it up: the slower
            // front wheel's speed at the ground.
            front_wheel_speed: inputs.front_rad_s.0.min(inputs.front_rad_s.1)
                * crate::constants::WHEEL_RADIUS_M,
            traction_torque_nm: traction_torque,
            slip_ratio: slip,
            power_allowed_nm: power_ceiling,
            power_efficiency: self.power.efficiency(),
            monitor_efficiency: self.efficiency.efficiency(),
            torque_command_nm: torque_nm,
        };
        TorqueCommand {
            torque_nm,
            allowed_nm: allowed,
            launch: self.launch.state(),
            slip,
        }
    }
}

/// The driver's torque request (Nm) for pedal `travel` (0..1): nothing within the deadband,
/// then linear up to the motor maximum at full travel.
pub fn torque_request(travel: f32) -> f32 {
    let fraction = (travel - PEDAL_DEADBAND) / (1.0 - PEDAL_DEADBAND);
    if fraction.is_nan() {
        return 0.0;
    }
    fraction.clamp(0.0, 1.0) * MOTOR_MAX_TORQUE_NM
}
