//! Time per telemetry packet: the firmware's pack and the Pi's Deku decode of the generated
//! 62-byte layout, beside today's design (a packed struct of f32s and bytes, about 118 bytes,
//! copied field by field on the CCM and read by a Deku struct on the Pi) in the same run.

use std::hint::black_box;

use aer::telemetry::{TELEMETRY_FINGERPRINT, Telemetry, TelemetryHeader};
use aer::telemetry_deku::TelemetryFrame;
use criterion::{Criterion, criterion_group, criterion_main};
use deku::prelude::*;

/// Today's layout (vehicle-facts.md), as the current Pi parser reads it.
#[derive(Debug, Clone, PartialEq, DekuRead, DekuWrite)]
#[deku(endian = "little")]
struct TodayFrame {
    apps_travel: f32,
    bse_front: f32,
    bse_rear: f32,
    imd_resistance: f32,
    imd_status: u32,
    pack_voltage: f32,
    pack_current: f32,
    soc: f32,
    discharge_limit: f32,
    charge_limit: f32,
    low_cell_volt: f32,
    high_cell_volt: f32,
    avg_cell_volt: f32,
    motor_speed: f32,
    motor_torque: f32,
    max_motor_torque: f32,
    motor_direction: u8,
    motor_state: u8,
    mcu_main_state: u8,
    mcu_work_mode: u8,
    mcu_voltage: f32,
    mcu_phase_current: f32,
    mcu_current: f32,
    motor_temp: i32,
    mcu_temp: i32,
    mcu_warning_level: u8,
    shocktravel: [f32; 4],
    inverter_faults: [u8; 13],
    ccm_faults: u8,
}

fn snapshot() -> (TelemetryHeader, Telemetry) {
    let mut bytes = [0x5Au8; Telemetry::LEN];
    bytes[..4].copy_from_slice(&TELEMETRY_FINGERPRINT.to_le_bytes());
    Telemetry::unpack(&bytes).expect("valid packet")
}

fn today() -> TodayFrame {
    TodayFrame {
        apps_travel: 0.5,
        bse_front: 1.2,
        bse_rear: 1.1,
        imd_resistance: 1500.0,
        imd_status: 1,
        pack_voltage: 398.2,
        pack_current: 120.5,
        soc: 81.5,
        discharge_limit: 250.0,
        charge_limit: 40.0,
        low_cell_volt: 3.91,
        high_cell_volt: 3.95,
        avg_cell_volt: 3.93,
        motor_speed: 4000.0,
        motor_torque: 120.0,
        max_motor_torque: 259.9,
        motor_direction: 1,
        motor_state: 1,
        mcu_main_state: 3,
        mcu_work_mode: 1,
        mcu_voltage: 396.4,
        mcu_phase_current: 250.0,
        mcu_current: 118.0,
        motor_temp: 85,
        mcu_temp: 60,
        mcu_warning_level: 0,
        shocktravel: [30.1, 31.2, 28.3, 29.4],
        inverter_faults: [0; 13],
        ccm_faults: 0,
    }
}

fn bench(c: &mut Criterion) {
    let (header, telemetry) = snapshot();
    let mut packed = [0u8; Telemetry::LEN];
    telemetry.pack(header, &mut packed);
    let today = today();
    let today_bytes = today.to_bytes().expect("serializes");
    eprintln!(
        "packet: {} bytes generated, {} bytes today",
        Telemetry::LEN,
        today_bytes.len()
    );

    let mut group = c.benchmark_group("telemetry/pack");
    group.bench_function("generated (firmware packer)", |b| {
        let mut out = [0u8; Telemetry::LEN];
        b.iter(|| black_box(black_box(&telemetry).pack(header, &mut out)))
    });
    group.bench_function("today (f32 struct, field by field)", |b| {
        let mut out = [0u8; 128];
        b.iter(|| {
            let t = black_box(&today);
            let mut at = 0;
            let mut put = |bytes: &[u8]| {
                out[at..at + bytes.len()].copy_from_slice(bytes);
                at += bytes.len();
            };
            for v in [t.apps_travel, t.bse_front, t.bse_rear, t.imd_resistance] {
                put(&v.to_le_bytes());
            }
            put(&t.imd_status.to_le_bytes());
            for v in [
                t.pack_voltage,
                t.pack_current,
                t.soc,
                t.discharge_limit,
                t.charge_limit,
                t.low_cell_volt,
                t.high_cell_volt,
                t.avg_cell_volt,
                t.motor_speed,
                t.motor_torque,
                t.max_motor_torque,
            ] {
                put(&v.to_le_bytes());
            }
            put(&[
                t.motor_direction,
                t.motor_state,
                t.mcu_main_state,
                t.mcu_work_mode,
            ]);
            for v in [t.mcu_voltage, t.mcu_phase_current, t.mcu_current] {
                put(&v.to_le_bytes());
            }
            put(&t.motor_temp.to_le_bytes());
            put(&t.mcu_temp.to_le_bytes());
            put(&[t.mcu_warning_level]);
            for v in t.shocktravel {
                put(&v.to_le_bytes());
            }
            put(&t.inverter_faults);
            put(&[t.ccm_faults]);
            black_box(at)
        })
    });
    group.finish();

    let mut group = c.benchmark_group("telemetry/decode");
    group.bench_function("generated (Deku + fingerprint + physical values)", |b| {
        b.iter(|| {
            let frame = TelemetryFrame::decode(black_box(&packed)).expect("decodes");
            black_box(frame.to_telemetry())
        })
    });
    group.bench_function("generated (no_std unpack)", |b| {
        b.iter(|| black_box(Telemetry::unpack(black_box(&packed))))
    });
    group.bench_function("today (Deku, f32 struct)", |b| {
        b.iter(|| {
            black_box(TodayFrame::from_bytes((black_box(&today_bytes[..]), 0)).expect("decodes"))
        })
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
