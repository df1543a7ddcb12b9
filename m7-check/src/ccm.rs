//! A CCM session in closed loop: power-up, precharge, ready-to-drive, a drive with throttle,
//! braking (with an APPS/brake plausibility event), falling SOC, rising temperatures, and the
//! PCC going away. Telemetry goes through ISO-TP to a receiver every 10 ms.

use crate::Digest;
use aer::can::{
    Mcu1, Mcu2, McuMainState, McuWarningLevel, McuWorkMode, MotorMode, MotorRotateDirection,
    OrionCellVoltages, OrionLimits, OrionPackStatus, PccStatus, PrechargeState,
};
use aer::runtime::EncodeError;
use aer::telemetry::Telemetry;
use aer_ccm::apps::AppsCalibration;
use aer_ccm::brakes::volts_for;
use aer_ccm::{Ccm, ControlOutputs, DriverInputs, SensorSample};
use aer_flexcan::CanFrame;
use aer_isotp::{Config, Received, Receiver};
use core::fmt::Write;
use embedded_can::{Frame, StandardId};

/// Session length (ms).
const DURATION_MS: u32 = 20_000;

/// The driver's script at `t` ms: pedal travel, brake psi, ready-to-move, launch button.
fn driver(t: u32) -> (f32, f32, bool, bool) {
    match t {
        0..1_500 => (0.0, 0.0, false, false),
        1_500..1_900 => (0.0, 120.0, true, false),
        1_900..4_000 => (0.0, 120.0, false, false),
        4_000..7_000 => ((t - 4_000) as f32 / 3_000.0 * 0.8, 0.0, false, false),
        7_000..8_000 => (0.3, 200.0, false, false), // brake with throttle: plausibility
        8_000..9_000 => (0.02, 0.0, false, false),  // released: plausibility resets
        9_000..14_000 => (0.6, 0.0, false, false),
        _ => (0.1, 0.0, false, false),
    }
}

/// The PCC's state at `t` ms.
fn pcc_state(t: u32) -> PrechargeState {
    match t {
        0..1_000 => PrechargeState::Precharge,
        1_000..18_000 => PrechargeState::Online,
        _ => PrechargeState::Standby,
    }
}

fn frame<M>(
    id: u32,
    message: &M,
    encode: fn(&M, &mut [u8]) -> Result<usize, EncodeError>,
) -> Option<CanFrame> {
    let mut data = [0u8; 8];
    let len = encode(message, &mut data).ok()?;
    CanFrame::new(StandardId::new(u16::try_from(id).ok()?)?, data.get(..len)?)
}

/// The simulated car around the CCM: driver, motor, pack and the other nodes' frames.
struct World {
    motor_rpm: f32,
    soc: f32,
    temperature: f32,
}

impl World {
    const fn new() -> Self {
        Self {
            motor_rpm: 0.0,
            soc: 90.0,
            temperature: 30.0,
        }
    }

    /// One millisecond: a sensor sample, and every 10 ms the buses and a control step.
    fn step(&mut self, ccm: &mut Ccm, t: u32) -> Option<ControlOutputs> {
        let calibration = AppsCalibration::DEFAULT;
        let (pedal, brake_psi, rtm, launch) = driver(t);
        let raw = |(rest, full): (f32, f32)| (rest + pedal * (full - rest)) as i16;
        ccm.sample(
            &SensorSample {
                apps_raw: (raw(calibration.apps1), raw(calibration.apps2)),
                brake_v: (volts_for(brake_psi), volts_for(brake_psi * 0.8)),
                shock_raw: [4000 - (t % 50) as u16, 4010, 4020, 4030],
            },
            t,
        );
        if t % 10 != 0 {
            return None;
        }
        let torque = ccm.last_outputs().map_or(0.0, |o| o.torque.torque_nm);
        self.motor_rpm = (self.motor_rpm + torque * 0.5 - self.motor_rpm * 0.01).max(0.0);
        self.soc = (self.soc - torque * 0.000_05).max(0.0);
        self.temperature += torque * 0.000_3;
        for frame in self.frames(t, torque).iter().flatten() {
            ccm.on_frame(frame, t);
        }
        Some(ccm.control(
            DriverInputs {
                ready_to_move: rtm,
                launch,
            },
            t,
            t * 1_000,
        ))
    }

