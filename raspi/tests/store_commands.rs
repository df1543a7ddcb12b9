//! The store commands as the data team types them on a test day: without `-c` they never make
//! a store of their own, an empty session is not a successful export, the pit user reads the
//! store from a folder it cannot write, an export never mixes with an earlier one, and a
//! session leaves the car as one archive.

mod common;

use common::{Car, text};
use std::path::Path;
use std::process::Command;

#[test]
fn without_a_configuration_no_command_makes_a_store_of_its_own() {
    let dir = tempfile::tempdir().expect("dir");
    let run = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_aer-raspi"))
            .args(args)
            .current_dir(dir.path())
            .env_remove("AER_CONFIG")
            .env_remove("AER_STORE_PATH")
            // A user's mistake is explained, never answered with a stack trace.
            .env("RUST_BACKTRACE", "1")
            .output()
            .expect("aer-raspi")
    };
    for args in [
        &["session", "new", "--driver", "Ben", "--run", "4"][..],
        &["session", "list"],
        &["session", "set", "--driver", "Ben"],
        &["export", "--session", "latest", "--out", "run4"],
        &["compact"],
    ] {
        let output = run(args);
        let (_, stderr) = text(&output);
        assert!(!output.status.success(), "{args:?} succeeded");
        assert!(
            stderr.contains("no store at aer-local.sqlite")
                && stderr.contains("/etc/aer/aer-raspi.toml"),
            "{args:?}: {stderr}"
        );
        assert!(!dir.path().join("aer-local.sqlite").exists(), "{args:?}");
        assert!(!stderr.contains("acktrace"), "{args:?}: {stderr}");
        assert!(!dir.path().join("run4").exists(), "{args:?}");
    }
    let created = run(&["session", "new", "--create-store"]);
    assert!(created.status.success(), "{}", text(&created).1);
    assert!(dir.path().join("aer-local.sqlite").exists());
}

#[test]
fn latest_is_the_newest_session_with_data_and_an_empty_selection_fails() {
    let car = Car::new();
    let latest = car.run(&[
        "export",
        "--session",
        "latest",
        "--format",
        "csv",
        "--out",
        "run",
    ]);
    let (stdout, stderr) = text(&latest);
    assert!(latest.status.success(), "{stderr}");
    assert!(
        stderr.contains("session 2 (opened 1970-01-01T00:00:00.002000Z) has no rows yet: exporting session 1, the newest with data"),
        "{stderr}"
    );
    assert!(stdout.contains("exported to run"), "{stdout}");
    assert!(car.dir.path().join("run/csv/telemetry.csv").exists());

    let empty = car.run(&["export", "--session", "2", "--out", "empty"]);
    let (_, stderr) = text(&empty);
    assert!(!empty.status.success());
    assert!(
        stderr.contains("session 2 has no rows; sessions with data, newest first: 1 ("),
        "{stderr}"
    );
    assert!(!car.dir.path().join("empty").exists(), "nothing written");

    let before = car.run(&["export", "--to", "1", "--out", "before"]);
    let (_, stderr) = text(&before);
    assert!(!before.status.success());
    assert!(
        stderr.contains("nothing to export: to 1970-01-01T00:00:01.000000Z selects no rows"),
        "{stderr}"
    );

    let list = car.run(&["session", "list"]);
    let (stdout, _) = text(&list);
    assert!(list.status.success());
    let header = stdout.lines().next().expect("header");
    assert!(
        header.contains("started (UTC)") && header.contains("rows"),
        "{header}"
    );
    assert!(
        stdout
            .lines()
            .nth(2)
            .is_some_and(|l| l.starts_with("2\t") && l.contains("\t0\t")),
        "{stdout}"
    );
}

#[test]
fn an_export_never_mixes_with_an_earlier_one() {
    let car = Car::new();
    let first = car.run(&[
        "export",
        "--session",
        "1",
        "--format",
        "csv",
        "--out",
        "run",
    ]);
    assert!(first.status.success(), "{}", text(&first).1);
    let again = car.run(&[
        "export",
        "--session",
        "1",
        "--format",
        "parquet",
        "--out",
        "run",
    ]);
    let (_, stderr) = text(&again);
    assert!(!again.status.success());
    assert!(
        stderr.contains("holds an earlier export") && stderr.contains("--replace"),
        "{stderr}"
    );
    assert!(
        !car.dir.path().join("run/parquet").exists(),
        "nothing added"
    );
    let replaced = car.run(&[
        "export",
        "--session",
        "1",
        "--format",
        "parquet",
        "--out",
        "run",
        "--replace",
    ]);
    assert!(replaced.status.success(), "{}", text(&replaced).1);
    assert!(
        car.dir
            .path()
            .join("run/parquet/telemetry.parquet")
            .exists()
    );
    assert!(
        !car.dir.path().join("run/csv").exists(),
        "the earlier export went whole"
    );
}

