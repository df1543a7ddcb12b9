//! Each session's CAN messages in the store: the bundled session replayed through the
//! service's pipeline leaves one row per bus and message with its frames and a measured rate
//! at the schema's cycle time; frames the schema's counter, checksum or freshness limit
//! flags are summed per session across commits.

mod common;

use aer::can::{AnyMessage, Vcu1};
use aer_host::decode::FrameCheck;
use aer_raspi::store::session::{self, Metadata};
use aer_raspi::store::session_messages::{self, MessageStats};
use aer_raspi::store::{self, Row, RowData, writer};

#[test]
fn a_replayed_session_has_every_message_at_its_cycle_time() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("store.sqlite");
    let db = store::open(&path).expect("store");
    let id = session::begin(&db, &Metadata::default(), "replay", 1).expect("session");
    drop(db);
    common::record_session(&path);

    let db = store::open(&path).expect("store");
    let messages = session_messages::list(&db, id).expect("list");
    // Every periodic message of each bus (CCM_Status on both), as the schema declares them.
    for bus in ["can0", "can1"] {
        let recorded: std::collections::BTreeSet<&str> = messages
            .iter()
            .filter(|m| m.bus == bus)
            .map(|m| m.message.as_str())
            .collect();
        assert_eq!(recorded, common::session_messages_on(bus), "{bus}");
    }
    for m in &messages {
        let (measured, declared) = (m.measured_hz().unwrap(), m.declared_hz().unwrap());
        assert!(
            (measured / declared - 1.0).abs() < 1e-3,
            "{} on {}: {measured} Hz against {declared}",
            m.message,
            m.bus
        );
        assert_eq!(
            (
                m.checksum_failures,
                m.counter_repeats,
                m.counter_jumps,
                m.late_frames
            ),
            (0, 0, 0, 0),
            "{m:?}"
        );
    }
    let frames: u64 = messages.iter().map(|m| m.frames).sum();
    let stored: i64 = aer::tables::TABLES
        .iter()
        .filter(|t| t.name.starts_with("can_"))
        .map(|t| {
            db.query_row(&format!("SELECT count(*) FROM \"{}\"", t.name), [], |r| {
                r.get::<_, i64>(0)
            })
            .expect("count")
        })
        .sum();
    assert_eq!(frames, u64::try_from(stored).expect("count"));
}

fn vcu1(ts_us: u64, check: FrameCheck) -> Row {
    let meta = Vcu1::META;
    Row {
        car_id: "car1".into(),
        ts_us,
        data: RowData::Can {
            bus: "can0".into(),
            message: AnyMessage::decode(meta.id, meta.extended, &[0; 8]).expect("frame"),
            check,
        },
    }
}

#[test]
fn flagged_frames_are_summed_per_session_across_commits() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut db = store::open(&dir.path().join("store.sqlite")).expect("store");
    let first = session::begin(&db, &Metadata::default(), "live", 1).expect("session");
    let fine = FrameCheck::default();
    let bad_checksum = FrameCheck {
        checksum_failed: true,
        ..fine
    };
    let repeated_and_late = FrameCheck {
        counter_repeated: true,
        late: true,
        ..fine
    };
    let jumped = FrameCheck {
        counter_jumped: true,
        ..fine
    };
    writer::commit(
        &mut db,
        &[vcu1(1_000_000, fine), vcu1(1_020_000, bad_checksum)],
    )
    .expect("commit");
    writer::commit(
        &mut db,
        &[vcu1(1_040_000, repeated_and_late), vcu1(1_060_000, jumped)],
    )
    .expect("commit");
    // The next session starts from nothing.
    let second = session::begin(&db, &Metadata::default(), "live", 2).expect("session");
    writer::commit(&mut db, &[vcu1(2_000_000, jumped)]).expect("commit");

    let vcu1_stats = |session| -> MessageStats {
        let list = session_messages::list(&db, session).expect("list");
        assert_eq!(list.len(), 1, "{list:?}");
        list.into_iter().next().expect("one")
    };
    let stats = vcu1_stats(first);
    assert_eq!(
        stats,
        MessageStats {
            bus: "can0".into(),
            message: "VCU1".into(),
            frames: 4,
            first_us: 1_000_000,
            last_us: 1_060_000,
            checksum_failures: 1,
            counter_repeats: 1,
            counter_jumps: 1,
            late_frames: 1,
        }
    );
    // Four frames over 60 ms: 50 Hz, as VCU1's 20 ms cycle declares.
    assert!((stats.measured_hz().unwrap() - 50.0).abs() < 1e-9);
    assert_eq!(stats.declared_hz(), Some(50.0));
    let next = vcu1_stats(second);
    assert_eq!(
        (next.frames, next.counter_jumps, next.measured_hz()),
        (1, 1, None)
    );
}
