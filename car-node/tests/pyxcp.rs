//! The CCM's XCP slave proven with a master no one on the team wrote: pyxcp (PyPI) plays
//! `tools/xcp_scenarios.py` over XCP on TCP against the slave in the closed-loop car model,
//! the same slave core the firmware serves on CAN (the virtual Pi plays the same scenarios
//! over XCP on CAN on a vcan, `tools/virtual_pi.sh`).
//!
//! Needs the venv's Python with pyxcp (`.ci/run` installs it); without it the test says
//! SKIPPED, unless `AER_REQUIRE_PYTHON` is set (CI sets it), when it fails.
//!
//! pyxcp also unlocks by itself through the team's seed-and-key library (`xcp-seedkey/`, the
//! Linux .so its `seed_n_key_dll` option names), against the desk server (`aer-car-node
//! serve`): see [`pyxcp_unlocks_through_the_seed_and_key_library`].

use aer_car_model::driver::Cycle;
use aer_car_node::link::TcpLink;
use aer_car_node::{checks, expected, masters, scenarios, serve};
use serde_json::Value;
use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The venv's Python (or `AER_PYTHON`), when it imports pyxcp and pya2ldb.
fn python() -> Option<PathBuf> {
    let venv = root().join(".venv/bin/python");
    let python = std::env::var_os("AER_PYTHON").map_or(venv, PathBuf::from);
    let usable = Command::new(&python)
        .args(["-c", "import pyxcp, pya2l"])
        .output()
        .is_ok_and(|o| o.status.success());
    if usable {
        return Some(python);
    }
    assert!(
        std::env::var_os("AER_REQUIRE_PYTHON").is_none(),
        "AER_REQUIRE_PYTHON is set but {} cannot import pyxcp",
        python.display()
    );
    eprintln!(
        "SKIPPED: the pyxcp scenarios need {} with pyxcp \
         (python3 -m venv .venv && .venv/bin/pip install -r tools/requirements.txt)",
        python.display()
    );
    None
}

#[test]
fn pyxcp_calibrates_and_measures_the_ccm_in_the_car_model() {
    let Some(python) = python() else {
        return;
    };
    let mut link = TcpLink::bind("127.0.0.1:0".parse().unwrap()).unwrap();
    let script = scenarios::in_checkout(&root(), python);
    let outcome = scenarios::play(&mut link, &script).unwrap();
    let verdicts = checks::judge(&outcome);
    for verdict in &verdicts {
        eprintln!("{verdict}");
    }
    assert!(verdicts.len() >= 20, "{} checks", verdicts.len());
    let failed = checks::failed(&verdicts);
    assert!(failed.is_empty(), "{failed:#?}");
}

/// The seed-and-key library pyxcp loads: `AER_XCP_SEEDKEY_LIBRARY` when set (a library built
/// beforehand), else the one `cargo build -p aer-xcp-seedkey` leaves. A test has no stable way
/// to depend on another package's cdylib (artifact dependencies are unstable; the copy a
/// dependency's build leaves in `deps/` is Cargo's internal layout), so this asks Cargo, which
/// builds it if it is stale (a few seconds, once) and names the file in its JSON messages,
/// wherever the target directory is. The outer `cargo test` holds no build lock while tests
/// run.
fn seed_key_library() -> PathBuf {
    if let Some(path) = std::env::var_os("AER_XCP_SEEDKEY_LIBRARY") {
        return PathBuf::from(path);
    }
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| env!("CARGO").into());
    let output = Command::new(cargo)
        .current_dir(root())
        .args([
            "build",
            "-p",
            "aer-xcp-seedkey",
            "--lib",
            "--message-format=json",
        ])
        .stderr(Stdio::inherit())
        .output()
        .expect("running cargo");
    assert!(
        output.status.success(),
        "cargo build -p aer-xcp-seedkey failed: {}",
        output.status
    );
    let name = format!(
        "{}aer_xcp_seedkey{}",
        std::env::consts::DLL_PREFIX,
        std::env::consts::DLL_SUFFIX
    );
    String::from_utf8_lossy(&output.stdout)
        .lines()
        .filter_map(|line| serde_json::from_str::<Value>(line).ok())
        .filter(|message| message["reason"] == "compiler-artifact")
        .flat_map(|message| message["filenames"].as_array().cloned().unwrap_or_default())
        .filter_map(|file| file.as_str().map(PathBuf::from))
        .find(|file| file.file_name().is_some_and(|n| *n == *name))
        .unwrap_or_else(|| panic!("cargo named no {name} among the artifacts it built"))
}

