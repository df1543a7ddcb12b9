//! The inverter and motor: torque follows the last valid command with a short lag, only
//! while the DC link is charged, the command says drive and the inverter has no fault; the DC
//! power it draws is the shaft power over the drivetrain's efficiency.
//!
//! The IFL100 takes VCU1 (valid checksum, rolling counter moved on) and drops to zero torque
//! when VCU1 stops. The DTI HV-550 takes its AC current command, drive enable and DC current
//! limit; it produces current only while drive enable keeps arriving set, and drops both the
//! current and the enable when either stops (the timeouts are assumed: the DTI's CAN manual
//! chapter on them could not be read, so the bench must confirm them).

use crate::params::powertrain::{
    COOLANT_DEGC, COOLING_PER_S, DTI_COMMAND_TIMEOUT_MS, HEATING_DEGC_PER_KJ, IDLE_LOSS_W, MAX_RPM,
    TORQUE_RESPONSE_MS, VCU1_TIMEOUT_MS,
};
use aer::can::{AnyMessage, DtiDriveEnable, MotorMode, Vcu1};
use aer::runtime::{CounterCheck, IntegrityError};
use aer_ccm::InverterKind;
use aer_ccm::constants::MOTOR_TORQUE_PER_PEAK_A;

/// The inverter's view of its commands and the motor's state.
#[derive(Debug, Clone, PartialEq)]
pub struct Inverter {
    /// Which inverter this is.
    pub kind: InverterKind,
    /// Torque requested by the last valid command (Nm): VCU1's torque, or the DTI's current
    /// times the motor's torque constant.
    pub command_nm: f32,
    /// The last valid VCU1 asked for drive mode; the DTI's last drive enable said enabled.
    pub drive: bool,
    /// When the last valid torque command (VCU1, or the DTI's current) arrived (ms).
    pub last_command_ms: Option<u32>,
    /// When the DTI's last drive enable arrived (ms).
    pub last_enable_ms: Option<u32>,
    /// The DTI's DC current limit (A) from the CCM.
    pub dc_limit_a: f32,
    /// The inverter has a fault of its own (injected): it does not drive and reports it.
    pub faulted: bool,
    /// Its command timeout is off (injected): the last command holds until another comes.
    pub timeout_off: bool,
    /// The last VCU1 counter accepted.
    vcu1_counter: CounterCheck,
    /// VCU1 frames refused (bad checksum or rolling counter).
    pub refused_frames: u32,
    /// Torque at the shaft (Nm).
    pub torque_nm: f32,
    /// Motor and inverter temperatures (degC).
    pub motor_degc: f32,
    /// Inverter temperature (degC).
    pub inverter_degc: f32,
}

impl Inverter {
    /// An inverter of `kind` at power-up: no command, cold.
    pub fn new(kind: InverterKind) -> Self {
        Self {
            kind,
            command_nm: 0.0,
            drive: false,
            last_command_ms: None,
            last_enable_ms: None,
            dc_limit_a: 0.0,
            faulted: false,
            timeout_off: false,
            vcu1_counter: CounterCheck::default(),
            refused_frames: 0,
            torque_nm: 0.0,
            motor_degc: COOLANT_DEGC,
            inverter_degc: COOLANT_DEGC,
        }
    }

    /// A frame from the CCM on the inverter bus (its id and format already matched to the
    /// schema by the caller's decode). Only this inverter's own commands count.
    pub fn on_message(&mut self, message: &AnyMessage, data: &[u8; 8], now_ms: u32) {
        match (self.kind, message) {
            (InverterKind::Ifl100, AnyMessage::Vcu1(_)) => self.on_vcu1(data, now_ms),
            (InverterKind::Dti, AnyMessage::DtiSetCurrent(current)) => {
                self.command_nm = current.dti_current_cmd as f32 * MOTOR_TORQUE_PER_PEAK_A;
                self.last_command_ms = Some(now_ms);
            }
            (InverterKind::Dti, AnyMessage::DtiSetDriveEnable(enable)) => {
                self.drive = enable.dti_drive_enable_cmd == DtiDriveEnable::Enabled;
                self.last_enable_ms = Some(now_ms);
            }
            (InverterKind::Dti, AnyMessage::DtiSetMaxCurrentDc(limit)) => {
                self.dc_limit_a = limit.dti_max_current_dc_cmd as f32;
            }
            _ => {}
        }
    }

    /// The DTI's drive is enabled: the last enable said so and is recent.
    pub fn enabled(&self, now_ms: u32) -> bool {
        match self.kind {
            InverterKind::Dti => {
                self.drive
                    && !self.faulted
                    && self.last_enable_ms.is_some_and(|at| {
                        self.timeout_off || now_ms.wrapping_sub(at) <= DTI_COMMAND_TIMEOUT_MS
                    })
            }
            InverterKind::Ifl100 => self.drive && !self.faulted,
        }
    }

    /// A VCU1 payload from the CCM. Refused unless its checksum is right and its rolling
    /// counter moved on (a counter that skipped, after frames were lost, is taken), as the
    /// inverter does.
    pub fn on_vcu1(&mut self, data: &[u8; 8], now_ms: u32) {
        let Ok(vcu1) = Vcu1::decode(data) else {
            self.refused_frames += 1;
            return;
        };
        match Vcu1::META.verify(&mut self.vcu1_counter, data) {
            Ok(()) | Err(IntegrityError::CounterJumped { .. }) => {}
            Err(_) => {
                self.refused_frames += 1;
                return;
            }
        }
        self.command_nm = vcu1.vcu_torque_req as f32;
        self.drive = vcu1.vcu_vehicle_state && vcu1.vcu_motor_mode == MotorMode::Drive;
        self.last_command_ms = Some(now_ms);
    }

    /// The torque the inverter is asked for now: 0 without a recent valid command, without
    /// drive (enable), or with a fault of its own.
    pub fn effective_command(&self, now_ms: u32) -> f32 {
        let timeout = match self.kind {
            InverterKind::Dti => DTI_COMMAND_TIMEOUT_MS,
            InverterKind::Ifl100 => VCU1_TIMEOUT_MS,
        };
        let recent = self
            .last_command_ms
            .is_some_and(|at| self.timeout_off || now_ms.wrapping_sub(at) <= timeout);
        if recent && self.enabled(now_ms) {
            self.command_nm
        } else {
            0.0
        }
    }

    /// Advances the motor torque by `dt_ms` towards the command (none without a live DC link
    /// or above the motor's top speed), at most `cap_nm` (the DTI's DC current limit).
    pub fn step(&mut self, now_ms: u32, dc_live: bool, motor_rpm: f32, cap_nm: f32, dt_ms: f32) {
        let target = if dc_live && motor_rpm < MAX_RPM {
            self.effective_command(now_ms).min(cap_nm.max(0.0))
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
