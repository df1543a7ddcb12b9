//! The BMS link: heartbeat, charger safety, and counted bad frames.

use aer::can::OrionPackStatus;
use aer_flexcan::CanFrame;
use aer_pcc::bms::BmsLink;
use embedded_can::{Frame, StandardId};

fn frame(id: u32, data: &[u8]) -> CanFrame {
    CanFrame::new(StandardId::new(id as u16).unwrap(), data).unwrap()
}

fn pack_status(relay_state: u16) -> CanFrame {
    let status = OrionPackStatus {
        orion_pack_current: 12.3,
        orion_pack_inst_voltage: 398.7,
        orion_pack_soc: 80.0,
        orion_relay_state: relay_state,
    };
    let mut data = [0; 8];
    status.encode(&mut data).unwrap();
    frame(OrionPackStatus::ID, &data)
}

#[test]
fn pack_status_frames_are_the_heartbeat_and_carry_charger_safety() {
    let mut bms = BmsLink::default();
    assert_eq!(bms.last_seen_ms(), None);
    bms.on_frame(100, &pack_status(0b0000_0001));
    assert_eq!(bms.last_seen_ms(), Some(100));
    assert!(!bms.charger_safety());
    bms.on_frame(200, &pack_status(0b0000_0101));
    assert!(bms.charger_safety());
    assert_eq!(bms.decode_errors, 0);
}

#[test]
fn other_orion_frames_keep_the_link_alive() {
    let mut bms = BmsLink::default();
    bms.on_frame(5, &frame(0x6B1, &[0; 8]));
    assert_eq!(bms.last_seen_ms(), Some(5));
    bms.on_frame(6, &frame(0x6B2, &[0; 8]));
    assert_eq!(bms.last_seen_ms(), Some(6));
}

#[test]
fn short_bms_frames_are_counted_and_not_trusted() {
    let mut bms = BmsLink::default();
    bms.on_frame(5, &frame(0x6B0, &[1, 2, 3]));
    assert_eq!(bms.decode_errors, 1);
    assert_eq!(bms.last_seen_ms(), None);
}

#[test]
fn frames_of_other_nodes_are_ignored() {
    let mut bms = BmsLink::default();
    bms.on_frame(5, &frame(0x101, &[0; 8]));
    bms.on_frame(
        5,
        &CanFrame::new(embedded_can::ExtendedId::new(0x6B0).unwrap(), &[0; 8]).unwrap(),
    );
    assert_eq!(bms.last_seen_ms(), None);
    assert_eq!(bms.decode_errors, 0);
}
