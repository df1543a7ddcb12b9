//! Faults on the way in: every kind is counted, logged, and the pipeline goes on. Plus the
//! start-up error for an unwritable store, and the forwarder's behaviour without TDengine.

mod common;

use aer::telemetry::Telemetry;
use aer_host::formats::candump::LoggedFrame;
use aer_host::reports::counters::{Counters, ServiceCounters};
use aer_raspi::config::TdengineConfig;
use aer_raspi::forward;
use aer_raspi::forward::{advance, next_batch};
use aer_raspi::ingest::Stage;
use aer_raspi::sink::Sink;
use aer_raspi::sink::store::StoreSink;
use aer_raspi::source::{Input, Replies};
use aer_raspi::store;
use std::sync::Arc;
use std::time::Duration;
use tokio_util::sync::CancellationToken;

/// A stage that stores everything it decodes through `writer`.
fn storing(counters: &Arc<Counters>, writer: &store::StoreWriter) -> Stage {
    let sinks: Vec<Box<dyn Sink>> = writer
        .sender()
        .map(|rows| Box::new(StoreSink::new(rows, "car1")) as Box<dyn Sink>)
        .into_iter()
        .collect();
    Stage::new(counters.clone(), sinks, Replies::default())
}

const SESSION: &str = include_str!("../data/session.log");

/// The session's first `packets` telemetry packets (and everything between), as lines.
fn session_lines(packets: usize) -> Vec<String> {
    let mut lines = Vec::new();
    let mut firsts = 0;
    for line in SESSION.lines() {
        if line.contains(" 666#1") {
            firsts += 1;
            if firsts > packets {
                break;
            }
        }
        lines.push(line.to_owned());
    }
    lines
}

async fn run(lines: &[String]) -> (ServiceCounters, u64) {
    let counters = Arc::new(Counters::default());
    let dir = tempfile::tempdir().expect("temp dir");
    let writer = store::StoreWriter::start(
        store::open(&dir.path().join("s.sqlite")).expect("store"),
        counters.clone(),
    );
    let stage = storing(&counters, &writer);
    let text = lines.join("\n");
    let (stage, stats) = stage.replay_all(text.as_bytes(), &counters).await;
    drop(stage);
    writer.finish();
    (counters.snapshot(), stats.bad_lines)
}

#[tokio::test]
async fn a_clean_log_has_no_errors() {
    let (snapshot, bad) = run(&session_lines(20)).await;
    assert_eq!(snapshot.packets, 20);
    assert_eq!(bad, 0);
    assert_eq!(
        snapshot.isotp_errors + snapshot.decode_errors + snapshot.unknown_ids,
        0
    );
}

#[tokio::test]
async fn every_fault_is_counted_and_the_rest_still_decodes() {
    let mut lines = session_lines(20);
    // Indices of the consecutive frames of the 3rd, 5th and 7th packets.
    let telemetry_frames: Vec<usize> = lines
        .iter()
        .enumerate()
        .filter(|(_, l)| l.contains(" 666#2"))
        .map(|(i, _)| i)
        .collect();
    let per_packet = (Telemetry::LEN - 6).div_ceil(7);
    let third_packet_cf = telemetry_frames[2 * per_packet + 3];
    let fifth_packet_cf = telemetry_frames[4 * per_packet + 5];
    // 1. a lost consecutive frame (3rd packet), 2. a repeated one (5th packet).
    let repeated = lines[fifth_packet_cf].clone();
    lines.insert(fifth_packet_cf, repeated);
    lines.remove(third_packet_cf);
    // 3. truncated and garbage lines, 4. an unknown id, 5. a known id with a short payload.
    lines.insert(10, "(1795348800.015000) can0 1A".into());
    lines.insert(11, "garbage".into());
    lines.insert(12, "(1795348800.015000) can0 7AB#0102".into());
    lines.insert(13, "(1795348800.015000) can1 105#0102".into());
    // 6. a packet from firmware built from another schema: same layout, other fingerprint.
    let foreign = foreign_packet_lines(Telemetry::LEN);
    let at = lines.len();
    lines.splice(at..at, foreign);

    let (snapshot, bad) = run(&lines).await;
    assert_eq!(bad, 2, "truncated + garbage");
    assert_eq!(snapshot.bad_lines, 2);
    assert_eq!(snapshot.unknown_ids, 1);
    assert_eq!(snapshot.decode_errors, 1);
    assert_eq!(snapshot.fingerprint_mismatches, 1);
    // The lost frame: the next frame has the wrong sequence number (one error); the repeated
    // frame likewise; the frames after each error until the next first frame are unexpected.
    assert!(snapshot.isotp_errors >= 2, "{snapshot:?}");
    assert_eq!(snapshot.packets, 18, "20 packets, two broken");
    assert_eq!(snapshot.stored, snapshot.packets + snapshot.messages);
}

