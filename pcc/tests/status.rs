//! The status frame through the generated codec: what the CCM and the Pi will decode.

use aer::can::{AnyMessage, PccStatus, PrechargeState};
use aer_flexcan::CanFrame;
use aer_pcc::{Inputs, Precharge, PrechargeConfig};
use embedded_can::{Frame, Id, StandardId};

fn inputs(now_ms: u32, accumulator_v: f32, tractive_v: f32) -> Inputs {
    Inputs {
        now_ms,
        accumulator_v,
        tractive_v,
        bms_last_seen_ms: Some(now_ms),
        charger_safety: false,
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
    assert_eq!(frame.data()[0], 5, "ERROR");
    assert_eq!(frame.data()[1], 0x01);
    assert_eq!(
        PccStatus::decode(frame.data()).unwrap().pcc_state,
        PrechargeState::Error
    );
}

#[test]
fn values_beyond_the_frame_are_clamped_not_refused() {
    let mut pcc = Precharge::new(PrechargeConfig::CAR, 0);
    pcc.step(&inputs(0, 700.0, 0.0));
    let frame: CanFrame = pcc.status_frame().unwrap();
    let status = PccStatus::decode(frame.data()).unwrap();
    assert!((status.pcc_accumulator_voltage - 655.35).abs() < 1e-9);
}
