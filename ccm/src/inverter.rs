//! Frames to the inverter through the generated codec: VCU1 (torque command, with the
//! incrementing rolling counter and checksum it checks) and the BMS1/BMS2 frames it expects
//! from a BMS, which the CCM emulates.

use aer::can::{Bms1, Bms2, GearLeverPos, KeyPosition, McuWarningLevel, MotorMode, Vcu1};
use aer::runtime::EncodeError;

/// Largest torque VCU1 can carry: 255 x 1.0192 Nm (0.392 % of 260 Nm per bit).
pub const VCU1_MAX_TORQUE_NM: f32 = 259.896;

/// What the CCM asks of the inverter this period.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DriveCommand {
    /// Torque request (Nm); clamped to 0..259.896.
    pub torque_nm: f32,
    /// DRIVING: motor mode drive, gear D, vehicle ready.
    pub drive: bool,
    /// The precharge is complete: the inverter may close its main relay.
    pub main_relay: bool,
    /// The brakes are engaged.
    pub brakes_engaged: bool,
}

/// Builds VCU1 frames; the rolling counter increments on every frame (mod 16).
#[derive(Debug, Clone, Default)]
pub struct Vcu1Builder {
    rolling_counter: u8,
}

impl Vcu1Builder {
    /// The next VCU1 message (checksum filled in) and its payload.
    pub fn next_frame(&mut self, command: &DriveCommand) -> Result<(Vcu1, [u8; 8]), EncodeError> {
        let torque = if command.torque_nm.is_finite() {
            command.torque_nm
        } else {
            0.0
        };
        let mut vcu1 = Vcu1 {
            vcu_torque_req: f64::from(torque.clamp(0.0, VCU1_MAX_TORQUE_NM)),
            vcu_motor_spd_req: 0,
            vcu_authentication_status: 0,
            vcu_change_gear_alarm: false,
            vcu_vehicle_state: command.drive,
            vcu_brake_pedal_sts: u8::from(command.brakes_engaged),
            vcu_bms_main_relay_cmd: command.main_relay,
            vcu_gear_lever_pos_sts: if command.drive {
                GearLeverPos::D
            } else {
                GearLeverPos::N
            },
            vcu_gear_lever_pos_sts_f: false,
            vcu_ac_control_cmd: false,
            vcu_work_mode: false,
            vcu_motor_mode: if command.drive {
                MotorMode::Drive
            } else {
                MotorMode::Standby
            },
            vcu_warning_level: McuWarningLevel::None,
            vcu_key_position: KeyPosition::On,
            vcu_rolling_counter: self.rolling_counter,
            vcu_bms_aux_relay_cmd: command.main_relay,
            vcu_power_reduce_req: 0,
            vcu_check_sum: 0,
        };
        let mut data = [0u8; 8];
        vcu1.encode(&mut data)?;
        vcu1.vcu_check_sum = checksum(&data);
        vcu1.encode(&mut data)?;
        self.rolling_counter = (self.rolling_counter + 1) & 0x0F;
        Ok((vcu1, data))
    }
}

/// VCU1's checksum: (sum of bytes 0..6) XOR 0xFF.
pub fn checksum(data: &[u8; 8]) -> u8 {
    data.iter()
        .take(7)
        .fold(0u8, |sum, byte| sum.wrapping_add(*byte))
        ^ 0xFF
}

/// BMS1: precharge relay feedback while precharging, "precharge finished" once online.
pub fn bms1_frame(precharging: bool, precharge_complete: bool) -> Result<[u8; 8], EncodeError> {
    let mut data = [0u8; 8];
    Bms1 {
        bms_precharge_relay_fb: precharging,
        bms_precharge_finish_sts: precharge_complete,
    }
    .encode(&mut data)?;
    Ok(data)
}

/// BMS2: the discharge current the inverter may draw, the Orion's DCL (A), clamped to what
/// the frame holds.
pub fn bms2_frame(discharge_limit_a: f32) -> Result<[u8; 8], EncodeError> {
    let limit = if discharge_limit_a.is_finite() {
        discharge_limit_a
    } else {
        0.0
    };
    let mut data = [0u8; 8];
    Bms2 {
        bms_allow_max_discharge: f64::from(limit.clamp(0.0, 6_000.0)),
    }
    .encode(&mut data)?;
    Ok(data)
}
