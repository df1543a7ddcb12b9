//! Behaviour of the generated codec for the car, through its typed API: the bugs of today's
//! hand-written layouts (vehicle-facts.md) cannot come back.

use aer::can::{
    AnyMessage, ImdInfoVoltage, Mcu1, Mcu2, McuMainState, MotorRotateDirection, OrionPackStatus,
    PccStatus, PrechargeState, Vcu1, VehicleState,
};
use aer::runtime::{CanMessage, DecodeError, EncodeError};
use embedded_can::{ExtendedId, Id, StandardId};

/// A minimal `embedded_can::Frame`, as a HAL would provide.
#[derive(Debug, Clone, PartialEq)]
struct TestFrame {
    id: Id,
    data: Vec<u8>,
}

impl embedded_can::Frame for TestFrame {
    fn new(id: impl Into<Id>, data: &[u8]) -> Option<Self> {
        (data.len() <= 8).then(|| Self {
            id: id.into(),
            data: data.to_vec(),
        })
    }
    fn new_remote(_id: impl Into<Id>, _dlc: usize) -> Option<Self> {
        None
    }
    fn is_extended(&self) -> bool {
        matches!(self.id, Id::Extended(_))
    }
    fn is_remote_frame(&self) -> bool {
        false
    }
    fn id(&self) -> Id {
        self.id
    }
    fn dlc(&self) -> usize {
        self.data.len()
    }
    fn data(&self) -> &[u8] {
        &self.data
    }
}

#[test]
fn inverter_torque_is_in_newton_metres_not_100x_off() {
    // Byte 2 = 100: 100 * 0.392 % of 260 Nm = 101.92 Nm.
    let mcu1 = Mcu1::decode(&[0x10, 0x00, 100, 255, 0, 0, 0, 0]).expect("decodes");
    assert!(
        (mcu1.mcu_actual_torque - 101.92).abs() < 1e-9,
        "{}",
        mcu1.mcu_actual_torque
    );
    assert!((mcu1.mcu_max_motor_torque - 259.896).abs() < 1e-9);
    // Motor speed: 0x1000 big-endian * 0.25 rpm.
    assert_eq!(mcu1.mcu_motor_speed, 1024.0);
}

#[test]
fn unknown_enum_values_decode_instead_of_panicking() {
    // Byte 5: MainState (bits 3-5) = 7, RotateDirection (bits 6-7) = 1.
    let mcu1 = Mcu1::decode(&[0, 0, 0, 0, 0, (7 << 3) | (1 << 6), 0, 0]).expect("decodes");
    assert_eq!(mcu1.mcu_main_state, McuMainState::Unknown(7));
    assert_eq!(mcu1.mcu_main_state.label(), None);
    assert_eq!(mcu1.mcu_rotate_direction, MotorRotateDirection::Forward);
    assert_eq!(mcu1.mcu_rotate_direction.label(), Some("FORWARD"));
}

#[test]
fn fault_bits_decode_to_flags_in_their_documented_places() {
    // Byte 2 bit 2 = OverHot, byte 6 bit 7 = Stall; temperatures offset by -40 degC.
    let mcu2 = Mcu2::decode(&[60, 0, 0b100, 0, 0, 0, 0x80, 0]).expect("decodes");
    assert!(mcu2.mcu_over_hot_fault);
    assert!(mcu2.mcu_motor_stall_fault);
    assert!(!mcu2.mcu_resolver_fault);
    assert_eq!(mcu2.mcu_motor_temp, 20);
    assert_eq!(mcu2.mcu_inverter_temp, -40);
}

#[test]
fn vcu1_encodes_counter_and_checksum_bytes() {
    let mut cmd = Vcu1::decode(&[0; 8]).expect("decodes");
    cmd.vcu_torque_req = 101.92;
    cmd.vcu_rolling_counter = 5;
    let mut frame = [0u8; 8];
    cmd.encode(&mut frame).expect("encodes");
    let sum = frame[..7].iter().fold(0u8, |a, b| a.wrapping_add(*b)) ^ 0xFF;
    cmd.vcu_check_sum = sum;
    cmd.encode(&mut frame).expect("encodes");
    assert_eq!(frame[0], 100, "torque byte");
    assert_eq!(frame[6] & 0x0F, 5, "rolling counter in byte 6 bits 0-3");
    assert_eq!(frame[7], sum);
    assert_eq!(Vcu1::vcu_torque_req_to_raw(101.92), Ok(100));
    let back = Vcu1::decode(&frame).expect("decodes");
    assert!((back.vcu_torque_req - 101.92).abs() <= 1.0192 / 2.0);
    assert_eq!((back.vcu_rolling_counter, back.vcu_check_sum), (5, sum));
}

