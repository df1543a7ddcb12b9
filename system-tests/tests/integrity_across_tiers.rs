//! One bus, two tiers, one schema: the same frames reach the CCM's bus state and the Pi's
//! ingest. A repeated rolling counter (a stuck inverter) is refused by the CCM, which keeps
//! its last good data and lets it age into a timeout, and counted by the Pi, which keeps the
//! frame as the bus carried it; a frame with a wrong checksum is counted by the Pi the same
//! way. Both tiers judge with the generated `MessageMeta::verify`, so they cannot disagree on
//! what a bad frame is.

use aer::can::{Mcu1, Vcu1};
use aer::runtime::CounterSender;
use aer_ccm::bus::BusState;
use aer_host::decode::{FrameCheck, Ingest, Record};
use aer_host::formats::candump::LoggedFrame;
use aer_host::reports::counters::Counters;
use embedded_can::{Frame, Id, StandardId};
use std::sync::Arc;

/// MCU1 at `rpm` with the counter `sender` gives it.
fn mcu1(sender: &mut CounterSender, rpm: f64) -> [u8; 8] {
    let mut data = [0u8; 8];
    let message = Mcu1 {
        mcu_motor_speed: rpm,
        ..Mcu1::decode(&[0; 8]).expect("frame")
    };
    message.encode(&mut data).expect("in range");
    Mcu1::META.seal(sender, &mut data);
    data
}

#[test]
fn a_repeated_counter_is_refused_by_the_ccm_and_counted_by_the_pi() {
    let mut ccm = BusState::default();
    let counters = Arc::new(Counters::default());
    let mut pi = Ingest::new(counters.clone());
    let mut kept = Vec::new();
    let mut feed = |at_ms: u32, id: u32, data: &[u8; 8]| {
        let can_id = StandardId::new(u16::try_from(id).expect("standard")).expect("id");
        let frame = aer_flexcan::CanFrame::new(can_id, data).expect("frame");
        ccm.on_frame(&frame, at_ms);
        let logged = LoggedFrame::new(u64::from(at_ms) * 1_000, 0, Id::Standard(can_id), data)
            .expect("frame");
        pi.on_frame(
            &logged,
            |record| {
                if let Record::Can { check, .. } = record {
                    kept.push(check);
                }
            },
            |_, _| {},
        );
        // What the CCM now takes as the motor speed, and how many frames it refused.
        (
            ccm.mcu1
                .fresh(at_ms, Mcu1::TIMEOUT_MS)
                .map(|m| m.mcu_motor_speed),
            ccm.integrity_errors,
        )
    };

    let mut inverter = CounterSender::default();
    let first = mcu1(&mut inverter, 1_000.0);
    let second = mcu1(&mut inverter, 1_100.0);
    assert_eq!(feed(0, Mcu1::ID, &first), (Some(1_000.0), 0));
    assert_eq!(feed(10, Mcu1::ID, &second), (Some(1_100.0), 0));
    // The inverter repeats its last frame, counter and all, with a new speed: the CCM keeps
    // the last good frame (aging from 10 ms), the Pi counts the repeat and keeps the frame.
    let mut stuck = second;
    stuck[0] ^= 0x01;
    assert_eq!(feed(20, Mcu1::ID, &stuck), (Some(1_100.0), 1));
    // Repeats keep being refused, so the data goes stale after MCU1's generated limit.
    let limit = Mcu1::TIMEOUT_MS;
    assert_eq!(feed(10 + limit, Mcu1::ID, &stuck), (Some(1_100.0), 2));
    assert_eq!(feed(11 + limit, Mcu1::ID, &stuck), (None, 3));

    // VCU1 as the CCM sends it, then one with a byte flipped on the way.
    let mut ccm_side = CounterSender::default();
    let mut vcu1 = [0x10, 0, 0, 0, 0, 0, 0, 0];
    Vcu1::META.seal(&mut ccm_side, &mut vcu1);
    let mut corrupted = [0x11, 0, 0, 0, 0, 0, 0, 0];
    Vcu1::META.seal(&mut ccm_side, &mut corrupted);
    corrupted[1] ^= 0x40;
    feed(100, Vcu1::ID, &vcu1);
    feed(120, Vcu1::ID, &corrupted);

    let counts = counters.snapshot();
    assert_eq!((counts.counter_repeats, counts.checksum_failures), (3, 1));
    assert_eq!(kept.len(), 7, "the Pi keeps every frame");
    let flagged = |check: &FrameCheck| check.counter_repeated || check.checksum_failed;
    assert_eq!(kept.iter().filter(|c| flagged(c)).count(), 4);
}
