//! The status frame through the generated codec: what the CCM and the Pi will decode.

use aer::can::{AnyMessage, PccStatus, PrechargeState};
use aer_flexcan::CanFrame;
use aer_pcc::measurement::Pulses;
use aer_pcc::{Inputs, Precharge, PrechargeConfig};
use embedded_can::{Frame, Id, StandardId};

fn inputs(now_ms: u32, accumulator_v: f32, tractive_v: f32) -> Inputs {
    Inputs {
        now_ms,
        accumulator_v,
        tractive_v,
        raw_v: [accumulator_v, tractive_v],
        bms_last_seen_ms: Some(now_ms),
        charger_safety: false,
        pulses: [Pulses::Live; 2],
        resistor_c: [Some(25.0); 2],
    }
}

#[test]
fn the_status_frame_is_0x222_and_decodes_to_the_controller_state() {
    let mut pcc = Precharge::new(PrechargeConfig::CAR, 0);
    pcc.step(&inputs(0, 400.0, 0.0));
    pcc.step(&inputs(200, 400.0, 123.45));
    let frame: CanFrame = pcc.status_frame().unwrap();
    assert_eq!(frame.id(), Id::Standard(StandardId::new(0x222).unwrap()));
    assert_eq!(frame.data().len(), 8);
    let AnyMessage::PccStatus(status) = AnyMessage::from_frame(&frame).unwrap() else {
        panic!("not a PCC status");
    };
    assert_eq!(status.pcc_state, PrechargeState::Precharge);
    assert!((status.pcc_accumulator_voltage - 400.0).abs() < 0.006);
    assert!((status.pcc_tractive_voltage - 123.45).abs() < 0.006);
    assert!((status.pcc_precharge_progress - 30.8625).abs() < 0.006);
    // Little-endian u16 x 0.01: 400 V = 40000 = 0x9C40.
    assert_eq!(&frame.data()[2..4], &[0x40, 0x9C]);
}

#[test]
fn error_bits_sit_where_vehicle_facts_put_them() {
    let mut pcc = Precharge::new(PrechargeConfig::CAR, 0);
    pcc.step(&inputs(0, 400.0, 0.0));
    pcc.step(&inputs(200, 400.0, 0.0));
    // The tractive system jumps to the target as precharge starts: too fast (0x01).
    pcc.step(&inputs(210, 400.0, 400.0));
    pcc.step(&inputs(230, 400.0, 400.0));
    pcc.step(&inputs(250, 400.0, 400.0));
    let frame: CanFrame = pcc.status_frame().unwrap();
    // A jump in one period did not go through the resistor: too fast (0x01 of byte 1) and,
    // above the state's four bits of byte 0, bypassed (0x10).
    assert_eq!(frame.data()[0] & 0x0F, 5, "ERROR");
    assert_eq!(frame.data()[0] & 0x10, 0x10, "bypassed");
    assert_eq!(frame.data()[1], 0x01);
    let status = PccStatus::decode(frame.data()).unwrap();
    assert_eq!(status.pcc_state, PrechargeState::Error);
    assert!(status.pcc_error_too_fast && status.pcc_error_bypassed);
}

#[test]
fn the_hardware_faults_have_bits_of_their_own() {
    // The tractive converter falls silent at 400 V: 0x20 of byte 1 latched, and bit 7 of
    // byte 0 while it gives no pulses.
    let mut pcc = Precharge::new(PrechargeConfig::CAR, 0);
    pcc.step(&inputs(0, 400.0, 400.0));
    let mut silent = inputs(10, 400.0, 0.0);
    silent.pulses[1] = Pulses::Silent {
        last_v: 400.0,
        since_ms: 100,
    };
    pcc.step(&silent);
    let frame: CanFrame = pcc.status_frame().unwrap();
    assert_eq!(frame.data()[0], 0x80 | 5);
    assert_eq!(frame.data()[1], 0x20);
    let status = PccStatus::decode(frame.data()).unwrap();
    assert!(status.pcc_error_tractive_silent && status.pcc_tractive_no_pulses);
    assert!(!status.pcc_error_accumulator_silent && !status.pcc_accumulator_no_pulses);

    // A hot resistor: bit 5 of byte 0.
    let mut pcc = Precharge::new(PrechargeConfig::CAR, 0);
    let mut hot = inputs(0, 400.0, 0.0);
    hot.resistor_c = [Some(25.0), Some(70.0)];
    pcc.step(&hot);
    let frame: CanFrame = pcc.status_frame().unwrap();
    assert_eq!(frame.data()[0], 0x20 | 5);
    assert_eq!(frame.data()[1], 0);
}

#[test]
fn the_thermal_frame_is_0x223_and_a_missing_reading_is_not_valid() {
    let mut pcc = Precharge::new(PrechargeConfig::CAR, 0);
    let mut reading = inputs(0, 400.0, 0.0);
    reading.resistor_c = [Some(31.25), None];
    pcc.step(&reading);
    let frame: CanFrame = pcc.thermal_frame().unwrap();
    assert_eq!(frame.id(), Id::Standard(StandardId::new(0x223).unwrap()));
    let AnyMessage::PccThermal(thermal) = AnyMessage::from_frame(&frame).unwrap() else {
        panic!("not PCC_Thermal");
    };
    assert!((thermal.pcc_resistor_temp1 - 31.2).abs() < 0.11);
    assert!(thermal.pcc_resistor_temp1_valid);
    assert!(!thermal.pcc_resistor_temp2_valid);
}

#[test]
fn values_beyond_the_frame_are_clamped_not_refused() {
    let mut pcc = Precharge::new(PrechargeConfig::CAR, 0);
    pcc.step(&inputs(0, 700.0, 0.0));
    let frame: CanFrame = pcc.status_frame().unwrap();
    let status = PccStatus::decode(frame.data()).unwrap();
    assert!((status.pcc_accumulator_voltage - 655.35).abs() < 1e-9);
}
