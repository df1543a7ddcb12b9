//! A season on the card: once a session is closed the writer compacts its rows into
//! compressed blocks. Nothing is lost (export and the forwarder read exactly what they read
//! before), the bundled session takes a small fraction of the room, the session being recorded
//! is never touched, retention still removes the oldest data first, and a damaged block is
//! reported and skipped, not fatal.

mod common;

use aer::tables::TABLES;
use aer_raspi::export::load::{self, Selection};
use aer_raspi::forward::next_batch;
use aer_raspi::store::{self as store, Budget, Compaction, Retention, compact, session};
use rusqlite::Connection;
use std::path::Path;
use std::time::Duration;
/// The bundled session's length.
const SESSION_SECONDS: f64 = 45.0;

/// Replays the bundled session into the store at `path`, in a session of its own.
fn record_session(path: &Path) -> i64 {
    let id = session::begin(
        &store::open(path).expect("store"),
        &session::Metadata::default(),
        "replay",
        1,
    )
    .expect("session");
    common::record_session(path);
    id
}

/// Closes the recorded session by opening the next one, then compacts until nothing is left.
fn compact_all(db: &mut Connection) -> u64 {
    session::begin(db, &session::Metadata::default(), "live", 2).expect("next session");
    let mut compaction = Compaction::default();
    let mut rows = 0;
    loop {
        let step = compaction.step(db).expect("compact");
        if step == 0 {
            return rows;
        }
        rows += step;
    }
}

fn plain_rows(db: &Connection) -> i64 {
    TABLES
        .iter()
        .map(|t| {
            db.query_row(&format!("SELECT count(*) FROM \"{}\"", t.name), [], |r| {
                r.get::<_, i64>(0)
            })
            .expect("count")
        })
        .sum()
}

/// Every table's rows as the forwarder reads them.
fn forwarded(db: &Connection) -> Vec<aer_raspi::forward::Batch> {
    (0..TABLES.len())
        .map(|t| next_batch(db, t, 100_000).expect("batch"))
        .collect()
}

/// The store's file size once freed pages are given back.
fn file_bytes(db: &Connection, path: &Path) -> u64 {
    store::space::release_free_pages(db).expect("vacuum");
    db.query_row("PRAGMA wal_checkpoint(TRUNCATE)", [], |_| Ok(()))
        .expect("checkpoint");
    std::fs::metadata(path).expect("store file").len()
}

#[test]
fn a_closed_session_compacts_to_a_fraction_and_reads_back_exactly() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("store.sqlite");
    let id = record_session(&path);
    let mut db = store::open(&path).expect("store");
    let selection = Selection {
        session: Some(id),
        ..Selection::default()
    };
    let exported = load::tables(&db, selection).expect("export");
    let batches = forwarded(&db);
    let rows = plain_rows(&db);
    let plain = file_bytes(&db, &path);

    assert_eq!(compact_all(&mut db), rows as u64);
    assert_eq!(
        plain_rows(&db),
        0,
        "every row of the closed session compacted"
    );
    let compacted = file_bytes(&db, &path);
    // Growth per hour: what the session adds to an empty store.
    let empty_path = dir.path().join("empty.sqlite");
    let empty = file_bytes(&store::open(&empty_path).expect("empty store"), &empty_path);
    let per_hour = |bytes: u64| (bytes - empty) as f64 * 3600.0 / SESSION_SECONDS / 1e6;
    eprintln!(
        "bundled session: {rows} rows; an empty store {empty} B; with the session {plain} B plain ({:.1} MB/h), {compacted} B compacted ({:.1} MB/h)",
        per_hour(plain),
        per_hour(compacted)
    );
    // The store's share of the 50 MB an hour a season on the card allows (the raw log's is
    // checked in storage_faults.rs).
    assert!(per_hour(compacted) < 15.0, "{compacted} B");

    let again = load::tables(&db, selection).expect("export");
    assert_eq!(exported.len(), again.len());
    for (before, after) in exported.iter().zip(&again) {
        assert_eq!(before.rows, after.rows, "{}", before.table.name);
        assert_eq!(before.values, after.values, "{}", before.table.name);
    }
    assert_eq!(forwarded(&db), batches, "the forwarder reads the same rows");
    // A time range inside compacted blocks selects as before.
    let ts_column = exported[0]
        .columns()
        .find(|(c, _)| c.name == "ts_us")
        .map(|(_, v)| v.clone());
    let Some(aer_raspi::export::columns::Values::Int(ts)) = ts_column else {
        panic!("no ts_us column");
    };
    let (from, to) = (ts[100].expect("ts"), ts[199].expect("ts"));
    let range = Selection {
        session: None,
        from_us: Some(from),
        to_us: Some(to),
    };
    assert_eq!(
        load::tables(&db, range).expect("range")[0].rows,
        100,
        "telemetry rows 100..=199"
    );
}

