//! Session exports read back by independent readers: the bundled session is stored as the
//! service stores it (a second session after it must stay out of the export), exported as
//! MCAP, Parquet and CSV, and `tools/check_exports.py` reads the files with Foxglove's `mcap`
//! package, `polars` and Python's `csv`, comparing row counts, column types and every value
//! with the store. The Python readers come from the project's venv (`tools/requirements.txt`,
//! which `.ci/run` installs); without them the comparison says SKIPPED, unless
//! `AER_REQUIRE_PYTHON` is set (CI sets it), when it fails.

mod common;

use aer::tables::TABLES;
use aer_host::decode::{Ingest, Record};
use aer_host::reports::counters::Counters;
use aer_raspi::export::frames::source::FrameSource;
use aer_raspi::export::load::Selection;
use aer_raspi::export::{self, Format, Request};
use aer_raspi::service::DEMO_LOG;
use aer_raspi::store::calibration::{ECU_PAGE, Entry, Kind};
use aer_raspi::store::session::{self, Metadata};
use aer_raspi::store::{self, row, writer};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Arc;

/// The bundled session's rows, as the service makes them.
fn session_rows(limit: usize) -> Vec<row::Row> {
    let mut ingest = Ingest::new(Arc::new(Counters::default()));
    let car: Arc<str> = "car1".into();
    let mut buses: Vec<Arc<str>> = Vec::new();
    let mut rows = Vec::new();
    for line in DEMO_LOG.lines().take(limit) {
        let frame = aer_host::formats::candump::parse_line(line, |name| {
            let index = buses.iter().position(|b| &**b == name).unwrap_or_else(|| {
                buses.push(name.into());
                buses.len() - 1
            });
            u8::try_from(index).expect("few buses")
        })
        .expect("the bundled log parses");
        ingest.on_frame(
            &frame,
            |record| {
                if matches!(record, Record::Telemetry { .. } | Record::Can { .. }) {
                    rows.push(row::row(&record, &car, &buses));
                }
            },
            |_, _| {},
        );
    }
    rows
}

/// A calibration record with one entry of each kind, refusals with text CSV must quote.
fn calibration_record() -> Vec<Entry> {
    let entry =
        |kind, parameter: &str, element: Option<u32>, old, new, accepted, reason: &str| Entry {
            at_us: 1_764_000_000_000_000 + i64::from(element.unwrap_or(0)),
            master: "10.9.0.2:51234".into(),
            kind,
            parameter: parameter.into(),
            element,
            old,
            new,
            accepted,
            reason: reason.into(),
            checksum: accepted.then_some(0xDEAD_BEEF),
        };
    vec![
        entry(
            Kind::Found,
            "traction_kp",
            None,
            Some(400.0),
            Some(400.0),
            true,
            "",
        ),
        entry(
            Kind::Write,
            "launch_slip_target",
            Some(2),
            Some(0.12),
            Some(0.03),
            true,
            "",
        ),
        entry(
            Kind::Write,
            "launch_kp",
            None,
            Some(300.0),
            Some(1e6),
            false,
            "out of range 0-2000, \"really\"",
        ),
        entry(
            Kind::Page,
            ECU_PAGE,
            None,
            Some(0.0),
            Some(1.0),
            false,
            "only at standstill",
        ),
        entry(Kind::Save, "", None, None, None, true, ""),
    ]
}

/// An export of session `id` in `formats` into `out`, its frames from `frames` (a log or
/// segment), the bus-logging formats asked for by name.
fn session_request(id: i64, formats: Vec<Format>, out: &Path, frames: PathBuf) -> Request {
    Request {
        selection: Selection {
            session: Some(id),
            ..Selection::default()
        },
        formats,
        out_dir: out.to_owned(),
        topic_root: "aer/car1".into(),
        extra: Vec::new(),
        frames: Some(FrameSource {
            files: vec![frames],
            ..FrameSource::default()
        }),
        frames_required: true,
    }
}

