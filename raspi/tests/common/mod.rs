//! What several of the service's test files build the same way (each uses some of it).
#![allow(dead_code)]

use aer_host::reports::counters::Counters;
use aer_raspi::ingest::Stage;
use aer_raspi::sink::Sink;
use aer_raspi::sink::store::StoreSink;
use aer_raspi::source::Replies;
use aer_raspi::store::{self, StoreWriter, WhenFull, WriterOptions, session};
use std::path::{Path, PathBuf};
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

/// The bundled session's candump log file.
pub fn session_log() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("data/session.log")
}

/// Runs `tools/check_frame_exports.py` on the bus-logging files in `dir` against `reference`
/// (a candump log), and with `messages` (written here) the MF4's signals against the Parquet
/// files; its output. Skips (empty output) without the Python readers.
pub fn check_frames(reference: &Path, dir: &Path, messages: Option<&Path>) -> String {
    let Some(python) = python() else {
        return String::new();
    };
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tools/check_frame_exports.py");
    let mut command = Command::new(python);
    command
        .arg(script)
        .arg("--reference")
        .arg(reference)
        .args(["--channels", "1=can0,2=can1", "--dir"])
        .arg(dir);
    if let Some(path) = messages {
        // Each DBC message's table and columns in the export.
        let messages: serde_json::Map<String, serde_json::Value> = aer::can::MESSAGES
            .iter()
            .filter_map(|message| {
                let table = aer::tables::TABLES
                    .iter()
                    .find(|t| std::ptr::eq(t.signals, message.signals))?;
                let columns = aer_raspi::export::columns::of(table);
                let signals: serde_json::Map<String, serde_json::Value> = message
                    .signals
                    .iter()
                    .filter_map(|signal| {
                        let column = table.columns.get(1 + usize::from(signal.index))?;
                        let exported = columns.iter().find(|c| c.stored == column.name)?;
                        Some((signal.name.to_owned(), exported.name.into()))
                    })
                    .collect();
                Some((
                    message.name.to_owned(),
                    serde_json::json!({"table": table.name, "signals": signals}),
                ))
            })
            .collect();
        std::fs::write(path, serde_json::to_string(&messages).expect("json")).expect("write");
        let dbc = Path::new(env!("CARGO_MANIFEST_DIR")).join("../schema/aer.dbc");
        command.arg("--dbc").arg(dbc).arg("--messages").arg(path);
    }
    let result = command.output().expect("run check_frame_exports.py");
    let stdout = String::from_utf8_lossy(&result.stdout).into_owned();
    assert!(
        result.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&result.stderr)
    );
    println!("{stdout}");
    stdout
}

/// The project venv's Python with the exports' independent readers; `None` (said as
/// SKIPPED) without them, unless `AER_REQUIRE_PYTHON` is set.
pub fn python() -> Option<PathBuf> {
    let venv = Path::new(env!("CARGO_MANIFEST_DIR")).join("../.venv/bin/python");
    let python = std::env::var_os("AER_PYTHON").map_or(venv, PathBuf::from);
    let usable = Command::new(&python)
        .args(["-c", "import mcap, polars, can, asammdf"])
        .output()
        .is_ok_and(|o| o.status.success());
    if usable {
        return Some(python);
    }
    assert!(
        std::env::var_os("AER_REQUIRE_PYTHON").is_none(),
        "AER_REQUIRE_PYTHON is set but {} cannot import mcap, polars, can and asammdf",
        python.display()
    );
    eprintln!(
        "SKIPPED: reading the exports back needs {} with mcap, polars, python-can and asammdf \
         (python3 -m venv .venv && .venv/bin/pip install -r tools/requirements.txt)",
        python.display()
    );
    None
}

/// The bundled session as one raw log segment, as the service writes it: the header, then
/// blocks of 4,096 frames.
pub fn session_segment() -> Vec<u8> {
    use aer_host::formats::raw_format::{BlockEncoder, MAGIC};
    let mut buses: Vec<Arc<str>> = Vec::new();
    let frames: Vec<_> = SESSION
        .lines()
        .map(|line| {
            aer_host::formats::candump::parse_line(line, |name| {
                let index = buses.iter().position(|b| &**b == name).unwrap_or_else(|| {
                    buses.push(name.into());
                    buses.len() - 1
                });
                u8::try_from(index).expect("few buses")
            })
            .expect("the bundled log parses")
        })
        .collect();
    let mut segment = MAGIC.to_vec();
    for chunk in frames.chunks(4096) {
        let mut block = BlockEncoder::new(chunk[0].ts_us, &buses);
        for frame in chunk {
            block.push(frame);
        }
        segment.extend_from_slice(&block.finish());
    }
    segment
}

/// The messages the demo session carries on interface `bus` (`can0`, the vehicle bus; `can1`,
/// the DTI's), from the schema: every periodic message on that bus but the XCP slave's
/// responses (sent only while a master talks to it). Tests count against this, so a message
/// added to the schema (and to the session) needs no edit here.
pub fn session_messages_on(bus: &str) -> std::collections::BTreeSet<&'static str> {
    let schema_bus = match bus {
        "can0" => "vehicle",
        "can1" => "inverter",
        other => panic!("the demo session has no interface {other}"),
    };
    aer::can::MESSAGES
        .iter()
        .filter(|m| m.timeout_ms.is_some() && m.buses.contains(&schema_bus))
        .filter(|m| m.extended || m.id != aer::calibration::xcp::CAN_ID_SLAVE)
        .map(|m| m.name)
        .collect()
}
