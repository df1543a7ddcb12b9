//! `cargo xtask session-log`: records a driving session of the CCM logic as a candump log, the
//! file the Pi's demo replays. Everything on the wire comes from the project's own code: the
//! CCM's control logic, its generated telemetry packer and its ISO-TP sender; the Pi's flow
//! control from the ISO-TP receiver; the other nodes' frames from the generated encoders.

use aer::can::{
    AnyMessage, Mcu1, Mcu2, Mcu3, McuMainState, McuWorkMode, MotorMode, MotorRotateDirection,
    OrionCellVoltages, OrionLimits, OrionPackStatus, PccStatus, PrechargeState,
};
use aer::telemetry::Telemetry;
use aer_ccm::apps::AppsCalibration;
use aer_ccm::brakes::volts_for;
use aer_ccm::{Ccm, DriverInputs, SensorSample};
use aer_flexcan::CanFrame;
use aer_isotp::{Config, Received, Receiver};
use aer_raspi::candump::LoggedFrame;
use anyhow::{Context, Result};
use embedded_can::{Id, StandardId};
use std::fmt::Write as _;
use std::path::Path;

/// Session start (2026-11-21 12:00:00 UTC) and length.
const START_US: u64 = 1_795_348_800_000_000;
const DURATION_MS: u32 = 45_000;
const LAP_MS: u32 = 20_000;
/// Bus names as the Pi names them: can0 = CAN1 (BMS, PCC, Pi), can1 = CAN2 (inverter).
const BUSES: [&str; 2] = ["can0", "can1"];

/// The driver over one lap (ms into the lap): throttle 0..1, brake psi.
/// A real driver is off the brake before opening the throttle (the CCM latches the APPS/brake
/// plausibility fault otherwise), hence the short coasting gaps.
fn lap(ms: u32) -> (f32, f32) {
    match ms {
        0..6_000 => (0.9, 0.0),
        6_000..7_500 => (0.0, 600.0),
        7_500..7_800 => (0.0, 0.0),
        7_800..12_000 => (0.35, 0.0),
        12_000..16_000 => (0.75, 0.0),
        16_000..17_000 => (0.0, 400.0),
        17_000..17_300 => (0.0, 0.0),
        _ => (0.5, 0.0),
    }
}

/// Driver script: start-up (button with the brake at 1.5 s, ready to drive at ~3.7 s), laps.
fn driver(t: u32) -> (f32, f32, bool) {
    match t {
        0..1_500 => (0.0, 0.0, false),
        1_500..1_900 => (0.0, 150.0, true),
        1_900..3_800 => (0.0, 150.0, false),
        3_800..4_000 => (0.0, 0.0, false),
        _ => {
            let (throttle, brake) = lap((t - 4_000) % LAP_MS);
            (throttle, brake, false)
        }
    }
}

struct Car {
    speed_rpm: f32,
    soc: f32,
    motor_temp: f32,
    inverter_temp: f32,
    pack_temp: f32,
}