/// A telemetry packet of `len` bytes whose fingerprint is not ours, as the frames a CCM built
/// from another schema would send (a field added or removed changes the length).
fn foreign_packet_lines(len: usize) -> Vec<String> {
    let mut ours = [0u8; Telemetry::LEN];
    Telemetry::zeroed().pack(
        aer::telemetry::TelemetryHeader {
            sequence: 9,
            timestamp_us: 0,
        },
        &mut ours,
    );
    let mut packet = ours.to_vec();
    packet.resize(len, 0);
    packet[..4].copy_from_slice(&0xDEAD_BEEFu32.to_le_bytes());
    let mut sender: aer_isotp::Sender<128> = aer_isotp::Sender::new(aer_isotp::Config::CAR);
    sender.start(&packet).expect("start");
    let mut lines = Vec::new();
    let id = embedded_can::Id::Standard(embedded_can::StandardId::new(0x666).expect("id"));
    let mut ts = 1_795_348_900_000_000u64;
    while let Ok(Some(frame)) = sender.poll(ts as u32) {
        sender.sent(ts as u32);
        lines.push(
            LoggedFrame::new(ts, 0, id, frame.as_slice())
                .expect("frame")
                .to_line("can0"),
        );
        if lines.len() == 1 {
            sender
                .on_flow_control(&[0x30, 0, 0], ts as u32)
                .expect("fc");
        }
        ts += 250;
    }
    lines
}

/// A CCM flashed from another schema is named as such, with both fingerprints on the status,
/// whether the schema change kept the packet's length or not; nothing is counted as malformed.
#[tokio::test]
async fn a_packet_of_another_schema_is_named_whatever_its_length() {
    for len in [Telemetry::LEN, Telemetry::LEN + 2, Telemetry::LEN - 3] {
        let counters = Arc::new(Counters::default());
        let stage = Stage::new(counters.clone(), Vec::new(), Replies::default());
        let text = foreign_packet_lines(len).join("\n");
        let (stage, _) = stage.replay_all(text.as_bytes(), &counters).await;
        drop(stage);
        let snapshot = counters.snapshot();
        assert_eq!(
            (snapshot.fingerprint_mismatches, snapshot.packet_errors),
            (1, 0),
            "{len} bytes: {snapshot:?}"
        );
        let status = aer_host::reports::status::status("car1", &counters, Default::default());
        assert_eq!(status.undecodable_packets, 1, "{len} bytes");
        assert_eq!(
            status.undecodable_fingerprint.as_deref(),
            Some("0xdeadbeef")
        );
        assert_eq!(status.fingerprint_match, Some(false));
        let problem = status
            .problems
            .firmware
            .expect("the status names the mismatch");
        assert!(
            problem.contains("another schema")
                && problem.contains("0xdeadbeef")
                && problem.contains(&status.telemetry_fingerprint),
            "{problem}"
        );
    }
}

#[test]
fn an_unwritable_store_path_is_a_clear_error_at_start_up() {
    let error =
        store::open(std::path::Path::new("/nonexistent-folder/aer.sqlite")).expect_err("must fail");
    let text = error.to_string();
    assert!(
        text.contains("/nonexistent-folder/aer.sqlite") && text.contains("cannot open"),
        "{text}"
    );
}

