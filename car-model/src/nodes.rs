//! The other nodes' frames: the BMS, the inverter (the DTI HV-550's status packets or the
//! IFL100's MCU1-3) and the IMD, each message at its DBC cycle time, encoded with the
//! generated codec (so at the wire's resolution and range), with the measurement's own lag,
//! the BMS's delay, bus jitter, silence and garbling as injected.

use crate::faults::{Fault, FaultPlan, Node};
use crate::params::powertrain::DTI_AVAILABLE_AC_A;
use crate::rng::Rng;
use aer::can::{
    AnyMessage, DtiAcLimits, DtiControl, DtiControlMode, DtiCurrents, DtiDcLimits, DtiDriveEnable,
    DtiFaultCode, DtiFlags, DtiFocCurrents, DtiSpeed, DtiTemperatures, ImdInfoGeneral,
    ImdInfoIsolationDetail, ImdInfoItSystem, ImdInfoVoltage, Mcu1, Mcu2, Mcu3, McuMainState,
    McuWarningLevel, McuWorkMode, MotorMode, MotorRotateDirection, OrionCellVoltages, OrionLimits,
    OrionPackStatus,
};
use aer_ccm::InverterKind;
use aer_ccm::constants::{DTI_CAN_MAP_VERSION, MOTOR_POLE_PAIRS, MOTOR_TORQUE_PER_PEAK_A};
use aer_flexcan::CanFrame;
use embedded_can::Frame;

/// CAN1: BMS, PCC, IMD, CCM status and telemetry.
pub const CAN1: usize = 0;
/// CAN2: the inverter.
pub const CAN2: usize = 1;

/// What the nodes measure this millisecond.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measured {
    /// The inverter the car carries.
    pub inverter: InverterKind,
    /// The DTI's drive is enabled.
    pub drive_enabled: bool,
    /// The inverter has a fault of its own.
    pub inverter_faulted: bool,
    /// Motor speed (rpm).
    pub motor_rpm: f32,
    /// Motor torque (Nm).
    pub torque_nm: f32,
    /// The torque the inverter can deliver now (Nm).
    pub max_torque_nm: f32,
    /// The inverter is running (DC link charged).
    pub running: bool,
    /// Motor and inverter temperatures (degC).
    pub temperatures_degc: (f32, f32),
    /// DC link voltage (V) and current (A).
    pub dc: (f32, f32),
    /// Pack terminal voltage (V), current (A), SOC (0..1), hottest temperature (degC).
    pub pack: (f32, f32, f32, f32),
    /// Average cell voltage (V).
    pub cell_v: f32,
}

/// A frame waiting for its (jittered) time on the bus.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Pending {
    at_ms: u32,
    bus: usize,
    frame: CanFrame,
}

/// Frames in flight at most (about 10 ms of every node's traffic with jitter).
const PENDING: usize = 32;

/// The BMS, the inverter and the IMD.
#[derive(Debug, Clone)]
pub struct Nodes {
    jitter_ms: u32,
    lag_ms: f32,
    bms_delay: usize,
    rng: Rng,
    pending: [Option<Pending>; PENDING],
    /// MCU3's filtered DC voltage and current.
    dc_filtered: (f32, f32),
    /// The BMS's filtered voltage and current.
    pack_filtered: (f32, f32),
    /// Pack snapshots every 10 ms, newest first, for the BMS's delay.
    pack_history: [(f32, f32, f32); 4],
    counter: u8,
    /// MCU1's and MCU2's rolling counters, each advanced on every frame it sends.
    mcu_counters: (u8, u8),
    /// While the inverter is stuck: what it measured (and its DC filter) when it stuck; it
    /// repeats the frames of that moment.
    frozen: Option<(Measured, (f32, f32))>,
}

impl Nodes {
    /// Nodes with `lag_ms` measurement lag, the BMS `bms_delay` periods late, frames delayed
    /// by up to `jitter_ms`.
    pub fn new(lag_ms: f32, bms_delay: usize, jitter_ms: u32, seed: u32) -> Self {
        Self {
            jitter_ms,
            lag_ms: lag_ms.max(0.0),
            bms_delay: bms_delay.min(3),
            rng: Rng::new(seed ^ 0xB05),
            pending: [None; PENDING],
            dc_filtered: (0.0, 0.0),
            pack_filtered: (0.0, 0.0),
            pack_history: [(0.0, 0.0, 0.0); 4],
            counter: 0,
            mcu_counters: (0, 0),
            frozen: None,
        }
    }

