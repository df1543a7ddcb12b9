//! The inverter and motor: torque follows the last valid VCU1 command with a short lag, only
//! while the DC link is charged and the command says drive; the DC power it draws is the
//! shaft power over the drivetrain's efficiency.

use crate::params::powertrain::{
    COOLANT_DEGC, COOLING_PER_S, HEATING_DEGC_PER_KJ, IDLE_LOSS_W, MAX_RPM, TORQUE_RESPONSE_MS,
    VCU1_TIMEOUT_MS,
};
use aer::can::{MotorMode, Vcu1};
use aer_ccm::inverter::checksum;

/// The inverter's view of its commands and the motor's state.
#[derive(Debug, Clone, PartialEq)]
pub struct Inverter {
    /// Torque requested by the last valid VCU1 (Nm).
    pub command_nm: f32,
    /// The last valid VCU1 asked for drive mode.
    pub drive: bool,
    /// When the last valid VCU1 arrived (ms).
    pub last_vcu1_ms: Option<u32>,
    last_counter: Option<u8>,
    /// VCU1 frames refused (bad checksum or rolling counter).
    pub refused_frames: u32,
    /// Torque at the shaft (Nm).
    pub torque_nm: f32,
    /// Motor and inverter temperatures (degC).
    pub motor_degc: f32,
    /// Inverter temperature (degC).
    pub inverter_degc: f32,
}

impl Default for Inverter {
    fn default() -> Self {
        Self {
            command_nm: 0.0,
            drive: false,
            last_vcu1_ms: None,
            last_counter: None,
            refused_frames: 0,
            torque_nm: 0.0,
            motor_degc: COOLANT_DEGC,
            inverter_degc: COOLANT_DEGC,
        }
    }
}

impl Inverter {
    /// A VCU1 payload from the CCM. Refused unless its checksum is right and its rolling
    /// counter moved on, as the inverter does.
    pub fn on_vcu1(&mut self, data: &[u8; 8], now_ms: u32) {
        let Ok(vcu1) = Vcu1::decode(data) else {
            self.refused_frames += 1;
            return;
        };
        let counter_moved = self
            .last_counter
            .is_none_or(|last| last != vcu1.vcu_rolling_counter);
        if data.get(7) != Some(&checksum(data)) || !counter_moved {
            self.refused_frames += 1;
            return;
        }
        self.last_counter = Some(vcu1.vcu_rolling_counter);
        self.command_nm = vcu1.vcu_torque_req as f32;
        self.drive = vcu1.vcu_vehicle_state && vcu1.vcu_motor_mode == MotorMode::Drive;
        self.last_vcu1_ms = Some(now_ms);
    }

    /// The torque the inverter is asked for now: 0 without a recent valid VCU1 or drive.
    pub fn effective_command(&self, now_ms: u32) -> f32 {
        let recent = self
            .last_vcu1_ms
            .is_some_and(|at| now_ms.wrapping_sub(at) <= VCU1_TIMEOUT_MS);
        if recent && self.drive {
            self.command_nm
        } else {
            0.0
        }
    }

    /// Advances the motor torque by `dt_ms` towards the command (none without a live DC link
    /// or above the motor's top speed).
    pub fn step(&mut self, now_ms: u32, dc_live: bool, motor_rpm: f32, dt_ms: f32) {
        let target = if dc_live && motor_rpm < MAX_RPM {
            self.effective_command(now_ms)
        } else {
            0.0
        };
        let factor = dt_ms / (TORQUE_RESPONSE_MS + dt_ms);
        self.torque_nm += (target - self.torque_nm) * factor;
        if !dc_live {
            self.torque_nm = 0.0;
        }
    }

    /// DC power drawn (W) at `motor_rad_s` with drivetrain `efficiency`, with the idle loss
    /// while the DC link is live. Also warms motor and inverter with the losses over `dt_s`.
    pub fn dc_power_w(
        &mut self,
        motor_rad_s: f32,
        efficiency: f32,
        dc_live: bool,
        dt_s: f32,
    ) -> f32 {
        if !dc_live {
            return 0.0;
        }
        let shaft = (self.torque_nm * motor_rad_s).max(0.0);
        let power = shaft / efficiency + IDLE_LOSS_W;
        let loss_kj = (power - shaft) * dt_s / 1_000.0;
        let cool = COOLING_PER_S * dt_s;
        self.motor_degc +=
            0.6 * loss_kj * HEATING_DEGC_PER_KJ - (self.motor_degc - COOLANT_DEGC) * cool;
        self.inverter_degc +=
            0.4 * loss_kj * HEATING_DEGC_PER_KJ - (self.inverter_degc - COOLANT_DEGC) * cool;
        power
    }
}

/// Drivetrain efficiency at `motor_rpm`: `base` falling by `droop` at the top speed, kept
/// within the range the CCM is designed for.
pub fn efficiency(base: f32, droop: f32, motor_rpm: f32) -> f32 {
    let (low, high) = aer_params::DRIVETRAIN_EFFICIENCY;
    (base - droop * (motor_rpm / MAX_RPM).clamp(0.0, 1.0)).clamp(low, high)
}