#[test]
fn the_session_being_recorded_stays_plain() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("store.sqlite");
    record_session(&path);
    let mut db = store::open(&path).expect("store");
    let before = plain_rows(&db);
    let mut compaction = Compaction::default();
    assert_eq!(compaction.step(&mut db).expect("step"), 0);
    assert_eq!(plain_rows(&db), before);
    // Nor is anything compacted without a session (the service always records one) ...
    session::end(&db, 3).expect("end");
    assert_eq!(compaction.step(&mut db).expect("step"), 0);
    // ... unless the service is stopped (`aer-raspi compact`): then every session is closed.
    let mut offline = Compaction::everything_closed();
    assert!(offline.step(&mut db).expect("step") > 0);
}

#[test]
fn retention_removes_compacted_blocks_oldest_first() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("store.sqlite");
    record_session(&path);
    let mut db = store::open(&path).expect("store");
    compact_all(&mut db);
    let blocks = |db: &Connection| -> (i64, i64) {
        db.query_row(
            "SELECT count(*), coalesce(min(first_id), 0) FROM compacted WHERE table_name = 'telemetry'",
            [],
            |r| Ok((r.get(0)?, r.get(1)?)),
        )
        .expect("blocks")
    };
    let (count, oldest) = blocks(&db);
    assert!(count > 1, "{count} telemetry blocks");
    let retention = Retention::new(
        path.clone(),
        Budget {
            max_bytes: 1,
            max_age: None,
            min_free_bytes: 0,
            interval: Duration::ZERO,
        },
    );
    let pruned = retention.prune(&db).expect("prune");
    let (left, new_oldest) = blocks(&db);
    assert!(pruned.rows > 0);
    assert!(left < count, "{left} of {count} blocks left");
    assert!(left == 0 || new_oldest > oldest, "the oldest went first");
}

#[test]
fn a_damaged_block_is_reported_and_skipped() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("store.sqlite");
    record_session(&path);
    let mut db = store::open(&path).expect("store");
    compact_all(&mut db);
    let telemetry = &TABLES[0];
    let all = compact::rows_between(&db, telemetry, 1, i64::MAX, usize::MAX).expect("rows");
    let (first_id, rows): (i64, i64) = db
        .query_row(
            "SELECT first_id, rows FROM compacted WHERE table_name = ?1 ORDER BY first_id LIMIT 1",
            [telemetry.name],
            |r| Ok((r.get(0)?, r.get(1)?)),
        )
        .expect("a block");
    db.execute(
        "UPDATE compacted SET data = x'28b52ffd00ff' WHERE table_name = ?1 AND first_id = ?2",
        rusqlite::params![telemetry.name, first_id],
    )
    .expect("damage");
    let read = compact::rows_between(&db, telemetry, 1, i64::MAX, usize::MAX).expect("rows");
    assert_eq!(read.damaged.len(), 1, "{:?}", read.damaged);
    assert_eq!(read.rows.len() as i64, all.rows.len() as i64 - rows);
    // The forwarder moves past it instead of stopping there.
    let batch = next_batch(&db, 0, 10).expect("batch");
    assert_eq!(batch.damaged.len(), 1);
    assert_eq!(batch.ids.first().copied(), Some(first_id + rows));
}

#[test]
fn the_free_space_floor_counts_compacted_history_at_its_real_size() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("store.sqlite");
    record_session(&path);
    compact_all(&mut store::open(&path).expect("store"));
    // The next session is recorded, plain, beside the first one's blocks, with later ids
    // (SQLite would reuse the ids of an emptied table without AUTOINCREMENT).
    let next = record_session(&path);
    let db = store::open(&path).expect("store");
    let (first_new, _) = session::rows(&db, next, "telemetry")
        .expect("rows")
        .expect("telemetry rows");
    let last_compacted: i64 = db
        .query_row(
            "SELECT max(last_id) FROM compacted WHERE table_name = 'telemetry'",
            [],
            |r| r.get(0),
        )
        .expect("blocks");
    assert!(
        first_new > last_compacted,
        "{first_new} after {last_compacted}"
    );
    let blocks: i64 = db
        .query_row("SELECT sum(length(data)) FROM compacted", [], |r| r.get(0))
        .expect("blocks");
    let blocks = blocks as u64;
    let free = 1_000_000_000u64;
    let retention = |floor: u64| {
        Retention::new(
            path.clone(),
            Budget {
                max_bytes: u64::MAX,
                max_age: None,
                min_free_bytes: floor,
                interval: Duration::ZERO,
            },
        )
        .with_free_space(move |_| Some(free))
    };
    // Removing every block could not lift the free space over this floor: nothing goes.
    let pruned = retention(free + 2 * blocks).prune(&db).expect("prune");
    assert_eq!(pruned.rows, 0);
    assert!(pruned.disk_low.is_some());
    // This floor the blocks can reach: the oldest go, the session being recorded stays.
    let plain = plain_rows(&db);
    let pruned = retention(free + blocks / 4).prune(&db).expect("prune");
    assert!(pruned.rows > 0);
    assert_eq!(pruned.disk_low, None);
    assert_eq!(plain_rows(&db), plain);
}