    /// Changes the measurement lag, the BMS's delay and the jitter from now on.
    pub fn retune(&mut self, lag_ms: f32, bms_delay: usize, jitter_ms: u32) {
        self.lag_ms = lag_ms.max(0.0);
        self.bms_delay = bms_delay.min(3);
        self.jitter_ms = jitter_ms;
    }

    /// One millisecond: updates the measurements, queues the frames due now, and hands every
    /// frame whose time has come to `deliver(bus, frame)`.
    pub fn step(
        &mut self,
        now_ms: u32,
        measured: &Measured,
        plan: &FaultPlan,
        mut deliver: impl FnMut(usize, &CanFrame),
    ) {
        let factor = 1.0 / (self.lag_ms + 1.0);
        let lag = |filtered: &mut (f32, f32), (v, i): (f32, f32)| {
            filtered.0 += (v - filtered.0) * factor;
            filtered.1 += (i - filtered.1) * factor;
        };
        lag(&mut self.dc_filtered, measured.dc);
        let (pack_v, pack_i, soc, _) = measured.pack;
        lag(&mut self.pack_filtered, (pack_v, pack_i));
        if now_ms % 10 == 0 || self.pack_history == [(0.0, 0.0, 0.0); 4] {
            if self.pack_history == [(0.0, 0.0, 0.0); 4] {
                // The BMS starts with what it measures now, not with zeros.
                self.pack_filtered = (pack_v, pack_i);
                self.pack_history = [(pack_v, pack_i, soc); 4];
                self.dc_filtered = measured.dc;
            }
            self.pack_history.rotate_right(1);
            if let Some(newest) = self.pack_history.first_mut() {
                *newest = (self.pack_filtered.0, self.pack_filtered.1, soc);
            }
            self.counter = self.counter.wrapping_add(1);
        }
        let inverter_up = !plan.is_active(now_ms, Fault::InverterSilent);
        let bms_up = !plan.is_active(now_ms, Fault::BmsSilent);
        let phase = now_ms % 100;
        let stuck = plan.is_active(now_ms, Fault::InverterStuck);
        if !stuck {
            self.frozen = None;
        } else if self.frozen.is_none() {
            self.frozen = Some((*measured, self.dc_filtered));
        }
        let (seen, dc) = self.frozen.unwrap_or((*measured, self.dc_filtered));
        let inverter = if inverter_up {
            match measured.inverter {
                InverterKind::Dti => dti(&seen, dc, phase),
                InverterKind::Ifl100 => self.ifl100(&seen, dc, phase, stuck),
            }
        } else {
            None
        };
        if let Some(message) = inverter {
            self.queue(now_ms, CAN2, Node::Inverter, &message, plan);
        }
        let due = match (now_ms % 10, phase) {
            (3, _) if bms_up => Some((CAN1, Node::Bms, self.pack_status())),
            (_, 7) if bms_up => Some((CAN1, Node::Bms, limits(measured))),
            (_, 8) if bms_up => Some((CAN1, Node::Bms, cells(measured))),
            (_, 9) => Some((CAN1, Node::Imd, self.imd())),
            (_, 19) => Some((CAN1, Node::Imd, self.imd_isolation())),
            (_, 29) => Some((CAN1, Node::Imd, self.imd_voltage(measured))),
            (_, 39) => Some((CAN1, Node::Imd, self.imd_it_system())),
            _ => None,
        };
        if let Some((bus, node, message)) = due {
            self.queue(now_ms, bus, node, &message, plan);
        }
        for slot in &mut self.pending {
            if let Some(pending) = slot.filter(|pending| pending.at_ms <= now_ms) {
                deliver(pending.bus, &pending.frame);
                *slot = None;
            }
        }
    }

    /// Queues `frame` (a PCC frame, from outside) with the same jitter and garbling as the
    /// nodes' own.
    pub fn send(
        &mut self,
        now_ms: u32,
        bus: usize,
        node: Node,
        frame: &CanFrame,
        plan: &FaultPlan,
    ) {
        let mut data = [0u8; 8];
        let payload = frame.data();
        let len = payload.len().min(8);
        if let (Some(out), Some(bytes)) = (data.get_mut(..len), payload.get(..len)) {
            out.copy_from_slice(bytes);
            if plan.is_active(now_ms, Fault::GarbledFrames(node)) {
                out.iter_mut()
                    .for_each(|byte| *byte = self.rng.next_u32().to_le_bytes()[0]);
            }
        }
        let Some(frame) = data
            .get(..len)
            .and_then(|data| CanFrame::new(frame.id(), data))
        else {
            return;
        };
        let at_ms = now_ms + self.rng.below(self.jitter_ms + 1);
        let free = self.pending.iter_mut().find(|slot| slot.is_none());
        if let Some(slot) = free {
            *slot = Some(Pending { at_ms, bus, frame });
        }
    }

