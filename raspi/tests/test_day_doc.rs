//! docs/test-day.md quotes what the commands print; every quote is printed here, by the same
//! command code the `aer-raspi` binary runs, on a store like the car's after a run (the
//! bundled session, then an LV power cycle's empty session), so the runbook cannot drift from
//! the tool. A quote sits in a ```text block right after a `<!-- test-day: NAME -->` line.
//! Timings (`12.3 ms`) differ from run to run and are compared as `#.# ms`. `cargo xtask docs`
//! rewrites every quote from what this test prints.

mod common;

use aer::calibration::Calibration;
use aer::calibration::xcp::CALIBRATION_ADDRESS;
use aer_raspi::commands::{self, Located, export::Wanted};
use aer_raspi::config::Origin;
use aer_raspi::store::{self, calibration, session};
use aer_raspi::xcp_gateway::record::Recorder;
use std::collections::BTreeMap;
use std::path::Path;

const DOC: &str = include_str!("../../docs/test-day.md");
const MARKER: &str = "<!-- test-day: ";

/// The bundled session's first frame: 2026-11-22T12:00:00Z.
const RUN_START_US: i64 = 1_795_348_800_000_000;
/// The LV power cycle after it, four minutes later.
const POWER_CYCLE_US: i64 = RUN_START_US + 250_000_000;
/// When the pit looks at the clock and starts the next run.
const NOW_US: i64 = RUN_START_US + 600_000_000;

const UNSYNCHRONIZED: &str = "NOT synchronized (the RTC, or the time saved at the last shutdown)";

/// The car's store after a run and a power cycle, read through a configuration as the
/// installed service's.
fn car() -> (tempfile::TempDir, Located) {
    let dir = tempfile::tempdir().expect("dir");
    let path = dir.path().join("store.sqlite");
    let db = store::open(&path).expect("store");
    let metadata = session::Metadata {
        driver: "Ana".into(),
        track: "Lot B autocross".into(),
        run: Some(3),
        notes: "dry".into(),
    };
    session::begin(&db, &metadata, "live", RUN_START_US).expect("session");
    drop(db);
    common::record_session(&path);
    let db = store::open(&path).expect("store");
    // The tuner, through the Pi's gateway: traction_kp raised while driving (accepted), the
    // launch gain refused while moving, a slip threshold past its limit refused.
    let mut gateway = Recorder::new();
    let tuner = "10.9.0.2:51234";
    let mut at = RUN_START_US + 60_000_000;
    let mut entries = gateway.found(Calibration::DEFAULT.to_page(), Some(0), at, tuner);
    for (name, value, answer) in [
        ("traction_kp", 650.0, &[0xFF][..]),
        ("launch_kp", 210.0, &[0xFE, 0x23][..]),
        ("traction_slip_threshold", 0.75, &[0xFE, 0x22][..]),
    ] {
        at += 20_000_000;
        entries.extend(write(&mut gateway, name, value, answer, at, tuner));
    }
    calibration::record(&db, 1, &entries).expect("record");
    session::begin(&db, &session::Metadata::default(), "live", POWER_CYCLE_US).expect("session");
    // After the power cycle the tuner connects again and lowers the slip threshold.
    let mut page = Calibration::DEFAULT.to_page();
    page[parameter("traction_kp").offset..][..4].copy_from_slice(&650.0f32.to_le_bytes());
    let mut gateway = Recorder::new();
    let at = POWER_CYCLE_US + 30_000_000;
    let mut entries = gateway.found(page, Some(0), at, tuner);
    entries.extend(write(
        &mut gateway,
        "traction_slip_threshold",
        0.08,
        &[0xFF],
        at + 5_000_000,
        tuner,
    ));
    calibration::record(&db, 2, &entries).expect("record");
    // What an unsynchronized Pi records, whatever this machine's clock is.
    db.execute("UPDATE sessions SET clock = ?1", [UNSYNCHRONIZED])
        .expect("clock");
    drop(db);
    // The raw log: the segment the service started at boot, before the run, holding the run.
    let raw = dir.path().join("raw");
    std::fs::create_dir(&raw).expect("raw");
    let boot = RUN_START_US - 20_000_000;
    std::fs::write(
        raw.join(format!("raw-{boot:020}.aerraw")),
        common::session_segment(),
    )
    .expect("segment");
    let config = dir.path().join("aer-raspi.toml");
    std::fs::write(
        &config,
        format!(
            "[store]\npath = {:?}\n[raw_log]\ndir = {:?}\n",
            path.display().to_string(),
            dir.path().join("raw").display().to_string()
        ),
    )
    .expect("config");
    let located = Located::load(Origin::Installed(config), |_| None).expect("config");
    (dir, located)
}