#[test]
fn a_session_exported_in_every_format_reads_back_equal_to_the_store() {
    let dir = tempfile::tempdir().expect("temp dir");
    let store_path = dir.path().join("store.sqlite");
    let mut db = store::open(&store_path).expect("store");
    let metadata = Metadata {
        driver: "Ana \"fast\" Lima".into(),
        track: "Skidpad, lot B".into(),
        run: Some(3),
        notes: "dry; 12 C\nnew rear tyres".into(),
    };
    let id = session::begin(&db, &metadata, "replay", 1).expect("session");
    let rows = session_rows(usize::MAX);
    for batch in rows.chunks(5000) {
        writer::commit(&mut db, batch).expect("commit");
    }
    let record = calibration_record();
    store::calibration::record(&db, id, &record).expect("calibration record");
    // A second session: none of its rows may appear in the first one's export.
    let second = session::begin(&db, &Metadata::default(), "replay", 2).expect("session");
    writer::commit(&mut db, &session_rows(3000)).expect("commit");
    store::calibration::record(&db, second, &record[..1]).expect("calibration record");

    let out = dir.path().join("export");
    let request = session_request(id, Format::all(), &out, common::session_log());
    let report = export::export(&db, &request).expect("export");
    let exported: usize = report.rows.iter().map(|(_, n)| n).sum();
    assert_eq!(exported, rows.len(), "every row of the session, no other");
    let frames = DEMO_LOG.lines().count();
    for format in report.formats.iter().filter(|f| f.format.holds_frames()) {
        assert_eq!(format.files.len(), 1, "{:?}", format.format);
        assert_eq!(format.files[0].rows, frames, "{:?}", format.format);
    }
    for format in report.formats.iter().filter(|f| !f.format.holds_frames()) {
        assert!(
            !format.files.is_empty(),
            "{:?} wrote nothing",
            format.format
        );
        let (record_files, data_files): (Vec<_>, Vec<_>) = format
            .files
            .iter()
            .partition(|f| f.path.file_stem().is_some_and(|s| s == "calibration"));
        let rows_in_files: usize = data_files.iter().map(|f| f.rows).sum();
        assert_eq!(rows_in_files, rows.len(), "{:?}", format.format);
        let entries: usize = record_files.iter().map(|f| f.rows).sum();
        let expected = if format.format == Format::Mcap {
            0
        } else {
            record.len()
        };
        assert_eq!(
            entries, expected,
            "{:?}: the calibration record",
            format.format
        );
    }

    let types: HashMap<&str, Vec<(&str, &str, String)>> = TABLES
        .iter()
        .map(|t| {
            let columns = export::columns::of(t)
                .iter()
                .map(|c| (c.stored, c.name, format!("{:?}", c.ty)))
                .collect();
            (t.name, columns)
        })
        .collect();
    let types_path = dir.path().join("types.json");
    std::fs::write(&types_path, serde_json::to_string(&types).expect("json")).expect("write");
    let Some(python) = common::python() else {
        return;
    };
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tools/check_exports.py");
    let result = Command::new(python)
        .arg(script)
        .arg("--store")
        .arg(&store_path)
        .arg("--out")
        .arg(&out)
        .arg("--types")
        .arg(&types_path)
        .args(["--session", &id.to_string()])
        .output()
        .expect("run check_exports.py");
    let stdout = String::from_utf8_lossy(&result.stdout);
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert!(result.status.success(), "{stdout}\n{stderr}");
    println!("{stdout}");
    assert!(stdout.contains(&format!("{} rows", rows.len())), "{stdout}");
    assert!(
        stdout.contains(&format!("calibration record of {} entries", record.len())),
        "{stdout}"
    );

    // The frames: python-can reads the BLF and ASC files, asammdf the MF4 (and decodes it with
    // the DBC into signals that must equal the Parquet files' columns).
    let stdout = common::check_frames(
        &common::session_log(),
        &out,
        Some(&dir.path().join("messages.json")),
    );
    assert!(
        stdout.contains(&format!("session.mf4 (asammdf): {frames} frames equal")),
        "{stdout}"
    );
    // asammdf groups by channel: CCM_Status, on both buses, counts once on each.
    let messages: usize = ["can0", "can1"]
        .into_iter()
        .map(|bus| common::session_messages_on(bus).len())
        .sum();
    assert!(
        stdout.contains(&format!(
            "signals of {messages} messages equal to the export"
        )),
        "{stdout}"
    );

    // The runbook's join of telemetry and a CAN message in time (docs/test-day.md) runs on
    // this export as it stands in the document.
    let join = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/examples/join_telemetry_can.py");
    let Some(python) = common::python() else {
        return;
    };
    let joined = Command::new(python)
        .arg(join)
        .arg(&out)
        .output()
        .expect("run join_telemetry_can.py");
    let stdout = String::from_utf8_lossy(&joined.stdout);
    assert!(
        joined.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&joined.stderr)
    );
    let telemetry = rows
        .iter()
        .filter(|row| row.table().name == "telemetry")
        .count();
    assert!(
        stdout.contains(&format!("{telemetry} packets, ")),
        "every packet joined: {stdout}"
    );
}