#[test]
fn a_session_leaves_the_car_as_one_archive_with_its_raw_log() {
    let car = Car::new();
    let archive = car.run(&["export", "--session", "latest", "--archive", "-"]);
    let (_, stderr) = text(&archive);
    assert!(archive.status.success(), "{stderr}");
    let mut entries: Vec<String> = tar::Archive::new(archive.stdout.as_slice())
        .entries()
        .expect("a tar archive")
        .map(|entry| {
            entry
                .expect("entry")
                .path()
                .expect("path")
                .display()
                .to_string()
        })
        .collect();
    entries.sort();
    for wanted in [
        "session-1/session.mcap",
        "session-1/parquet/telemetry.parquet",
        "session-1/csv/telemetry.csv",
        "session-1/csv/session.csv",
        "session-1/raw/raw-00000000000000000999.aerraw",
    ] {
        assert!(
            entries.iter().any(|e| e == wanted),
            "{wanted} in {entries:?}"
        );
    }
    assert!(
        !entries
            .iter()
            .any(|e| e.ends_with("raw-00000000000000000010.aerraw")),
        "a segment that ended before the session is not the session's: {entries:?}"
    );
}

/// The pit user, in group `aer`, reads the service's 0750 folder but cannot write it: with the
/// service stopped there is no WAL index, and SQLite cannot make one there.
#[test]
fn the_pit_user_reads_the_store_from_a_folder_it_cannot_write() {
    let car = Car::new();
    let data = car.store.parent().expect("data").to_owned();
    assert!(
        !Path::new(&format!("{}-wal", car.store.display())).exists(),
        "the service stopped: no WAL"
    );
    let export_to = tempfile::tempdir().expect("out");
    let out = export_to.path().join("run");
    for path in [car.dir.path(), export_to.path()] {
        chmod(path, 0o777);
    }
    chmod(&car.store, 0o444);
    chmod(&data, 0o555);
    let as_reader = |args: &[&str]| {
        let mut command = if is_root() {
            // Root ignores permissions: run as nobody, who is held to them.
            let mut command = Command::new("setpriv");
            command.args(["--reuid=65534", "--regid=65534", "--clear-groups", "--"]);
            command.arg(env!("CARGO_BIN_EXE_aer-raspi"));
            command
        } else {
            Command::new(env!("CARGO_BIN_EXE_aer-raspi"))
        };
        command
            .arg("-c")
            .arg(&car.config)
            .args(args)
            .current_dir(export_to.path())
            .env("RUST_BACKTRACE", "0")
            .output()
            .expect("aer-raspi")
    };
    let list = as_reader(&["session", "list"]);
    let (stdout, stderr) = text(&list);
    assert!(list.status.success(), "{stderr}");
    assert!(stderr.contains("read as a still file"), "{stderr}");
    assert!(!stderr.contains("damaged"), "{stderr}");
    assert!(stdout.lines().count() == 3, "{stdout}");
    let export = as_reader(&[
        "export",
        "--session",
        "1",
        "--format",
        "csv",
        "--out",
        out.to_str().expect("path"),
    ]);
    assert!(export.status.success(), "{}", text(&export).1);
    assert!(out.join("csv/telemetry.csv").exists());
    // A reader that may not read the file is told so, and never that the store is damaged.
    chmod(&car.store, 0o000);
    let refused = as_reader(&["session", "list"]);
    let (_, stderr) = text(&refused);
    if is_root() {
        assert!(!refused.status.success());
        assert!(
            stderr.contains("cannot read the store") && !stderr.contains("damaged"),
            "{stderr}"
        );
    }
    chmod(&data, 0o755);
    chmod(&car.store, 0o644);
}

fn chmod(path: &Path, mode: u32) {
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode)).expect("chmod");
}

fn is_root() -> bool {
    Command::new("id")
        .arg("-u")
        .output()
        .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).trim() == "0")
}

/// The pit marks the end of a lap in the running session; its events list it.
#[test]
fn a_pit_mark_is_an_event_of_the_open_session() {
    let car = Car::new();
    let marked = car.run(&["session", "mark", "--at", "1764000000.5"]);
    let (stdout, stderr) = text(&marked);
    assert!(marked.status.success(), "{stderr}");
    assert!(
        stdout.contains("lap mark at 2025-11-24T16:00:00.500000Z in session 2"),
        "{stdout}"
    );
    let events = car.run(&["session", "events"]);
    let (stdout, stderr) = text(&events);
    assert!(events.status.success(), "{stderr}");
    assert!(stdout.contains("mark\tpit\tlap ends"), "{stdout}");
}

