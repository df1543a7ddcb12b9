//! The HIMaC bench's IFL100: VCU1 (torque command, with the incrementing rolling counter and
//! checksum it checks) and the BMS1/BMS2 frames it expects from a BMS, which the CCM emulates;
//! its status from MCU1 (speed, available torque), MCU2 (temperatures, fault bits) and MCU3
//! (DC voltage and current).

use super::{DriveCommand, InverterStatus, OutFrame, OutFrames, finite_or_zero};
use crate::bus::BusState;
use crate::constants::{MCU1_TIMEOUT_MS, MCU2_TIMEOUT_MS, MCU3_TIMEOUT_MS};
use aer::can::{Bms1, Bms2, GearLeverPos, KeyPosition, Mcu2, McuWarningLevel, MotorMode, Vcu1};
use aer::runtime::{CounterSender, EncodeError};

/// Largest torque VCU1 can carry: 255 x 1.0192 Nm (0.392 % of 260 Nm per bit).
pub const VCU1_MAX_TORQUE_NM: f32 = 259.896;

/// Builds VCU1 frames: the rolling counter (advancing on every frame) and the checksum are
/// filled as the schema declares them (`CounterStep`, `ChecksumAlgorithm`).
#[derive(Debug, Clone, Default)]
pub struct Vcu1Builder {
    counter: CounterSender,
}

impl Vcu1Builder {
    /// The next VCU1 message (as commanded; its counter and checksum are in the payload only)
    /// and its payload.
    pub fn next_frame(&mut self, command: &DriveCommand) -> Result<(Vcu1, [u8; 8]), EncodeError> {
        let torque = finite_or_zero(command.torque_nm);
        let vcu1 = Vcu1 {
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
            // The counter and checksum are the schema's to fill (`seal`).
            vcu_rolling_counter: 0,
            vcu_bms_aux_relay_cmd: command.main_relay,
            vcu_power_reduce_req: 0,
            vcu_check_sum: 0,
        };
        let mut data = [0u8; 8];
        vcu1.encode(&mut data)?;
        Vcu1::META.seal(&mut self.counter, &mut data);
        Ok((vcu1, data))
    }
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
    let limit = finite_or_zero(discharge_limit_a);
    let mut data = [0u8; 8];
    Bms2 {
        bms_allow_max_discharge: f64::from(limit.clamp(0.0, 6_000.0)),
    }
    .encode(&mut data)?;
    Ok(data)
}

/// The period's frames: VCU1 (returned too, for the telemetry mirror), BMS1 and BMS2.
pub fn frames(
    builder: &mut Vcu1Builder,
    command: &DriveCommand,
) -> Result<(Vcu1, OutFrames), EncodeError> {
    let (vcu1, vcu1_data) = builder.next_frame(command)?;
    let frame = |id: u32, data: [u8; 8]| {
        OutFrame::encoded(id, false, |out| {
            *out = data;
            Ok(8)
        })
    };
    let frames = OutFrames::new([
        Some(frame(Vcu1::ID, vcu1_data)?),
        Some(frame(
            Bms1::ID,
            bms1_frame(command.precharging, command.main_relay)?,
        )?),
        Some(frame(Bms2::ID, bms2_frame(command.discharge_limit_a)?)?),
        None,
    ]);
    Ok((vcu1, frames))
}

/// The IFL100's status from MCU1-3.
pub fn status(bus: &BusState, now_ms: u32, started_ms: u32) -> InverterStatus {
    let motor = bus.mcu1.fresh(now_ms, MCU1_TIMEOUT_MS);
    let inverter = bus.mcu2.fresh(now_ms, MCU2_TIMEOUT_MS);
    let dc_link = bus.mcu3.fresh(now_ms, MCU3_TIMEOUT_MS);
    let (fault, warning) = inverter.map_or((false, false), |mcu2| condition(&mcu2));
    InverterStatus {
        motor_rpm: motor.map(|mcu1| mcu1.mcu_motor_speed as f32),
        torque_nm: motor.map(|mcu1| mcu1.mcu_actual_torque as f32),
        phase_current_a: dc_link.map(|mcu3| mcu3.mcu_phase_current as f32),
        available_torque_nm: motor.map(|mcu1| mcu1.mcu_max_motor_torque as f32),
        dc_link: dc_link.map(|mcu3| (mcu3.mcu_dc_voltage as f32, mcu3.mcu_dc_current as f32)),
        temperatures_degc: inverter.map(|mcu2| {
            (
                f32::from(mcu2.mcu_inverter_temp),
                f32::from(mcu2.mcu_motor_temp),
            )
        }),
        fault,
        warning,
        lost: bus.mcu1.lost(now_ms, MCU1_TIMEOUT_MS, started_ms)
            || bus.mcu2.lost(now_ms, MCU2_TIMEOUT_MS, started_ms)
            || bus.mcu3.lost(now_ms, MCU3_TIMEOUT_MS, started_ms),
    }
}

/// What the inverter's MCU2 frame reports: (fault, warning).
///
/// The fault bits and warning level HIGH stop the car; the low-voltage warnings, the four
/// sensor/system state bits and levels LOW/MEDIUM are warnings. (The state bits' polarity is
/// not in the team's documentation; 1 is taken as "not normal" and only reported, since the
/// inverter protects itself against its own sensor faults.)
pub fn condition(mcu2: &Mcu2) -> (bool, bool) {
    let fault = mcu2.mcu_dc_main_wire_over_curr_fault
        || mcu2.mcu_motor_phase_curr_fault
        || mcu2.mcu_over_hot_fault
        || mcu2.mcu_resolver_fault
        || mcu2.mcu_phase_curr_sensor_fault
        || mcu2.mcu_motor_over_spd_fault
        || mcu2.mcu_drv_motor_over_hot_fault
        || mcu2.mcu_dc_main_wire_over_volt_fault
        || mcu2.mcu_drv_motor_over_cool_fault
        || mcu2.mcu_motor_stall_fault
        || mcu2.mcu_motor_open_phase_fault
        || matches!(
            mcu2.mcu_warning_level,
            McuWarningLevel::High | McuWarningLevel::Unknown(_)
        );
    let warning = mcu2.mcu_dc_low_volt_warning
        || mcu2.mcu_12v_low_volt_warning
        || mcu2.mcu_motor_system_state
        || mcu2.mcu_temp_sensor_state
        || mcu2.mcu_motor_temp_sensor_state
        || mcu2.mcu_dc_volt_sensor_state
        || matches!(
            mcu2.mcu_warning_level,
            McuWarningLevel::Low | McuWarningLevel::Medium
        );
    (fault, warning)
}