    /// What the other nodes send at `t`: PCC and inverter every 10 ms, BMS and temperatures
    /// every 100 ms.
    fn frames(&self, t: u32, torque: f32) -> [Option<CanFrame>; 6] {
        let pcc = PccStatus {
            pcc_state: pcc_state(t),
            pcc_error_too_fast: false,
            pcc_error_too_slow: false,
            pcc_error_bms_timeout: false,
            pcc_error_shutdown: false,
            pcc_error_undefined_state: false,
            pcc_accumulator_voltage: 398.0,
            pcc_tractive_voltage: 397.0,
            pcc_precharge_progress: 99.75,
        };
        let mcu1 = Mcu1 {
            mcu_motor_speed: f64::from((self.motor_rpm * 4.0) as u32) / 4.0,
            mcu_actual_torque: f64::from((torque / 1.0192) as u8) * 1.0192,
            mcu_max_motor_torque: 259.896,
            mcu_max_motor_brake_torque: 0.0,
            mcu_main_state: McuMainState::Run,
            mcu_rotate_direction: MotorRotateDirection::Forward,
            mcu1_rolling_counter: (t / 10 % 16) as u8,
            mcu_motor_state: MotorMode::Drive,
            mcu_work_mode: McuWorkMode::Torque,
        };
        let mut frames = [
            frame(PccStatus::ID, &pcc, PccStatus::encode),
            frame(Mcu1::ID, &mcu1, Mcu1::encode),
            None,
            None,
            None,
            None,
        ];
        if t % 100 == 0 {
            let pack = OrionPackStatus {
                orion_pack_current: f64::from((torque * 2.0) as i16),
                orion_pack_inst_voltage: 398.0,
                orion_pack_soc: f64::from((self.soc * 2.0) as u8) / 2.0,
                orion_relay_state: 1,
            };
            let limits = OrionLimits {
                orion_pack_dcl: 350,
                orion_pack_ccl: 50,
                orion_high_temperature: 30,
                orion_low_temperature: 25,
            };
            let cells = OrionCellVoltages {
                orion_low_cell_voltage: 3.7,
                orion_high_cell_voltage: 3.9,
                orion_avg_cell_voltage: 3.8,
                orion_low_cell_id: 12,
            };
            let temperatures = Mcu2 {
                mcu_motor_temp: self.temperature as i16,
                mcu_inverter_temp: (self.temperature * 0.8) as i16,
                ..quiet_mcu2()
            };
            frames[2] = frame(OrionPackStatus::ID, &pack, OrionPackStatus::encode);
            frames[3] = frame(OrionLimits::ID, &limits, OrionLimits::encode);
            frames[4] = frame(OrionCellVoltages::ID, &cells, OrionCellVoltages::encode);
            frames[5] = frame(Mcu2::ID, &temperatures, Mcu2::encode);
        }
        frames
    }
}

/// A CCM driven through the session's first `until_ms` (4,500 ms: DRIVING, throttle opening).
pub fn ccm_at(until_ms: u32) -> Ccm {
    let mut ccm = Ccm::new(AppsCalibration::DEFAULT);
    let mut world = World::new();
    for t in 1..=until_ms {
        world.step(&mut ccm, t);
    }
    ccm
}

/// Runs the session and prints state and fault changes and digests.
pub fn session(out: &mut impl Write) -> core::fmt::Result {
    let mut ccm = Ccm::new(AppsCalibration::DEFAULT);
    let mut world = World::new();
    let mut receiver: Receiver<128> = Receiver::new(Config::CAR);
    let mut torque_digest = Digest::default();
    let mut frames_digest = Digest::default();
    let mut telemetry_digest = Digest::default();
    let mut packets = 0u32;
    let mut last = None;

    for t in 1..=DURATION_MS {
        let Some(outputs) = world.step(&mut ccm, t) else {
            continue;
        };
        torque_digest.bytes(&outputs.torque.torque_nm.to_le_bytes());
        if t % 20 == 0 {
            match ccm.inverter_frames() {
                Ok(frames) => frames.iter().for_each(|(id, data)| {
                    frames_digest.bytes(&id.to_le_bytes());
                    frames_digest.bytes(data);
                }),
                Err(error) => write!(frames_digest, "{error:?}")?,
            }
        }
        let now = (outputs.vehicle.state, outputs.faults.bits());
        if last != Some(now) {
            last = Some(now);
            writeln!(
                out,
                "ccm t={t} {:?} faults={:08b} torque={:.3} launch={:?}",
                outputs.vehicle.state,
                outputs.faults.bits(),
                outputs.torque.torque_nm,
                outputs.torque.launch
            )?;
        }

        // Telemetry through ISO-TP, 250 us per frame on the bus.
        let mut now_us = t * 1_000;
        ccm.send_telemetry(now_us);
        while let Some(out_frame) = ccm.link().poll(now_us) {
            ccm.link().sent(now_us);
            match receiver.on_frame(out_frame.as_slice(), now_us) {
                Ok(Received::FlowControl(reply)) => {
                    ccm.link().on_flow_control(reply.as_slice(), now_us);
                }
                Ok(Received::Message(packet)) => {
                    packets += 1;
                    telemetry_digest.bytes(packet);
                    if Telemetry::unpack(packet).is_err() {
                        writeln!(out, "ccm t={t} telemetry packet did not unpack")?;
                    }
                }
                Ok(Received::Nothing) => {}
                Err(error) => write!(telemetry_digest, "{error:?}")?,
            }
            now_us += 250;
        }
    }
    let counters = ccm.link().counters();
    writeln!(
        out,
        "ccm end torque-digest={:08x} inverter-digest={:08x} telemetry packets={packets} sent={} superseded={} failed={} digest={:08x}",
        torque_digest.value(),
        frames_digest.value(),
        counters.sent,
        counters.superseded,
        counters.failed,
        telemetry_digest.value()
    )
}

/// An MCU2 frame with no fault or warning set (fill in the temperatures).
pub fn quiet_mcu2() -> Mcu2 {
    Mcu2 {
        mcu_motor_temp: 30,
        mcu_inverter_temp: 30,
        mcu_dc_main_wire_over_curr_fault: false,
        mcu_motor_phase_curr_fault: false,
        mcu_over_hot_fault: false,
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
        mcu2_rolling_counter: 0,
        mcu_warning_level: McuWarningLevel::None,
        mcu_motor_open_phase_fault: false,
        mcu_motor_stall_fault: false,
    }
}
