//! The comp car's DTI HV-550 (CAN map 2.5, extended ids carrying its node id).
//!
//! Commands, every 10 ms: the AC current for the torque request (torque over the motor's
//! torque constant: an absolute current means the same torque whatever maximum current the
//! DTI is configured with, where a relative current would scale with that setting), drive
//! enable (1 only while torque is enabled in DRIVING; the DTI needs it repeated), the DC
//! current limit (the BMS's fresh discharge limit, else 0) and the DC brake current limit (0:
//! the CCM does not regenerate). Status: speed and DC voltage (0x20), currents (0x21),
//! temperatures and the fault code (0x22), drive enabled, limits and the CAN map version
//! (0x24), and the available AC current (0x25).

use super::{DriveCommand, InverterStatus, OutFrame, OutFrames, finite_or_zero};
use crate::bus::BusState;
use crate::constants::{
    DTI_AC_LIMITS_TIMEOUT_MS, DTI_CAN_MAP_VERSION, DTI_CURRENTS_TIMEOUT_MS, DTI_ENABLE_MISMATCH_MS,
    DTI_FLAGS_TIMEOUT_MS, DTI_SPEED_TIMEOUT_MS, DTI_TEMPERATURES_TIMEOUT_MS, MOTOR_MAX_TORQUE_NM,
    MOTOR_POLE_PAIRS, MOTOR_TORQUE_PER_PEAK_A,
};
use aer::can::{
    DtiDriveEnable, DtiFaultCode, DtiFlags, DtiSetCurrent, DtiSetDriveEnable,
    DtiSetMaxBrakeCurrentDc, DtiSetMaxCurrentDc,
};
use aer::runtime::EncodeError;
use aer_control::Persist;

/// The largest current the CCM commands (A, peak AC): the motor's maximum torque.
pub const MAX_CURRENT_A: f32 = MOTOR_MAX_TORQUE_NM / MOTOR_TORQUE_PER_PEAK_A;
/// The largest DC current limit a frame carries (A).
const MAX_DC_LIMIT_A: f32 = 3_276.7;

/// The AC current (A, peak) for a torque request: 0 unless the command allows driving.
pub fn current_for(command: &DriveCommand) -> f32 {
    if !command.drive {
        return 0.0;
    }
    (finite_or_zero(command.torque_nm) / MOTOR_TORQUE_PER_PEAK_A).clamp(0.0, MAX_CURRENT_A)
}

/// The period's frames: current (returned too, for the telemetry mirror), drive enable, DC
/// current limit and DC brake current limit.
pub fn frames(command: &DriveCommand) -> Result<(DtiSetCurrent, OutFrames), EncodeError> {
    let current = DtiSetCurrent {
        dti_current_cmd: f64::from(current_for(command)),
    };
    let enable = DtiSetDriveEnable {
        dti_drive_enable_cmd: if command.drive {
            DtiDriveEnable::Enabled
        } else {
            DtiDriveEnable::Disabled
        },
    };
    let dc_limit = DtiSetMaxCurrentDc {
        dti_max_current_dc_cmd: f64::from(
            finite_or_zero(command.discharge_limit_a).clamp(0.0, MAX_DC_LIMIT_A),
        ),
    };
    let brake_limit = DtiSetMaxBrakeCurrentDc {
        dti_max_brake_current_dc_cmd: 0.0,
    };
    let frames = OutFrames::new([
        Some(OutFrame::encoded(DtiSetCurrent::ID, true, |out| {
            current.encode(out)
        })?),
        Some(OutFrame::encoded(DtiSetDriveEnable::ID, true, |out| {
            enable.encode(out)
        })?),
        Some(OutFrame::encoded(DtiSetMaxCurrentDc::ID, true, |out| {
            dc_limit.encode(out)
        })?),
        Some(OutFrame::encoded(
            DtiSetMaxBrakeCurrentDc::ID,
            true,
            |out| brake_limit.encode(out),
        )?),
    ]);
    Ok((current, frames))
}