#[test]
fn encoding_out_of_range_names_the_signal_and_decoding_never_refuses() {
    // SOC 255 * 0.5 = 127.5 % decodes as it is ...
    let status = OrionPackStatus::decode(&[0, 0, 0, 0, 255, 0, 0, 0]).expect("decodes");
    assert_eq!(status.orion_pack_soc, 127.5);
    // ... but is refused on encoding, naming the signal.
    let err = status.encode(&mut [0u8; 8]).expect_err("out of range");
    assert_eq!(
        err,
        EncodeError::OutOfRange {
            message: "Orion_PackStatus",
            signal: "Orion_PackSoc"
        }
    );
    assert_eq!(
        err.to_string(),
        "Orion_PackStatus.Orion_PackSoc: value out of range"
    );
}

#[test]
fn short_payloads_and_buffers_are_typed_errors() {
    assert_eq!(
        PccStatus::decode(&[3, 0, 0]),
        Err(DecodeError::TooShort {
            message: "PCC_Status",
            expected: 8,
            actual: 3
        })
    );
    let pcc = PccStatus::decode(&[3, 0x01, 0x10, 0x27, 0, 0, 0x88, 0x13]).expect("decodes");
    assert_eq!(pcc.pcc_state, PrechargeState::Online);
    assert!(pcc.pcc_error_too_fast);
    assert_eq!(pcc.pcc_accumulator_voltage, 100.0);
    assert_eq!(pcc.pcc_precharge_progress, 50.0);
    assert!(matches!(
        pcc.encode(&mut [0u8; 4]),
        Err(EncodeError::BufferTooSmall {
            needed: 8,
            actual: 4,
            ..
        })
    ));
    assert_eq!(
        AnyMessage::decode(0x7FF, false, &[0; 8]),
        Err(DecodeError::UnknownId {
            id: 0x7FF,
            extended: false
        })
    );
}

#[test]
fn embedded_can_frames_round_trip_with_standard_and_extended_ids() {
    let voltage = ImdInfoVoltage::decode(&[0x80, 0x7D, 0, 0, 0xFF, 0xFF, 1, 100]).expect("decodes");
    // Raw 32128 is 0 V: the Bender offset.
    assert_eq!(voltage.imd_hv_system_voltage, 0.0);
    let frame: TestFrame = voltage.to_frame().expect("fits a classic frame");
    assert_eq!(
        frame.id,
        Id::Extended(ExtendedId::new(0x18FF_03F4).expect("valid"))
    );
    assert_eq!(ImdInfoVoltage::from_frame(&frame), Ok(voltage));
    assert_eq!(
        AnyMessage::from_frame(&frame),
        Ok(AnyMessage::ImdInfoVoltage(voltage))
    );

    let pcc_frame = TestFrame {
        id: Id::Standard(StandardId::new(0x222).expect("valid")),
        data: vec![2, 0, 0, 0, 0, 0, 0, 0],
    };
    assert!(
        matches!(AnyMessage::from_frame(&pcc_frame), Ok(AnyMessage::PccStatus(p)) if p.pcc_state == PrechargeState::Discharge)
    );
    assert_eq!(
        ImdInfoVoltage::from_frame(&pcc_frame),
        Err(DecodeError::WrongId {
            message: "IMD_InfoVoltage",
            id: 0x222,
            extended: false
        })
    );
}

#[test]
fn constants_and_metadata_come_from_the_schema() {
    assert_eq!(Vcu1::ID, 0x101);
    assert_eq!(Vcu1::CYCLE_TIME_MS, 20);
    assert_eq!(PccStatus::CYCLE_TIME_MS, 10);
    assert_eq!(<Vcu1 as CanMessage>::META.len, 8);
    const { assert!(ImdInfoVoltage::EXTENDED) };
    let torque = Mcu1::META
        .signals
        .iter()
        .find(|s| s.name == "MCU_ActualTorque")
        .expect("signal");
    assert_eq!(torque.unit, "Nm");
    assert!(torque.comment.contains("260 Nm maximum"));
    assert_eq!(VehicleState::from_raw(4), VehicleState::Driving);
    assert_eq!(u8::from(VehicleState::Fault), 5);
    assert_ne!(aer::can::SCHEMA_FINGERPRINT, 0);
}