    fn queue(
        &mut self,
        now_ms: u32,
        bus: usize,
        node: Node,
        message: &AnyMessage,
        plan: &FaultPlan,
    ) {
        let mut data = [0u8; 8];
        let Ok(len) = message.encode(&mut data) else {
            return;
        };
        if let Some(frame) = data
            .get(..len)
            .and_then(|data| CanFrame::new(message.meta().can_id(), data))
        {
            self.send(now_ms, bus, node, &frame, plan);
        }
    }

    /// The IFL100's frame due at `phase` (ms in the 100 ms cycle): MCU1 and MCU3 every
    /// 10 ms, MCU2 every 100 ms; a `stuck` inverter's counters do not move.
    fn ifl100(
        &mut self,
        measured: &Measured,
        dc: (f32, f32),
        phase: u32,
        stuck: bool,
    ) -> Option<AnyMessage> {
        let advance = |counter: &mut u8| {
            let now = *counter;
            if !stuck {
                *counter = (*counter + 1) & 0x0F;
            }
            now
        };
        match (phase % 10, phase) {
            (1, _) => Some(mcu1(measured, advance(&mut self.mcu_counters.0))),
            (2, _) => Some(mcu3(dc)),
            (_, 5) => Some(mcu2(measured, advance(&mut self.mcu_counters.1))),
            _ => None,
        }
    }

    fn pack_status(&self) -> AnyMessage {
        let index = self.bms_delay.min(self.pack_history.len() - 1);
        let (volts, amps, soc) = self.pack_history.get(index).copied().unwrap_or_default();
        AnyMessage::OrionPackStatus(OrionPackStatus {
            orion_pack_current: quantise(amps, 0.1, -3_276.8, 3_276.7),
            orion_pack_inst_voltage: quantise(volts, 0.1, 0.0, 6_553.5),
            orion_pack_soc: quantise(soc * 100.0, 0.5, 0.0, 100.0),
            // Bit 0: discharge enabled; the charger-safety bit (2) stays clear.
            orion_relay_state: 1,
        })
    }

    /// IMD_InfoIsolationDetail: each pole's isolation, as healthy as the general figure.
    fn imd_isolation(&mut self) -> AnyMessage {
        let noise = self.rng.below(200) as u16;
        AnyMessage::ImdInfoIsolationDetail(ImdInfoIsolationDetail {
            imd_r_iso_negative: 2_500 + noise,
            imd_r_iso_positive: 2_450 + noise,
            imd_r_iso_original: 2_400 + noise,
            imd_iso_measurement_counter: self.counter,
            imd_iso_quality: 100,
        })
    }

    /// IMD_InfoVoltage: the HV system's voltage, split evenly about earth.
    fn imd_voltage(&self, measured: &Measured) -> AnyMessage {
        let (pack_v, ..) = measured.pack;
        let volts = f64::from(pack_v).clamp(0.0, 1_670.0);
        AnyMessage::ImdInfoVoltage(ImdInfoVoltage {
            imd_hv_system_voltage: volts,
            imd_hv_neg_to_earth_voltage: -volts / 2.0,
            imd_hv_pos_to_earth_voltage: volts / 2.0,
            imd_voltage_measurement_counter: self.counter,
            imd_voltage_quality: 100,
        })
    }

    /// IMD_InfoItSystem: a small, balanced Y capacitance on a DC system.
    fn imd_it_system(&self) -> AnyMessage {
        AnyMessage::ImdInfoItSystem(ImdInfoItSystem {
            imd_capacity: 150,
            imd_capacity_measurement_counter: self.counter,
            imd_unbalance: 0,
            imd_unbalance_measurement_counter: self.counter,
            imd_voltage_frequency: 0.0,
        })
    }