fn parameter(name: &str) -> &'static aer::calibration::Parameter {
    aer::calibration::PARAMETERS
        .iter()
        .find(|p| p.name == name)
        .expect("in the schema")
}

/// What the gateway records of a master writing `value` to `name` (SET_MTA, DOWNLOAD) and the
/// CCM answering `answer`.
fn write(
    gateway: &mut Recorder,
    name: &str,
    value: f32,
    answer: &[u8],
    at_us: i64,
    master: &str,
) -> Vec<calibration::Entry> {
    let address = CALIBRATION_ADDRESS + u32::try_from(parameter(name).offset).expect("offset");
    let mut set_mta = vec![0xF6, 0, 0, 0];
    set_mta.extend(address.to_le_bytes());
    gateway.command(&set_mta);
    gateway.answer(&[0xFF], at_us, master);
    let mut download = vec![0xF0, 4];
    download.extend(value.to_le_bytes());
    gateway.command(&download);
    gateway.answer(answer, at_us, master)
}

/// What a command printed: its output, then its notes, with the temporary folder's path
/// written as it is on the car.
fn printed(dir: &Path, run: impl FnOnce(&mut Vec<u8>, &mut Vec<u8>)) -> String {
    let (mut out, mut notes) = (Vec::new(), Vec::new());
    run(&mut out, &mut notes);
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&notes),
        String::from_utf8_lossy(&out)
    );
    let dir = dir.display().to_string();
    text.replace(&format!("{dir}/aer-raspi.toml"), "/etc/aer/aer-raspi.toml")
        .replace(&format!("{dir}/store.sqlite"), "/var/lib/aer/store.sqlite")
        .replace(&format!("{dir}/run3.tar"), "run3.tar")
        .replace(&dir, "/var/lib/aer")
}

fn examples() -> BTreeMap<&'static str, String> {
    let (dir, car) = car();
    let dir = dir.path().to_owned();
    let mut examples = BTreeMap::new();
    examples.insert(
        "clock",
        printed(&dir, |out, notes| {
            commands::clock::show(&car, NOW_US, UNSYNCHRONIZED, out, notes).expect("clock")
        }),
    );
    examples.insert(
        "session-list",
        printed(&dir, |out, notes| {
            commands::session::list(&car, out, notes).expect("list")
        }),
    );
    examples.insert(
        "session-messages",
        printed(&dir, |out, notes| {
            commands::session::messages(&car, Some(1), out, notes).expect("messages")
        }),
    );
    examples.insert(
        "session-calibration",
        printed(&dir, |out, notes| {
            commands::session::calibration(&car, Some(1), None, out, notes).expect("calibration")
        }),
    );
    examples.insert(
        "session-calibration-compare",
        printed(&dir, |out, notes| {
            commands::session::calibration(&car, Some(2), Some(1), out, notes).expect("calibration")
        }),
    );
    examples.insert(
        "export-empty",
        printed(&dir, |out, notes| {
            let wanted = Wanted {
                session: Some("2".into()),
                out: Some(dir.join("run3")),
                ..Wanted::default()
            };
            let error = commands::export::run(&car, &wanted, out, notes).expect_err("empty");
            let _ = std::io::Write::write_all(out, format!("Error: {error}\n").as_bytes());
        }),
    );
    examples.insert(
        "export-archive",
        printed(&dir, |out, notes| {
            let wanted = Wanted {
                session: Some("latest".into()),
                archive: Some(dir.join("run3.tar")),
                ..Wanted::default()
            };
            commands::export::run(&car, &wanted, out, notes).expect("archive")
        }),
    );
    let metadata = session::Metadata {
        driver: "Sam".into(),
        track: "Skidpad".into(),
        run: Some(4),
        notes: String::new(),
    };
    examples.insert(
        "session-new",
        printed(&dir, |out, notes| {
            // As on the car: the service runs, holding the store.
            let _service = aer_raspi::store::lock::take(
                &aer_raspi::store::lock::store_lock_path(car.store()),
                "the store",
                &aer_raspi::store::lock::this_process("run", NOW_US),
            )
            .expect("the service's lock");
            commands::session::new(&car, &metadata, false, NOW_US, out, notes).expect("new")
        }),
    );
    examples.insert(
        "join-script",
        std::fs::read_to_string(
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/examples/join_telemetry_can.py"),
        )
        .expect("docs/examples/join_telemetry_can.py"),
    );
    examples
}