/// pyxcp unlocks calibration by itself through the team's seed-and-key library, installed as
/// docs/calibration.md tells a tuner (the library with `aer-xcp-secret.key` beside it), both
/// ways pyxcp calls it: in its `asamkeydll` helper program (the default) and loaded into
/// Python with ctypes (`seed_n_key_dll_same_bit_width`). Against the desk server: a write is
/// refused while locked, then accepted after pyxcp's unlock, and reads back.
#[test]
fn pyxcp_unlocks_through_the_seed_and_key_library() {
    let Some(python) = python() else {
        return;
    };
    let built = seed_key_library();
    let dir = tempfile::tempdir().unwrap();
    let library = dir
        .path()
        .join(built.file_name().expect("the library's file name"));
    std::fs::copy(&built, &library).unwrap();
    let secret: String = scenarios::SECRET
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect();
    std::fs::write(dir.path().join("aer-xcp-secret.key"), format!("{secret}\n")).unwrap();
    let description = expected::description(&root().join("generated/aer.a2l"));
    let default = description["parameters"]
        .as_array()
        .into_iter()
        .flatten()
        .find(|p| p["name"] == "traction_kp")
        .map(|p| p["defaults"][0].clone())
        .expect("traction_kp in the description");
    let expected = dir.path().join("expected.json");
    std::fs::write(&expected, description.to_string()).unwrap();

    for (how, same_bit_width) in [("asamkeydll helper", false), ("ctypes", true)] {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let address = listener.local_addr().unwrap();
        let transport = masters::listen(listener).unwrap();
        let mut command = Command::new(&python);
        command
            .arg(root().join("tools/xcp_scenarios.py"))
            .arg("--seed-key-library")
            .arg(&library);
        if same_bit_width {
            command.arg("--same-bit-width");
        }
        let script = command
            .env("AER_XCP_TRANSPORT", "tcp")
            .env("AER_XCP_HOST", address.ip().to_string())
            .env("AER_XCP_PORT", address.port().to_string())
            .env("AER_XCP_EXPECTED", &expected)
            .env_remove("AER_XCP_SECRET_FILE")
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .unwrap();
        let finished = Arc::new(AtomicBool::new(false));
        let waiter = {
            let finished = Arc::clone(&finished);
            std::thread::spawn(move || {
                let output = script.wait_with_output();
                finished.store(true, Ordering::Release);
                output
            })
        };
        // The desk server, in real time, until the script has ended (or a minute has passed).
        let ran = serve::serve(
            &transport,
            Cycle::Acceleration,
            Some(scenarios::SECRET),
            &[0x5E; 32],
            |ms| ms < 60_000 && !finished.load(Ordering::Acquire),
        )
        .unwrap();
        assert!(
            finished.load(Ordering::Acquire),
            "{how}: the script still ran after {} ms",
            ran.model_ms
        );
        let output = waiter.join().unwrap().unwrap();
        assert!(
            output.status.success(),
            "{how}: the script failed: {}",
            output.status
        );
        let stdout = String::from_utf8_lossy(&output.stdout);
        let outcome: Value = serde_json::from_str(stdout.trim())
            .unwrap_or_else(|e| panic!("{how}: the script printed {stdout:?}: {e}"));
        eprintln!("{how}: {outcome}");
        assert_eq!(
            outcome["locked_before"], true,
            "{how}: locked after CONNECT"
        );
        assert_eq!(
            outcome["locked_write"], 0x25,
            "{how}: a write before unlocking is ERR_ACCESS_LOCKED"
        );
        assert_eq!(
            outcome["unlock_error"],
            Value::Null,
            "{how}: pyxcp's unlock through the library"
        );
        assert_eq!(outcome["unlocked"], true, "{how}: unlocked afterwards");
        assert_eq!(outcome["write"], Value::Null, "{how}: the write accepted");
        assert_eq!(
            outcome["read_back"], outcome["value"],
            "{how}: the value written reads back"
        );
        assert_ne!(
            outcome["value"], default,
            "{how}: the value written is not the default"
        );
    }
}

/// docs/examples/tune_desk_car.py, the guide's first session, as a tuner runs it against the
/// desk car: it unlocks through the library, sees a refusal's reason read from the slave's
/// status block, and writes an allowed value.
#[test]
fn the_guides_first_session_runs_against_the_desk_car() {
    let Some(python) = python() else {
        return;
    };
    let built = seed_key_library();
    let dir = tempfile::tempdir().unwrap();
    let library = dir.path().join(built.file_name().expect("a file name"));
    std::fs::copy(&built, &library).unwrap();
    let secret: String = scenarios::SECRET
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect();
    std::fs::write(dir.path().join("aer-xcp-secret.key"), format!("{secret}\n")).unwrap();
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let address = listener.local_addr().unwrap();
    let transport = masters::listen(listener).unwrap();
    let script = Command::new(&python)
        .current_dir(root())
        .arg("docs/examples/tune_desk_car.py")
        .arg("--library")
        .arg(&library)
        .arg("--port")
        .arg(address.port().to_string())
        .env_remove("AER_XCP_SECRET_FILE")
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .unwrap();
    let finished = Arc::new(AtomicBool::new(false));
    let waiter = {
        let finished = Arc::clone(&finished);
        std::thread::spawn(move || {
            let output = script.wait_with_output();
            finished.store(true, Ordering::Release);
            output
        })
    };
    serve::serve(
        &transport,
        Cycle::Practice,
        Some(scenarios::SECRET),
        &[0x5E; 32],
        |ms| ms < 60_000 && !finished.load(Ordering::Acquire),
    )
    .unwrap();
    let output = waiter.join().unwrap().unwrap();
    let stdout = String::from_utf8_lossy(&output.stdout);
    eprintln!("{stdout}");
    assert!(output.status.success(), "{}", output.status);
    for line in [
        "calibration unlocked",
        "refused as expected: DOWNLOAD refused with ERR_OUT_OF_RANGE: traction_kp[0] = 2001, \
         above its maximum (limit 2000)",
        "traction_kp = ",
        "slave counters: commands ",
    ] {
        assert!(stdout.contains(line), "{line:?} not in:\n{stdout}");
    }
}