    fn imd(&mut self) -> AnyMessage {
        let noise = self.rng.below(200) as u16;
        AnyMessage::ImdInfoGeneral(ImdInfoGeneral {
            // A healthy isolation: a few megaohms.
            imd_r_iso_corrected: 2_400 + noise,
            imd_r_iso_status: 0,
            imd_measurement_counter: self.counter,
            imd_device_error: false,
            imd_hv_pos_connection_failure: false,
            imd_hv_neg_connection_failure: false,
            imd_earth_connection_failure: false,
            imd_iso_alarm: false,
            imd_iso_warning: false,
            imd_iso_outdated: false,
            imd_unbalance_alarm: false,
            imd_undervoltage_alarm: false,
            imd_unsafe_to_start: false,
            imd_earthlift_open: false,
            imd_device_activity: aer::can::ImdDeviceActivity::Normal,
        })
    }
}

/// MCU1: speed, torques, state.
fn mcu1(measured: &Measured, counter: u8) -> AnyMessage {
    AnyMessage::Mcu1(Mcu1 {
        mcu_motor_speed: quantise(measured.motor_rpm, 0.25, 0.0, 16_383.75),
        mcu_actual_torque: quantise(measured.torque_nm, 1.0192, 0.0, 259.896),
        mcu_max_motor_torque: quantise(measured.max_torque_nm, 1.0192, 0.0, 259.896),
        mcu_max_motor_brake_torque: 0.0,
        mcu_main_state: if measured.running {
            McuMainState::Run
        } else {
            McuMainState::Standby
        },
        mcu_rotate_direction: MotorRotateDirection::Forward,
        mcu1_rolling_counter: counter,
        mcu_motor_state: MotorMode::Drive,
        mcu_work_mode: McuWorkMode::Torque,
    })
}

fn mcu2(measured: &Measured, counter: u8) -> AnyMessage {
    let (motor, inverter) = measured.temperatures_degc;
    AnyMessage::Mcu2(Mcu2 {
        mcu_motor_temp: motor.clamp(-40.0, 215.0) as i16,
        mcu_inverter_temp: inverter.clamp(-40.0, 215.0) as i16,
        mcu_dc_main_wire_over_curr_fault: false,
        mcu_motor_phase_curr_fault: false,
        mcu_over_hot_fault: measured.inverter_faulted,
        mcu_resolver_fault: false,
        mcu_phase_curr_sensor_fault: false,
        mcu_motor_over_spd_fault: false,
        mcu_drv_motor_over_hot_fault: false,
        mcu_dc_main_wire_over_volt_fault: false,
        mcu_drv_motor_over_cool_fault: false,
        mcu_motor_system_state: false,
        mcu_temp_sensor_state: false,
        mcu_motor_temp_sensor_state: false,
        mcu_dc_volt_sensor_state: false,
        mcu_dc_low_volt_warning: false,
        mcu_12v_low_volt_warning: false,
        mcu2_rolling_counter: counter,
        mcu_warning_level: McuWarningLevel::None,
        mcu_motor_open_phase_fault: false,
        mcu_motor_stall_fault: false,
    })
}

fn mcu3((volts, amps): (f32, f32)) -> AnyMessage {
    AnyMessage::Mcu3(Mcu3 {
        mcu_dc_voltage: quantise(volts, 0.01, 0.0, 655.35),
        mcu_dc_current: quantise(amps, 0.01, -327.68, 327.67),
        mcu_phase_current: quantise(amps * 1.4, 0.01, 0.0, 655.35),
    })
}

