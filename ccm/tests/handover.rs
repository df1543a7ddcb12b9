//! The console's `bootloader` (typed, or a USB host setting 134 baud) stops every task of the
//! race image. The CCM obeys it only when no torque depends on it, and first sends the
//! inverter the commands that leave it safe: no torque, drive disabled, main relay open, no
//! current allowed. With either inverter.

mod rig;

use aer::can::{AnyMessage, DtiDriveEnable};
use aer_ccm::control::HandoverRefusal;
use aer_ccm::vehicle::State;
use rig::{INVERTERS, Rig, Tick};

#[test]
fn the_bootloader_is_refused_while_driving_or_while_torque_is_commanded() {
    for inverter in INVERTERS {
        let mut rig = Rig::with_inverter(inverter);
        rig.drive_away();
        let outputs = rig.hold(&Tick::driving(0.5, 2_000.0), 20);
        assert!(outputs.torque.torque_nm > 10.0, "{inverter:?}");
        rig.ccm.inverter_frames().expect("frames");
        assert_eq!(
            rig.ccm.handover(),
            Err(HandoverRefusal::Driving),
            "{inverter:?}"
        );
        assert_eq!(
            HandoverRefusal::Driving.to_string(),
            "the car is DRIVING: stop, press ready-to-move to leave DRIVING, then ask again"
        );

        // Ready-to-move pressed: IDLE, zero torque from this step, but the inverter still
        // holds the last command until the next command period sends zero.
        let pressed = Tick {
            rtm: true,
            ..Tick::driving(0.0, 2_000.0)
        };
        let idle = (0..30)
            .map(|_| rig.tick(&pressed))
            .find(|outputs| outputs.vehicle.state == State::Idle)
            .expect("the debounced press leaves DRIVING");
        assert_eq!(idle.torque.torque_nm, 0.0);
        let Err(HandoverRefusal::TorqueCommanded { torque_nm }) = rig.ccm.handover() else {
            panic!("{inverter:?}: torque still commanded must refuse");
        };
        assert!(torque_nm > 10.0, "{inverter:?}: {torque_nm}");

        rig.ccm.inverter_frames().expect("frames");
        let frames = rig
            .ccm
            .handover()
            .expect("idle with zero torque hands over");
        let mut checked = 0;
        for frame in frames.iter() {
            match AnyMessage::decode(frame.id, frame.extended, frame.data()).expect("decodes") {
                AnyMessage::DtiSetCurrent(current) => {
                    assert_eq!(current.dti_current_cmd, 0.0);
                    checked += 1;
                }
                AnyMessage::DtiSetDriveEnable(enable) => {
                    assert_eq!(enable.dti_drive_enable_cmd, DtiDriveEnable::Disabled);
                    checked += 1;
                }
                AnyMessage::DtiSetMaxCurrentDc(limit) => {
                    assert_eq!(limit.dti_max_current_dc_cmd, 0.0);
                    checked += 1;
                }
                AnyMessage::Vcu1(vcu1) => {
                    assert_eq!(vcu1.vcu_torque_req, 0.0);
                    assert!(!vcu1.vcu_vehicle_state, "drive disabled");
                    assert!(!vcu1.vcu_bms_main_relay_cmd, "main relay open");
                    checked += 1;
                }
                _ => {}
            }
        }
        let expected = match inverter {
            aer_ccm::InverterKind::Dti => 3,
            aer_ccm::InverterKind::Ifl100 => 1,
        };
        assert_eq!(checked, expected, "{inverter:?}");
    }
}

#[test]
fn before_precharge_the_ccm_hands_over_at_once() {
    for inverter in INVERTERS {
        let mut rig = Rig::with_inverter(inverter);
        let outputs = rig.tick(&Tick {
            pcc: Some(0),
            ..Tick::CALM
        });
        assert_ne!(outputs.vehicle.state, State::Driving);
        assert!(rig.ccm.handover().is_ok(), "{inverter:?}");
    }
}