/// The DTI's status from its packets 0x20, 0x21, 0x22, 0x24 and 0x25.
pub fn status(bus: &BusState, now_ms: u32, started_ms: u32) -> InverterStatus {
    let speed = bus.dti_speed.fresh(now_ms, DTI_SPEED_TIMEOUT_MS);
    let currents = bus.dti_currents.fresh(now_ms, DTI_CURRENTS_TIMEOUT_MS);
    let temperatures = bus
        .dti_temperatures
        .fresh(now_ms, DTI_TEMPERATURES_TIMEOUT_MS);
    let flags = bus.dti_flags.fresh(now_ms, DTI_FLAGS_TIMEOUT_MS);
    let ac_limits = bus.dti_ac_limits.fresh(now_ms, DTI_AC_LIMITS_TIMEOUT_MS);
    let faulted = temperatures.is_some_and(|t| t.dti_fault_code != DtiFaultCode::None);
    let wrong_map = flags.is_some_and(|flags| flags.dti_can_map_version != DTI_CAN_MAP_VERSION);
    InverterStatus {
        motor_rpm: speed.map(|speed| speed.dti_erpm as f32 / MOTOR_POLE_PAIRS),
        torque_nm: currents
            .map(|currents| currents.dti_ac_current as f32 * MOTOR_TORQUE_PER_PEAK_A),
        phase_current_a: currents.map(|currents| currents.dti_ac_current as f32),
        available_torque_nm: ac_limits.map(|limits| {
            (limits.dti_available_max_ac_current as f32 * MOTOR_TORQUE_PER_PEAK_A).max(0.0)
        }),
        dc_link: speed.zip(currents).map(|(speed, currents)| {
            (
                f32::from(speed.dti_input_voltage),
                currents.dti_dc_current as f32,
            )
        }),
        temperatures_degc: temperatures
            .map(|t| (t.dti_controller_temp as f32, t.dti_motor_temp as f32)),
        fault: faulted || wrong_map,
        warning: flags.is_some_and(|flags| limited(&flags)),
        lost: bus.dti_speed.lost(now_ms, DTI_SPEED_TIMEOUT_MS, started_ms)
            || bus
                .dti_currents
                .lost(now_ms, DTI_CURRENTS_TIMEOUT_MS, started_ms)
            || bus
                .dti_temperatures
                .lost(now_ms, DTI_TEMPERATURES_TIMEOUT_MS, started_ms)
            || bus.dti_flags.lost(now_ms, DTI_FLAGS_TIMEOUT_MS, started_ms)
            || bus
                .dti_ac_limits
                .lost(now_ms, DTI_AC_LIMITS_TIMEOUT_MS, started_ms),
    }
}

/// A "limit active" bit: the DTI reduces its current. The drive-enable limit is left out: it is
/// set whenever the drive is disabled, which outside DRIVING is what the CCM asks for.
fn limited(flags: &DtiFlags) -> bool {
    flags.dti_limit_capacitor_temp
        || flags.dti_limit_dc_current
        || flags.dti_limit_igbt_accel_temp
        || flags.dti_limit_igbt_temp
        || flags.dti_limit_input_voltage
        || flags.dti_limit_motor_accel_temp
        || flags.dti_limit_motor_temp
        || flags.dti_limit_rpm_min
        || flags.dti_limit_rpm_max
        || flags.dti_limit_power
}

/// Watches that the DTI is disabled when the CCM disables it: a DTI that reports its drive
/// enabled for longer than [`DTI_ENABLE_MISMATCH_MS`] while the CCM sends "disabled" is not
/// obeying its commands (an inverter fault). Enabled where the CCM asked for it and disabled
/// where the CCM enabled it are both safe and not watched.
#[derive(Debug, Clone, Default)]
pub struct EnableWatch {
    disobeying: Persist,
}

impl EnableWatch {
    /// True once the DTI has reported "enabled" against the CCM's "disabled" for too long.
    /// `commanded` is the enable the CCM sends; `flags` the DTI's fresh packet 0x24.
    pub fn disobeyed(&mut self, commanded: bool, flags: Option<&DtiFlags>, now_ms: u32) -> bool {
        let enabled =
            flags.is_some_and(|flags| flags.dti_drive_enabled != DtiDriveEnable::Disabled);
        self.disobeying
            .update(enabled && !commanded, now_ms)
            .is_some_and(|held| held > DTI_ENABLE_MISMATCH_MS)
    }
}