/// The DTI's packet due at `phase` (ms in the 100 ms cycle): speed, currents and flags every
/// 10 ms, the others every 100 ms (the periods the schema declares). `dc` is its filtered DC
/// voltage and current.
fn dti(measured: &Measured, (volts, amps): (f32, f32), phase: u32) -> Option<AnyMessage> {
    let ac_a = measured.torque_nm / MOTOR_TORQUE_PER_PEAK_A;
    match (phase % 10, phase) {
        (1, _) => Some(AnyMessage::DtiSpeed(DtiSpeed {
            dti_erpm: (measured.motor_rpm * MOTOR_POLE_PAIRS) as i32,
            dti_duty_cycle: 0.0,
            dti_input_voltage: volts.clamp(0.0, 32_767.0) as i16,
        })),
        (2, _) => Some(AnyMessage::DtiCurrents(DtiCurrents {
            dti_ac_current: quantise(ac_a, 0.1, -3_276.8, 3_276.7),
            dti_dc_current: quantise(amps, 0.1, -3_276.8, 3_276.7),
        })),
        (4, _) => Some(AnyMessage::DtiFlags(dti_flags(measured))),
        (_, 5) => {
            let (motor, inverter) = measured.temperatures_degc;
            Some(AnyMessage::DtiTemperatures(DtiTemperatures {
                dti_controller_temp: quantise(inverter, 0.1, -3_276.8, 3_276.7),
                dti_motor_temp: quantise(motor, 0.1, -3_276.8, 3_276.7),
                dti_fault_code: if measured.inverter_faulted {
                    DtiFaultCode::ControllerOvertemp
                } else {
                    DtiFaultCode::None
                },
            }))
        }
        (_, 6) => Some(AnyMessage::DtiAcLimits(DtiAcLimits {
            dti_max_ac_current: f64::from(DTI_AVAILABLE_AC_A),
            dti_available_max_ac_current: f64::from(DTI_AVAILABLE_AC_A),
            dti_min_ac_current: 0.0,
            dti_available_min_ac_current: 0.0,
        })),
        (_, 16) => Some(AnyMessage::DtiDcLimits(DtiDcLimits {
            dti_max_dc_current: 300.0,
            dti_available_max_dc_current: 300.0,
            dti_min_dc_current: 0.0,
            dti_available_min_dc_current: 0.0,
        })),
        (_, 26) => Some(AnyMessage::DtiControl(DtiControl {
            dti_control_mode: DtiControlMode::Current,
            dti_target_iq: quantise(ac_a, 0.1, -3_276.8, 3_276.7),
            dti_motor_position: 0.0,
            dti_motor_still: u8::from(measured.motor_rpm.abs() < 1.0),
        })),
        (_, 36) => Some(AnyMessage::DtiFocCurrents(DtiFocCurrents {
            dti_foc_id: 0.0,
            dti_foc_iq: quantise(ac_a, 0.01, -21_474_836.48, 21_474_836.47),
        })),
        _ => None,
    }
}

/// DTI packet 0x24: drive enabled (and its limit bit while disabled), map 2.5.
fn dti_flags(measured: &Measured) -> DtiFlags {
    DtiFlags {
        dti_throttle_input: 0,
        dti_brake_input: 0,
        dti_digital_in1: false,
        dti_digital_in2: false,
        dti_digital_in3: false,
        dti_digital_in4: false,
        dti_digital_out1: false,
        dti_digital_out2: false,
        dti_digital_out3: false,
        dti_digital_out4: false,
        dti_drive_enabled: if measured.drive_enabled {
            DtiDriveEnable::Enabled
        } else {
            DtiDriveEnable::Disabled
        },
        dti_limit_capacitor_temp: false,
        dti_limit_dc_current: false,
        dti_limit_drive_enable: !measured.drive_enabled,
        dti_limit_igbt_accel_temp: false,
        dti_limit_igbt_temp: false,
        dti_limit_input_voltage: false,
        dti_limit_motor_accel_temp: false,
        dti_limit_motor_temp: false,
        dti_limit_rpm_min: false,
        dti_limit_rpm_max: false,
        dti_limit_power: false,
        dti_can_map_version: DTI_CAN_MAP_VERSION,
    }
}

fn limits(measured: &Measured) -> AnyMessage {
    let (_, _, _, temperature) = measured.pack;
    AnyMessage::OrionLimits(OrionLimits {
        orion_pack_dcl: 300,
        orion_pack_ccl: 40,
        orion_high_temperature: temperature.clamp(-128.0, 127.0) as i8,
        orion_low_temperature: (temperature - 3.0).clamp(-128.0, 127.0) as i8,
    })
}

fn cells(measured: &Measured) -> AnyMessage {
    let spread = crate::params::accumulator::CELL_SPREAD_V;
    AnyMessage::OrionCellVoltages(OrionCellVoltages {
        orion_low_cell_voltage: quantise(measured.cell_v - spread, 0.0001, 0.0, 6.5535),
        orion_high_cell_voltage: quantise(measured.cell_v + spread, 0.0001, 0.0, 6.5535),
        orion_avg_cell_voltage: quantise(measured.cell_v, 0.0001, 0.0, 6.5535),
        orion_low_cell_id: 17,
    })
}

/// `value` rounded to the wire's `step` and clamped to its range, as the node's firmware
/// would put it in the frame.
fn quantise(value: f32, step: f64, low: f64, high: f64) -> f64 {
    let value = if value.is_finite() {
        f64::from(value)
    } else {
        0.0
    };
    (nearest(value / step) * step).clamp(low, high)
}

/// The nearest integer, halves away from zero (`f64::round` needs the standard library).
fn nearest(value: f64) -> f64 {
    let shifted = if value >= 0.0 {
        value + 0.5
    } else {
        value - 0.5
    };
    (shifted as i64) as f64
}