#[test]
fn the_cursor_gives_no_duplicates_and_no_gaps_across_failures_and_restarts() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("s.sqlite");
    let counters = Arc::new(Counters::default());
    let writer = store::StoreWriter::start(store::open(&path).expect("store"), counters.clone());
    let sender = writer.sender().expect("sender");
    let row = common::telemetry_row;
    for seq in 0..12 {
        sender.send(row(seq));
    }
    drop(sender);
    writer.finish();

    let sequences = |rows: &[Vec<rusqlite::types::Value>]| -> Vec<i64> {
        rows.iter()
            .map(|r| match r[3] {
                rusqlite::types::Value::Integer(i) => i,
                _ => -1,
            })
            .collect()
    };
    let db = store::open(&path).expect("reopen");
    // A batch that TDengine refused: the cursor stays.
    let batch = next_batch(&db, 0, 5).expect("batch");
    let last = batch.last_id();
    assert_eq!(sequences(&batch.rows), [0, 1, 2, 3, 4]);
    drop(db);
    // Restart: the same rows again (no gap), then accepted.
    let db = store::open(&path).expect("restart");
    let batch = next_batch(&db, 0, 5).expect("batch");
    assert_eq!(
        (batch.last_id(), sequences(&batch.rows)),
        (last, vec![0, 1, 2, 3, 4])
    );
    advance(&db, 0, batch.last_id().expect("rows")).expect("cursor");
    drop(db);
    // Restart after success: only what follows (no duplicate).
    let db = store::open(&path).expect("restart");
    let batch = next_batch(&db, 0, 100).expect("batch");
    assert_eq!(sequences(&batch.rows), (5..12).collect::<Vec<_>>());
    advance(&db, 0, batch.last_id().expect("rows")).expect("cursor");
    assert!(next_batch(&db, 0, 100).expect("batch").rows.is_empty());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn without_tdengine_rows_stay_and_the_forwarder_retries() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("s.sqlite");
    let (_, _) = {
        let counters = Arc::new(Counters::default());
        let writer =
            store::StoreWriter::start(store::open(&path).expect("store"), counters.clone());
        let stage = storing(&counters, &writer);
        let text = session_lines(5).join("\n");
        let (stage, _) = stage.replay_all(text.as_bytes(), &counters).await;
        drop(stage);
        writer.finish();
        (counters.snapshot(), 0)
    };
    // A port nothing listens on.
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("port")
        .port();
    let config = TdengineConfig {
        enabled: true,
        dsn: format!("taos+ws://127.0.0.1:{port}"),
        ..TdengineConfig::default()
    };
    let counters = Arc::new(Counters::default());
    let cancel = CancellationToken::new();
    let forwarder = tokio::spawn(forward::run(
        config,
        path.clone(),
        counters.clone(),
        Arc::default(),
        cancel.clone(),
    ));
    // Wait (bounded) until both workers have failed to connect at least once.
    let waited = tokio::time::timeout(Duration::from_secs(20), async {
        while counters.snapshot().forward_errors < 2 {
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    })
    .await;
    cancel.cancel();
    assert!(waited.is_ok(), "the forwarder never reported the outage");
    let _ = tokio::time::timeout(Duration::from_secs(10), forwarder).await;
    assert_eq!(counters.snapshot().forwarded, 0);
    let db = store::open(&path).expect("store");
    let batch = next_batch(&db, 0, 5_000).expect("batch");
    assert_eq!(batch.rows.len(), 5, "every telemetry row is still waiting");
}

#[tokio::test]
async fn kernel_reassembled_packets_take_the_same_path() {
    let counters = Arc::new(Counters::default());
    let dir = tempfile::tempdir().expect("temp dir");
    let writer = store::StoreWriter::start(
        store::open(&dir.path().join("k.sqlite")).expect("store"),
        counters.clone(),
    );
    let stage = storing(&counters, &writer).with_kernel_isotp();
    // Raw ISO-TP frames are the kernel's business now: ignored, not counted as errors.
    let text = session_lines(3).join("\n");
    let (mut stage, _) = stage.replay_all(text.as_bytes(), &counters).await;
    assert_eq!(counters.snapshot().packets, 0);
    assert_eq!(counters.snapshot().isotp_errors, 0);
    // Whole packets, as the can-isotp socket delivers them.
    let mut packet = [0u8; Telemetry::LEN];
    Telemetry {
        soc: 77.5,
        ..Telemetry::zeroed()
    }
    .pack(
        aer::telemetry::TelemetryHeader {
            sequence: 1,
            timestamp_us: 2,
        },
        &mut packet,
    );
    stage.take(Input::Packet {
        ts_us: 1_795_348_800_000_000,
        bus: 0,
        packet: packet.to_vec(),
    });
    stage.take(Input::Packet {
        ts_us: 1_795_348_800_010_000,
        bus: 0,
        packet: packet[..10].to_vec(),
    });
    drop(stage);
    writer.finish();
    let snapshot = counters.snapshot();
    assert_eq!(snapshot.packets, 1);
    assert_eq!(snapshot.packet_errors, 1, "a short packet is counted");
    assert_eq!(snapshot.stored, snapshot.packets + snapshot.messages);
}
