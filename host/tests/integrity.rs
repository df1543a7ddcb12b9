//! The Pi's view of the schema's counters, checksums and freshness limits: a frame with a
//! wrong checksum, a repeated or skipped counter, or a gap longer than its message's limit is
//! counted (in the metrics and per message in the status) and still kept.

use aer::can::{Mcu1, Vcu1};
use aer::runtime::CounterSender;
use aer_host::decode::{Ingest, Record};
use aer_host::formats::candump::LoggedFrame;
use aer_host::reports::counters::{Counters, MessageHealth};
use embedded_can::{Id, StandardId};
use std::sync::Arc;

fn frame(ts_ms: u64, id: u32, data: &[u8; 8]) -> LoggedFrame {
    let id = Id::Standard(StandardId::new(id as u16).unwrap());
    LoggedFrame::new(ts_ms * 1_000, 0, id, data).unwrap()
}

#[test]
fn bad_checksums_repeats_skips_and_late_frames_are_counted_per_message_and_kept() {
    let counters = Arc::new(Counters::default());
    let mut ingest = Ingest::new(counters.clone());
    let mut kept = 0;
    let mut feed = |ingest: &mut Ingest, f: &LoggedFrame| {
        ingest.on_frame(
            f,
            |record| kept += usize::from(matches!(record, Record::Can { .. })),
            |_, _| {},
        );
    };
    // VCU1 every 20 ms, sealed as the CCM sends it.
    let mut sender = CounterSender::default();
    let mut sealed = |torque: u8| {
        let mut data = [torque, 0, 0, 0, 0, 0, 0, 0];
        Vcu1::META.seal(&mut sender, &mut data);
        data
    };
    let first = sealed(1);
    let second = sealed(2);
    let _lost = sealed(3);
    let fourth = sealed(4);
    let mut corrupted = sealed(5);
    corrupted[0] ^= 0x10;
    feed(&mut ingest, &frame(0, Vcu1::ID, &first));
    feed(&mut ingest, &frame(20, Vcu1::ID, &second));
    feed(&mut ingest, &frame(40, Vcu1::ID, &second)); // repeated
    feed(&mut ingest, &frame(60, Vcu1::ID, &fourth)); // skipped one
    feed(&mut ingest, &frame(80, Vcu1::ID, &corrupted)); // bad checksum
    // MCU1 (limit 50 ms): a 200 ms gap is late.
    let mut mcu1 = CounterSender::default();
    for at in [0, 10, 210] {
        let mut data = [0u8; 8];
        Mcu1::META.seal(&mut mcu1, &mut data);
        feed(&mut ingest, &frame(at, Mcu1::ID, &data));
    }
    let snapshot = counters.snapshot();
    assert_eq!(
        (
            snapshot.checksum_failures,
            snapshot.counter_repeats,
            snapshot.counter_jumps,
            snapshot.late_frames
        ),
        (1, 1, 1, 1)
    );
    assert_eq!(kept, 8, "every frame is still a record");
    let status = aer_host::reports::status::status("car1", &counters, Default::default());
    assert_eq!(
        status.message_health.get("VCU1"),
        Some(&MessageHealth {
            checksum_failures: 1,
            counter_repeats: 1,
            counter_jumps: 1,
            late_frames: 0,
        })
    );
    assert_eq!(
        status.message_health.get("MCU1").map(|h| h.late_frames),
        Some(1)
    );
    // A healthy message is not listed.
    assert_eq!(
        status.message_health.len(),
        2,
        "{:?}",
        status.message_health
    );
}
