//! What a panic sends the inverter: the stop frames the control task publishes every period
//! (`aer_ccm::stop`), read back whole by the panic handler, for either inverter, while the car
//! drives with torque. The handler itself (register writes, the reset) is firmware; the
//! closed-loop proof that torque stops within 100 ms with the DTI's timeout disabled is
//! `car-model/tests/hardware_lies.rs`, its cost `cargo xtask m7-check`.

mod rig;

use aer::can::{AnyMessage, DtiDriveEnable, Vcu1};
use aer_ccm::stop::StopFrames;
use embedded_can::{Frame, Id};
use rig::{INVERTERS, Rig, Tick};

#[test]
fn while_torque_flows_the_published_stop_frames_disable_the_inverter() {
    for inverter in INVERTERS {
        let mut rig = Rig::with_inverter(inverter);
        rig.drive_away();
        let outputs = rig.hold(&Tick::driving(0.6, 2_000.0), 20);
        assert!(outputs.torque.torque_nm > 10.0, "{inverter:?}");
        let stop = StopFrames::new();
        assert!(stop.latest().is_empty(), "nothing before the first publish");
        stop.publish(&rig.ccm.stop_frames().expect("stop frames"));
        let frames: Vec<_> = stop.latest_frames().collect();
        let mut disabled = false;
        let mut zero_current = false;
        for frame in &frames {
            let (id, extended) = match frame.id() {
                Id::Standard(id) => (u32::from(id.as_raw()), false),
                Id::Extended(id) => (id.as_raw(), true),
            };
            match AnyMessage::decode(id, extended, frame.data()).expect("decodes") {
                AnyMessage::DtiSetDriveEnable(enable) => {
                    disabled = enable.dti_drive_enable_cmd == DtiDriveEnable::Disabled;
                }
                AnyMessage::DtiSetCurrent(current) => {
                    zero_current = current.dti_current_cmd == 0.0;
                }
                AnyMessage::Vcu1(vcu1) => {
                    disabled = !vcu1.vcu_vehicle_state;
                    zero_current = vcu1.vcu_torque_req == 0.0;
                    // A VCU1 the IFL100 takes: its checksum and a counter that moved on.
                    let mut data = [0u8; 8];
                    data.copy_from_slice(frame.data());
                    assert!(
                        Vcu1::META.verify(&mut Default::default(), &data).is_ok(),
                        "{inverter:?}: checksum"
                    );
                }
                _ => {}
            }
        }
        assert!(disabled && zero_current, "{inverter:?}: {frames:?}");
        // Building them sent nothing: the torque path goes on as before.
        let next = rig.ccm.inverter_frames().expect("the next period's frames");
        assert!(!next.is_empty());
    }
}

#[test]
fn a_publish_interrupted_by_a_panic_leaves_the_previous_copy_whole() {
    // The two-slot cell: a reader between two publishes sees one whole copy, never a mix.
    let mut rig = Rig::with_inverter(aer_ccm::InverterKind::Ifl100);
    rig.drive_away();
    let stop = StopFrames::new();
    let first = rig.ccm.stop_frames().expect("frames");
    stop.publish(&first);
    assert_eq!(stop.latest(), first);
    rig.hold(&Tick::driving(0.3, 2_000.0), 1);
    rig.ccm.inverter_frames().expect("the counter moves on");
    let second = rig.ccm.stop_frames().expect("frames");
    assert_ne!(first, second, "the IFL100's next counter");
    stop.publish(&second);
    assert_eq!(stop.latest(), second);
    assert_eq!(stop.clone().latest(), second, "a copy keeps the newest");
}
