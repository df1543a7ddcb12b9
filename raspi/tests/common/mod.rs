//! What several of the service's test files build the same way (each uses some of it).
#![allow(dead_code)]

use aer_host::counters::Counters;
use aer_raspi::sink::Sink;
use aer_raspi::sink::store::StoreSink;
use aer_raspi::source::Replies;
use aer_raspi::stage::Stage;
use aer_raspi::store::{self, StoreWriter, WhenFull, WriterOptions, session};
use std::path::PathBuf;
use std::process::{Command, Output};
use std::sync::Arc;

/// The bundled session (candump -l).
pub const SESSION: &str = include_str!("../../data/session.log");

/// A default telemetry row of `car1` with sequence `seq`, stamped 1 ms + `seq` us.
pub fn telemetry_row(seq: u16) -> store::Row {
    store::Row {
        car_id: "car1".into(),
        ts_us: 1_000 + u64::from(seq),
        data: store::RowData::Telemetry {
            header: aer::telemetry::TelemetryHeader {
                sequence: seq,
                timestamp_us: 0,
            },
            telemetry: aer::telemetry::Telemetry::zeroed(),
        },
    }
}

/// Replays the bundled session into the store at `path` (in the session open there, if any).
pub fn record_session(path: &std::path::Path) {
    let counters = Arc::new(Counters::default());
    let writer = StoreWriter::with_options(
        store::open(path).expect("store"),
        counters.clone(),
        WriterOptions {
            when_full: WhenFull::Wait,
            ..WriterOptions::default()
        },
    );
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("runtime");
    let sinks: Vec<Box<dyn Sink>> = vec![Box::new(StoreSink::new(
        writer.sender().expect("open"),
        "car1",
    ))];
    let stage = Stage::new(counters.clone(), sinks, Replies::default());
    let (stage, _) = runtime.block_on(stage.replay_all(SESSION.as_bytes(), &counters));
    drop(stage);
    writer.finish();
}

/// A folder with a store holding the bundled session (session 1, closed) and, after it, a
/// session opened and left empty (session 2: the LV power cycle before the export).
pub struct Car {
    pub dir: tempfile::TempDir,
    pub config: PathBuf,
    pub store: PathBuf,
}

impl Car {
    pub fn new() -> Self {
        let dir = tempfile::tempdir().expect("dir");
        let data = dir.path().join("data");
        std::fs::create_dir(&data).expect("data");
        let store = data.join("store.sqlite");
        let db = store::open(&store).expect("store");
        session::begin(&db, &session::Metadata::default(), "live", 1_000).expect("session");
        drop(db);
        record_session(&store);
        let db = store::open(&store).expect("store");
        session::begin(&db, &session::Metadata::default(), "live", 2_000).expect("session");
        drop(db);
        // The session's raw log: one segment started with it, one long before it.
        let raw = data.join("raw");
        std::fs::create_dir(&raw).expect("raw");
        for start in [10u64, 999] {
            std::fs::write(raw.join(format!("raw-{start:020}.aerraw")), b"segment")
                .expect("segment");
        }
        let config = dir.path().join("aer-raspi.toml");
        std::fs::write(
            &config,
            format!(
                "[store]\npath = {:?}\n[raw_log]\ndir = {:?}\n",
                store.display().to_string(),
                raw.display().to_string()
            ),
        )
        .expect("config");
        Self { dir, config, store }
    }

    pub fn run(&self, args: &[&str]) -> Output {
        Command::new(env!("CARGO_BIN_EXE_aer-raspi"))
            .arg("-c")
            .arg(&self.config)
            .args(args)
            .current_dir(self.dir.path())
            .env_remove("AER_STORE_PATH")
            .env("RUST_BACKTRACE", "0")
            .output()
            .expect("aer-raspi")
    }
}

/// A command's standard output and error.
pub fn text(output: &Output) -> (String, String) {
    (
        String::from_utf8_lossy(&output.stdout).into_owned(),
        String::from_utf8_lossy(&output.stderr).into_owned(),
    )
}