/// `session new` while the service runs: the writer commits a batch up to a second after its
/// rows arrived, so rows received before the new session began reach the store after it. Each
/// row belongs to the session open when it was received, and the raw log's frames are taken
/// by the same window, so every format of either session holds the same traffic: the row
/// formats (MCAP, Parquet, CSV) the rows received in the window, the frame formats (BLF,
/// ASC, MF4) the frames received in it.
#[test]
fn at_a_session_new_every_format_of_each_session_takes_the_same_traffic() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut db = store::open(&dir.path().join("store.sqlite")).expect("store");
    let rows = session_rows(usize::MAX);
    let ts = |row: &row::Row| i64::try_from(row.ts_us).expect("a time");
    let (first, last) = (ts(&rows[0]), ts(&rows[rows.len() - 1]));
    let boundary = ts(&rows[rows.len() / 2]);
    session::begin(&db, &Metadata::default(), "demo", first).expect("session 1");
    let (before, after) = rows.split_at(rows.len() / 3);
    writer::commit(&mut db, before).expect("commit");
    // The pit starts the next session; the writer has not yet committed what came before.
    let second = session::hand_over(&db, &Metadata::default(), boundary).expect("session 2");
    for batch in after.chunks(5000) {
        writer::commit(&mut db, batch).expect("commit");
    }
    session::end(&db, last + 1).expect("end");

    let log = common::session_log();
    let log_times: Vec<u64> = DEMO_LOG
        .lines()
        .map(|line| {
            aer_host::formats::candump::parse_line(line, |_| 0)
                .expect("the bundled log parses")
                .ts_us
        })
        .collect();
    for id in [1, second] {
        let session = session::get(&db, id).expect("read").expect("session");
        assert_eq!(session.source, "demo", "session new keeps the source");
        let (from, to) = session.window();
        let within = |t: u64| t >= from && to.is_none_or(|to| t <= to);
        let out = dir.path().join(format!("session-{id}"));
        let mut request = session_request(id, Format::all(), &out, log.clone());
        if let Some(frames) = request.frames.as_mut() {
            frames.from_us = Some(from);
            frames.to_us = to;
        }
        let report = export::export(&db, &request).expect("export");
        for table in TABLES {
            let expected = rows
                .iter()
                .filter(|r| r.table().name == table.name && within(r.ts_us))
                .count();
            let exported = report
                .rows
                .iter()
                .find(|(name, _)| *name == table.name)
                .map_or(0, |(_, n)| *n);
            assert_eq!(exported, expected, "session {id}: {}", table.name);
        }
        let frames = log_times.iter().filter(|t| within(**t)).count();
        assert!(frames > 0, "session {id} has frames");
        for format in &report.formats {
            let written: usize = format
                .files
                .iter()
                .filter(|f| f.path.file_stem().is_none_or(|s| s != "calibration"))
                .map(|f| f.rows)
                .sum();
            let expected = if format.format.holds_frames() {
                frames
            } else {
                rows.iter().filter(|r| within(r.ts_us)).count()
            };
            assert_eq!(written, expected, "session {id}: {:?}", format.format);
        }
    }
}