/// Timings differ from run to run: `12.3 ms` reads `#.# ms`.
fn without_timings(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(at) = rest.find(" ms") {
        let (before, after) = rest.split_at(at);
        let number_start = before
            .rfind(|c: char| !(c.is_ascii_digit() || c == '.'))
            .map_or(0, |i| i + 1);
        let number = &before[number_start..];
        if number.contains('.') && number.chars().any(|c| c.is_ascii_digit()) {
            out.push_str(&before[..number_start]);
            out.push_str("#.#");
        } else {
            out.push_str(before);
        }
        out.push_str(" ms");
        rest = &after[3..];
    }
    out.push_str(rest);
    out
}

fn quotes() -> Vec<(String, String)> {
    let mut quotes = Vec::new();
    let mut lines = DOC.lines().enumerate();
    while let Some((number, line)) = lines.next() {
        let Some(rest) = line.trim().strip_prefix(MARKER) else {
            continue;
        };
        let name = rest.trim_end_matches("-->").trim().to_owned();
        let fence = lines.next().map(|(_, line)| line.trim().to_owned());
        assert!(
            fence.as_deref().is_some_and(|f| f.starts_with("```")),
            "docs/test-day.md:{}: `{name}` must be followed by a fenced block",
            number + 1
        );
        let mut block = String::new();
        for (_, line) in lines.by_ref() {
            if line.trim() == "```" {
                break;
            }
            block.push_str(line);
            block.push('\n');
        }
        quotes.push((name, block));
    }
    quotes
}

/// `cargo xtask docs` sets this to a file the examples are written to, to rewrite the quotes.
const EXAMPLES_FILE: &str = "AER_DOC_EXAMPLES";

#[test]
fn every_quote_in_the_test_day_runbook_is_what_the_commands_print() {
    let examples = examples();
    let quotes = quotes();
    let mut all = String::new();
    for (name, text) in &examples {
        // A quote that differs in its timings alone stays as the page has it.
        let unchanged = quotes.iter().find(|(quoted, block)| {
            quoted == name && without_timings(block) == without_timings(text)
        });
        let text = unchanged.map_or(text.as_str(), |(_, block)| block.as_str());
        all.push_str(&format!("--- test-day {name}\n{text}"));
    }
    if let Some(path) = std::env::var_os(EXAMPLES_FILE) {
        std::fs::write(&path, &all).expect("write the examples for cargo xtask docs");
    }
    let mut differ = Vec::new();
    for (name, block) in &quotes {
        let printed = examples.get(name.as_str()).unwrap_or_else(|| {
            panic!("docs/test-day.md quotes `{name}`, which no command prints here")
        });
        if without_timings(block) != without_timings(printed) {
            differ.push(format!("`{name}`, which the command prints as:\n{printed}"));
        }
    }
    assert!(
        differ.is_empty(),
        "docs/test-day.md's quotes differ from what the commands print (run `cargo xtask docs` to rewrite them all):\n{}",
        differ.join("\n")
    );
    for name in examples.keys() {
        assert!(
            quotes.iter().any(|(quoted, _)| quoted == name),
            "`{name}` is never quoted in docs/test-day.md: add its marker where it belongs, then `cargo xtask docs`"
        );
    }
}

#[test]
fn timings_are_compared_without_their_digits() {
    assert_eq!(
        without_timings("read in 163.0 ms\nParquet: 19 file(s), 846237 bytes, 12.5 ms\n"),
        "read in #.# ms\nParquet: 19 file(s), 846237 bytes, #.# ms\n"
    );
    assert_eq!(without_timings("every 10 ms"), "every 10 ms");
}