/// Writes the session to `path`; returns the number of frames.
pub fn write(path: &Path) -> Result<usize> {
    let calibration = AppsCalibration::DEFAULT;
    let mut ccm = Ccm::new(calibration);
    let mut pi: Receiver<128> = Receiver::new(Config::CAR);
    let mut car = Car {
        speed_rpm: 0.0,
        soc: 92.0,
        motor_temp: 28.0,
        inverter_temp: 26.0,
        pack_temp: 27.0,
    };
    let mut log = String::new();
    let mut frames = 0usize;
    let mut put = |log: &mut String, ts_us: u64, bus: usize, id: u32, data: &[u8]| {
        let id = if id > 0x7FF {
            embedded_can::ExtendedId::new(id).map(Id::Extended)
        } else {
            StandardId::new(id as u16).map(Id::Standard)
        };
        if let Some(frame) = id.and_then(|id| LoggedFrame::new(ts_us, bus as u8, id, data)) {
            let _ = writeln!(log, "{}", frame.to_line(BUSES[bus]));
            frames += 1;
        }
    };

    for t in 1..=DURATION_MS {
        let ts = START_US + u64::from(t) * 1_000;
        let (throttle, brake, rtm) = driver(t);
        let raw = |(rest, full): (f32, f32)| (rest + throttle * (full - rest)) as i16;
        ccm.sample(
            &SensorSample {
                apps_raw: (raw(calibration.apps1), raw(calibration.apps2)),
                brake_v: (volts_for(brake), volts_for(brake * 0.85)),
                shock_raw: [4080 - (t % 37) as u16, 4075 - (t % 29) as u16, 4085, 4082],
            },
            t,
        );
        if t % 10 != 0 {
            continue;
        }
        // The car responds to the torque the CCM commands.
        let torque = ccm.last_outputs().map_or(0.0, |o| o.torque.torque_nm);
        // About 3.5 s from standstill to 5,500 rpm at full torque; quadratic drag; brakes.
        let drag = car.speed_rpm * car.speed_rpm * 4e-7 + brake * 0.06 + 0.5;
        car.speed_rpm = (car.speed_rpm + torque * 0.07 - drag).clamp(0.0, 6_500.0);
        let power_kw = torque * car.speed_rpm * std::f32::consts::TAU / 60.0 / 1_000.0;
        car.soc = (car.soc - power_kw * 0.000_06).max(0.0);
        car.motor_temp += power_kw * 0.000_35 - (car.motor_temp - 28.0) * 0.000_2;
        car.inverter_temp += power_kw * 0.000_2 - (car.inverter_temp - 26.0) * 0.000_3;
        car.pack_temp += power_kw * 0.000_1 - (car.pack_temp - 27.0) * 0.000_1;
        let pack_v = 380.0 + car.soc * 0.3 - power_kw * 0.1;
        // Within what MCU3's 16-bit x 0.01 A field holds.
        let current = (power_kw * 1_000.0 / pack_v).min(320.0);

        // Other nodes, through the generated encoders.
        let mut others: Vec<(usize, AnyMessage)> = vec![
            (
                0,
                AnyMessage::PccStatus(PccStatus {
                    pcc_state: if t < 900 {
                        PrechargeState::Precharge
                    } else {
                        PrechargeState::Online
                    },
                    pcc_error_too_fast: false,
                    pcc_error_too_slow: false,
                    pcc_error_bms_timeout: false,
                    pcc_error_shutdown: false,
                    pcc_error_undefined_state: false,
                    pcc_accumulator_voltage: f64::from((pack_v * 100.0).round() / 100.0),
                    pcc_tractive_voltage: f64::from((pack_v * 99.0).round() / 100.0),
                    pcc_precharge_progress: 99.0,
                }),
            ),
            (
                1,
                AnyMessage::Mcu1(Mcu1 {
                    mcu_motor_speed: f64::from((car.speed_rpm * 4.0).round() / 4.0),
                    mcu_actual_torque: f64::from((torque / 1.0192).round()) * 1.0192,
                    mcu_max_motor_torque: 259.896,
                    mcu_max_motor_brake_torque: 0.0,
                    mcu_main_state: McuMainState::Run,
                    mcu_rotate_direction: MotorRotateDirection::Forward,
                    mcu1_rolling_counter: (t / 10 % 16) as u8,
                    mcu_motor_state: MotorMode::Drive,
                    mcu_work_mode: McuWorkMode::Torque,
                }),
            ),
        ];
        if t % 100 == 0 {
            others.extend([
                (
                    0,
                    AnyMessage::OrionPackStatus(OrionPackStatus {
                        orion_pack_current: f64::from((current * 10.0).round() / 10.0),
                        orion_pack_inst_voltage: f64::from((pack_v * 10.0).round() / 10.0),
                        orion_pack_soc: f64::from((car.soc * 2.0).round() / 2.0),
                        orion_relay_state: 1,
                    }),
                ),
                (
                    0,
                    AnyMessage::OrionLimits(OrionLimits {
                        orion_pack_dcl: 300,
                        orion_pack_ccl: 40,
                        orion_high_temperature: car.pack_temp.round() as i8,
                        orion_low_temperature: 24,
                    }),
                ),
                (
                    0,
                    AnyMessage::OrionCellVoltages(OrionCellVoltages {
                        orion_low_cell_voltage: f64::from(
                            (pack_v / 96.0 * 1e4 - 150.0).round() / 1e4,
                        ),
                        orion_high_cell_voltage: f64::from(
                            (pack_v / 96.0 * 1e4 + 120.0).round() / 1e4,
                        ),
                        orion_avg_cell_voltage: f64::from((pack_v / 96.0 * 1e4).round() / 1e4),
                        orion_low_cell_id: 17,
                    }),
                ),
                (
                    1,
                    AnyMessage::Mcu2(Mcu2 {
                        mcu_motor_temp: car.motor_temp as i16,
                        mcu_inverter_temp: car.inverter_temp as i16,
                        ..aer_m7_check::quiet_mcu2()
                    }),
                ),
                (
                    1,
                    AnyMessage::Mcu3(Mcu3 {
                        mcu_dc_voltage: f64::from((pack_v * 100.0).round() / 100.0),
                        mcu_dc_current: f64::from((current * 100.0).round() / 100.0),
                        mcu_phase_current: f64::from((current * 140.0).round() / 100.0),
                    }),
                ),
            ]);
        }
        for (bus, message) in &others {
            let mut data = [0u8; 8];
            let len = message
                .encode(&mut data)
                .context("encoding a node's frame")?;
            put(&mut log, ts, *bus, message.meta().id, &data[..len]);
            let frame: Option<CanFrame> =
                embedded_can::Frame::new(message.meta().can_id(), &data[..len]);
            if let Some(frame) = frame {
                ccm.on_frame(&frame, t);
            }
        }

        ccm.control(
            DriverInputs {
                ready_to_move: rtm,
                launch: false,
            },
            t,
            t * 1_000,
        );
        if t % 20 == 0 {
            for (id, data) in ccm.inverter_frames().context("inverter frames")? {
                put(&mut log, ts + 100, 1, id, &data);
            }
        }
        if t % 100 == 0 {
            let mut data = [0u8; 8];
            ccm.status().encode(&mut data).context("CCM status")?;
            put(&mut log, ts + 150, 0, aer::can::CcmStatus::ID, &data);
        }

        // Telemetry: CCM sender <-> Pi receiver, 250 us per frame on the bus.
        let mut at = ts + 200;
        ccm.send_telemetry(t * 1_000);
        while let Some(frame) = ccm.link().poll((at - START_US) as u32) {
            ccm.link().sent((at - START_US) as u32);
            put(
                &mut log,
                at,
                0,
                u32::from(Telemetry::TX_ID),
                frame.as_slice(),
            );
            at += 250;
            if let Ok(Received::FlowControl(fc)) =
                pi.on_frame(frame.as_slice(), (at - START_US) as u32)
            {
                put(
                    &mut log,
                    at,
                    0,
                    u32::from(Telemetry::FLOW_CONTROL_ID),
                    fc.as_slice(),
                );
                ccm.link()
                    .on_flow_control(fc.as_slice(), (at - START_US) as u32);
                at += 250;
            }
        }
    }
    std::fs::write(path, log).with_context(|| format!("writing {}", path.display()))?;
    Ok(frames)
}