/// The command line exports a recorded log straight away, with the session flags as its
/// metadata, and takes the same rows the service would have stored.
#[test]
fn a_recorded_log_exports_without_a_store() {
    let dir = tempfile::tempdir().expect("temp dir");
    let log = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/session.log");
    let out = dir.path().join("export");
    let result = Command::new(env!("CARGO_BIN_EXE_aer-raspi"))
        .args(["--driver", "Ben", "--run", "7", "export", "--format", "csv"])
        .arg("--log")
        .arg(&log)
        .arg("--out")
        .arg(&out)
        .env("AER_STORE_PATH", dir.path().join("unused.sqlite"))
        .output()
        .expect("aer-raspi export");
    assert!(
        result.status.success(),
        "{}",
        String::from_utf8_lossy(&result.stderr)
    );
    let expected = session_rows(usize::MAX).len();
    let mut lines = 0;
    for table in TABLES {
        if let Ok(text) =
            std::fs::read_to_string(out.join("csv").join(format!("{}.csv", table.name)))
        {
            lines += text.lines().count() - 1;
        }
    }
    assert_eq!(lines, expected);
    let session = std::fs::read_to_string(out.join("csv/session.csv")).expect("session.csv");
    assert!(
        session.contains("driver,Ben") && session.contains("run,7"),
        "{session}"
    );
}

/// After the demo, `export` without flags says which flag reads the demo's store, and that
/// flag exports it.
#[test]
fn the_demo_store_is_found_with_the_flag_the_error_names() {
    let dir = tempfile::tempdir().expect("temp dir");
    let db = store::open(&dir.path().join("aer-demo.sqlite")).expect("store");
    session::begin(&db, &Metadata::default(), "demo", 1).expect("session");
    let mut db = db;
    writer::commit(&mut db, &session_rows(200)).expect("commit");
    drop(db);
    let export = |extra: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_aer-raspi"))
            .args([
                "export",
                "--session",
                "latest",
                "--format",
                "csv",
                "--out",
                "out",
            ])
            .args(extra)
            .current_dir(dir.path())
            .env_remove("AER_STORE_PATH")
            .output()
            .expect("aer-raspi export")
    };
    let without = export(&[]);
    let stderr = String::from_utf8_lossy(&without.stderr);
    assert!(!without.status.success());
    assert!(
        stderr.contains("no store at aer-local.sqlite") && stderr.contains("add --demo"),
        "{stderr}"
    );
    let with = export(&["--demo"]);
    assert!(
        with.status.success(),
        "{}",
        String::from_utf8_lossy(&with.stderr)
    );
    assert!(dir.path().join("out/csv/telemetry.csv").exists());
}

/// The bus-logging formats asked for by name with no frames to hold is an error found before
/// anything is written, so the folder is not left half-written.
#[test]
fn bus_logging_formats_without_frames_fail_before_writing_anything() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut db = store::open(&dir.path().join("store.sqlite")).expect("store");
    let id = session::begin(&db, &Metadata::default(), "replay", 1).expect("session");
    writer::commit(&mut db, &session_rows(3000)).expect("commit");
    let out = dir.path().join("export");
    let request = session_request(
        id,
        vec![Format::Parquet, Format::Blf],
        &out,
        dir.path().join("no-such-segment.aerraw"),
    );
    let error = export::export(&db, &request).expect_err("no frames");
    assert!(
        matches!(error, export::ExportError::Read { .. }),
        "a single missing file is an error: {error}"
    );
    let request = Request {
        frames: None,
        ..request
    };
    let error = export::export(&db, &request).expect_err("no frames");
    assert!(matches!(error, export::ExportError::NoFrames), "{error}");
    assert!(!out.exists(), "nothing written");
}