/// A store has one writer: with the demo running, a second `demo` in the same folder refuses
/// before it touches the store (naming the process that holds it), and the running session
/// stays one session with its metadata.
#[test]
fn a_second_service_on_a_running_store_refuses_and_the_first_session_stays_whole() {
    use std::io::{BufRead, BufReader};
    use std::process::Stdio;
    let dir = tempfile::tempdir().expect("dir");
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("a free port");
    let broker = dir.path().join("rumqttd.toml");
    std::fs::write(
        &broker,
        aer_raspi::broker::DEFAULT_CONFIG.replace("127.0.0.1:1883", &format!("127.0.0.1:{port}")),
    )
    .expect("broker config");
    let config = dir.path().join("aer-raspi.toml");
    std::fs::write(
        &config,
        format!("[broker]\nconfig = {:?}\n", broker.display().to_string()),
    )
    .expect("config");
    let service = |args: &[&str]| {
        let mut command = Command::new(env!("CARGO_BIN_EXE_aer-raspi"));
        command
            .arg("-c")
            .arg(&config)
            .args(args)
            .current_dir(dir.path())
            .env_remove("AER_STORE_PATH")
            .env_remove("AER_RAW_LOG_DIR")
            .env("RUST_BACKTRACE", "0");
        command
    };
    let mut first = service(&["demo", "--driver", "Ana", "--run", "3"])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("first demo");
    // The service logs to its standard output.
    let mut log = BufReader::new(first.stdout.take().expect("stdout")).lines();
    // Its announcement comes once it handles Ctrl-C, after it opened its session.
    let (mut opened, mut replaying, mut said) = (false, false, String::new());
    for line in log.by_ref().map_while(Result::ok) {
        opened |= line.contains("session open");
        said.push_str(&line);
        said.push('\n');
        if line.contains("aer-raspi demo: replaying") {
            replaying = true;
            break;
        }
    }
    // A demo that stopped (its output ended) must not leave the second one running for ever.
    assert!(opened && replaying, "the first demo did not start: {said}");
    // Keep reading its log, so it never blocks on a full pipe.
    let drain = std::thread::spawn(move || log.map_while(Result::ok).count());

    let second = service(&["demo", "--driver", "Ben"])
        .output()
        .expect("second demo");
    let (stdout, stderr) = text(&second);
    assert!(
        !second.status.success(),
        "the second demo ran: {stdout}{stderr}"
    );
    assert!(
        stderr.contains(&format!(
            "in use by another aer-raspi (pid {}, aer-raspi demo",
            first.id()
        )),
        "{stderr}"
    );
    assert!(!stdout.contains("session open"), "{stdout}");

    let stopped = Command::new("kill")
        .args(["-INT", &first.id().to_string()])
        .status()
        .expect("kill");
    assert!(stopped.success());
    assert!(first.wait().expect("first demo").success());
    drain.join().expect("log");

    let listing = service(&["session", "list", "--demo"])
        .output()
        .expect("session list");
    let (stdout, stderr) = text(&listing);
    assert!(listing.status.success(), "{stderr}");
    let sessions: Vec<&str> = stdout.lines().skip(1).collect();
    assert_eq!(sessions.len(), 1, "one session, not split: {stdout}");
    let fields: Vec<&str> = sessions[0].split('\t').collect();
    assert_eq!(fields.get(3), Some(&"demo"), "{stdout}");
    assert_eq!(fields.get(5), Some(&"Ana"), "{stdout}");
    assert_eq!(fields.get(7), Some(&"3"), "{stdout}");
    assert_ne!(
        fields.get(2),
        Some(&"open"),
        "closed when it stopped: {stdout}"
    );
}

/// A session that does not exist is named as such, whichever command and flag names it.
#[test]
fn a_missing_session_is_named_by_every_session_command() {
    let car = Car::new();
    for args in [
        &["session", "messages", "--id", "9"][..],
        &["session", "events", "--id", "9"],
        &["session", "calibration", "--id", "9"],
        &["session", "calibration", "--id", "1", "--compare", "9"],
    ] {
        let output = car.run(args);
        let (stdout, stderr) = text(&output);
        assert!(!output.status.success(), "{args:?}: {stdout}");
        assert!(
            stderr.contains("no session 9 in the store"),
            "{args:?}: {stderr}"
        );
        assert!(stdout.is_empty(), "{args:?} printed a table: {stdout}");
    }
}
