//! The service as systemd runs it, stopped three ways while the car model feeds it: SIGTERM
//! (a clean stop: nothing lost, out within seconds), SIGKILL (a crash), and a power cut (the
//! disk as it was at one instant: the process frozen, its files copied, then killed). After
//! each, what the store holds is compared with what the raw log holds, decoded; the losses
//! are printed (`--nocapture`) and bounded.

#![cfg(unix)]

use aer_host::decode::{Ingest, Record};
use aer_host::formats::raw_format::SegmentReader;
use aer_host::reports::counters::Counters;
use aer_raspi::rawlog::segments;
use aer_raspi::store;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Rows the car model makes a second (100 packets and the DBC frames of both buses).
const ROWS_PER_S: usize = 700;

fn start(dir: &Path) -> Child {
    let config = dir.join("aer-raspi.toml");
    std::fs::write(
        &config,
        format!(
            "[store]\npath = \"{}\"\n[raw_log]\ndir = \"{}\"\n[broker]\nembedded = false\n[mqtt]\nport = 9\n",
            dir.join("store.sqlite").display(),
            dir.join("raw").display()
        ),
    )
    .expect("config");
    Command::new(env!("CARGO_BIN_EXE_aer-raspi"))
        .args(["--config"])
        .arg(&config)
        .args(["replay", "--loop"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("start aer-raspi")
}

fn rows(store: &Path) -> usize {
    let Ok(db) =
        rusqlite::Connection::open_with_flags(store, rusqlite::OpenFlags::SQLITE_OPEN_READ_ONLY)
    else {
        return 0;
    };
    aer::tables::TABLES
        .iter()
        .map(|t| {
            db.query_row(&format!("SELECT count(*) FROM \"{}\"", t.name), [], |r| {
                r.get::<_, i64>(0)
            })
            .unwrap_or(0) as usize
        })
        .sum()
}

/// Waits (bounded) until the store holds `count` rows.
fn wait_for_rows(store: &Path, count: usize) {
    let deadline = Instant::now() + Duration::from_secs(120);
    while rows(store) < count {
        assert!(Instant::now() < deadline, "the service stored nothing");
        std::thread::sleep(Duration::from_millis(100));
    }
}

fn signal(child: &Child, signal: &str) {
    let status = Command::new("kill")
        .args([signal, &child.id().to_string()])
        .status()
        .expect("kill");
    assert!(status.success());
}

/// Waits (bounded) for the process to end; how long it took.
fn wait_exit(child: &mut Child, limit: Duration) -> Duration {
    let started = Instant::now();
    loop {
        if let Some(status) = child.try_wait().expect("wait") {
            assert!(
                status.success() || status.code().is_none(),
                "exit status {status}"
            );
            return started.elapsed();
        }
        assert!(started.elapsed() < limit, "not stopped within {limit:?}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// The records the raw log's frames decode to (packets and DBC messages).
fn raw_records(raw: &Path) -> usize {
    let counters = Arc::new(Counters::default());
    let mut ingest = Ingest::new(counters);
    let mut records = 0;
    for (path, _) in segments::list(raw) {
        let data = std::fs::read(&path).expect("segment");
        for frame in SegmentReader::new(&data).expect("header").flatten() {
            ingest.on_frame(
                &frame.frame,
                |record| {
                    if matches!(record, Record::Telemetry { .. } | Record::Can { .. }) {
                        records += 1;
                    }
                },
                |_, _| {},
            );
        }
    }
    records
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).expect("dir");
    for entry in std::fs::read_dir(from).expect("read").flatten() {
        let path = entry.path();
        let target: PathBuf = to.join(entry.file_name());
        if path.is_dir() {
            copy_dir(&path, &target);
        } else {
            std::fs::copy(&path, &target).expect("copy");
        }
    }
}

#[test]
fn sigterm_stops_within_seconds_and_loses_nothing() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut service = start(dir.path());
    let store = dir.path().join("store.sqlite");
    wait_for_rows(&store, 4 * ROWS_PER_S);
    signal(&service, "-TERM");
    let took = wait_exit(&mut service, Duration::from_secs(15));
    let stored = rows(&store);
    let logged = raw_records(&dir.path().join("raw"));
    eprintln!(
        "SIGTERM: stopped in {took:?}; stored {stored} rows, the raw log decodes to {logged}"
    );
    assert!(took < Duration::from_secs(10));
    assert_eq!(stored, logged, "every decoded frame is stored");
    assert!(store::open(&store).is_ok());
}

#[test]
fn sigkill_and_a_power_cut_lose_at_most_the_last_seconds() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut service = start(dir.path());
    let store_path = dir.path().join("store.sqlite");
    wait_for_rows(&store_path, 4 * ROWS_PER_S);
    // The power cut: the disk as it is at this instant.
    signal(&service, "-STOP");
    let image = dir.path().join("power-cut");
    std::fs::create_dir_all(&image).expect("dir");
    for name in ["store.sqlite", "store.sqlite-wal", "store.sqlite-shm"] {
        let from = dir.path().join(name);
        if from.exists() {
            std::fs::copy(&from, image.join(name)).expect("copy");
        }
    }
    copy_dir(&dir.path().join("raw"), &image.join("raw"));
    // The crash.
    signal(&service, "-KILL");
    let _ = wait_exit(&mut service, Duration::from_secs(10));

    for (what, at) in [("SIGKILL", dir.path().to_path_buf()), ("power cut", image)] {
        let store_path = at.join("store.sqlite");
        let db = store::open(&store_path).unwrap_or_else(|e| panic!("{what}: {e}"));
        drop(db);
        let stored = rows(&store_path);
        let logged = raw_records(&at.join("raw"));
        let lost = logged.saturating_sub(stored);
        eprintln!(
            "{what}: the store reopens intact with {stored} rows; the raw log decodes to {logged}; {lost} rows not stored ({:.1} s of traffic)",
            lost as f64 / ROWS_PER_S as f64
        );
        assert!(stored > 0);
        // One commit a second, plus what waited in the queue.
        assert!(lost <= 3 * ROWS_PER_S, "{what}: {lost} rows lost");
    }
}
