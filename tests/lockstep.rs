//! A tier that was not updated after a schema change fails to compile instead of mis-decoding:
//! a new telemetry field must be filled by the firmware (on a copy of the repository, so the
//! test holds whatever fields the live schema has), a topic only takes its own payload type,
//! and code using a removed signal stops building. (`TRYBUILD=overwrite` refreshes the expected
//! compiler output after an intended change.)

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

#[test]
fn stale_code_does_not_compile() {
    let cases = trybuild::TestCases::new();
    cases.compile_fail("tests/compile_fail/*.rs");
}

/// A new field the CCM must measure itself, appended to the schema's field list.
const OWN_FIELD: &str = "
  - name: lockstep_measured
    group: chassis
    label: Lockstep measured
    type: i16
    scale: 0.1
    unit: deg
    min: -180
    max: 180
    description: Steering wheel angle, positive to the left.";

/// A new field that mirrors a DBC signal: generated code fills it, the CCM needs no change.
const MIRRORED_FIELD: &str = "
  - name: lockstep_mirrored
    group: motor
    label: Lockstep mirrored
    signal: MCU1.MCU_MaxMotorBrakeTorque";

/// A new field mirroring a message the CCM sends itself: the CCM hears no frame of its own, so
/// only the message it passes to `from_parts` can fill it.
const SENT_FIELD: &str = "
  - name: lockstep_sent
    group: chassis
    label: Lockstep sent
    signal: CCM_LockstepProbe.CCM_LockstepValue";

/// The message that field mirrors, new in the DBC, sent by the CCM on the vehicle bus.
/// (Its id is the first of these the DBC does not use: the test must hold whatever the team
/// adds.)
const SENT_MESSAGE: &str = "BO_ {id} CCM_LockstepProbe: 2 CCM
 SG_ CCM_LockstepValue : 0|16@1+ (0.01,0) [0|100] \"mm\" RASPI

";
const FREE_IDS: [u32; 4] = [0x7E5, 0x7E6, 0x7E7, 0x7E8];

/// The promise made to a new team member, on a copy of this repository: add a telemetry field
/// to the schema and the CCM firmware crate stops building, naming the field (or the message
/// the CCM must pass as it sends it), until the CCM fills it; a field mirrored from a message
/// another node sends is filled by generated code and needs nothing.
#[test]
fn a_new_telemetry_field_fails_the_ccm_build_until_the_ccm_fills_it() {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    let copy = tempfile::tempdir().expect("temporary directory");
    copy_tracked_files(repo, copy.path());

    let schema = copy.path().join("schema/telemetry.yaml");
    let text = std::fs::read_to_string(&schema).expect("telemetry.yaml");
    let text = text.replacen(
        "\nfields:",
        &format!("\nfields:{OWN_FIELD}{MIRRORED_FIELD}{SENT_FIELD}"),
        1,
    );
    std::fs::write(&schema, text).expect("write telemetry.yaml");
    let dbc = copy.path().join("schema/aer.dbc");
    let text = std::fs::read_to_string(&dbc).expect("aer.dbc");
    assert!(text.contains("BO_ 161 "), "the DBC has CCM_Calibration");
    let id = FREE_IDS
        .into_iter()
        .find(|id| !text.contains(&format!("BO_ {id} ")))
        .expect("a free id for the probe message");
    let message = SENT_MESSAGE.replace("{id}", &id.to_string());
    let text = text
        .replacen("BO_ 161 ", &format!("{message}BO_ 161 "), 1)
        .replacen(
            "BA_ \"AerBus\" BO_ 161 ",
            &format!("BA_ \"AerBus\" BO_ {id} \"vehicle\";\nBA_ \"AerBus\" BO_ 161 "),
            1,
        );
    std::fs::write(&dbc, text).expect("write aer.dbc");

    let unfilled = check_ccm(copy.path());
    let stderr = String::from_utf8_lossy(&unfilled.stderr);
    assert!(
        !unfilled.status.success(),
        "the CCM built with an unfilled field:\n{stderr}"
    );
    assert!(
        stderr.contains("missing field `lockstep_measured` in initializer of `TelemetryOwnFields`"),
        "the error names the new field:\n{stderr}"
    );
    assert!(
        stderr.contains("missing field `ccm_lockstep_probe` in initializer of `TelemetrySent`"),
        "the error names the message the CCM sends that the new mirrored field needs:\n{stderr}"
    );
    assert!(
        stderr.contains("ccm/src/control.rs"),
        "in the CCM's snapshot:\n{stderr}"
    );
    assert!(
        !stderr.contains("lockstep_mirrored"),
        "a mirrored field needs no code in the CCM:\n{stderr}"
    );

    let control = copy.path().join("ccm/src/control.rs");
    let code = std::fs::read_to_string(&control).expect("control.rs");
    assert!(
        code.contains("shocktravel4: rr,"),
        "the snapshot fills shocktravel4"
    );
    assert!(
        code.contains("ccm_status: self.status(),"),
        "the snapshot passes the CCM_Status it sends"
    );
    let code = code
        .replacen(
            "shocktravel4: rr,",
            "shocktravel4: rr,\n                lockstep_measured: 0.0,",
            1,
        )
        .replacen(
            "ccm_status: self.status(),",
            "ccm_status: self.status(),\n                ccm_lockstep_probe: aer::can::CcmLockstepProbe { ccm_lockstep_value: 0.0 },",
            1,
        );
    std::fs::write(&control, code).expect("write control.rs");
    let filled = check_ccm(copy.path());
    assert!(
        filled.status.success(),
        "the CCM builds once it fills the field:\n{}",
        String::from_utf8_lossy(&filled.stderr)
    );
}

/// `cargo check` of the CCM library alone (as the firmware build resolves its features), in a
/// target directory of its own that later runs reuse.
fn check_ccm(workspace: &Path) -> Output {
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    Command::new(cargo)
        .args([
            "check",
            "--quiet",
            "--offline",
            "--locked",
            "-p",
            "aer-ccm",
            "--lib",
        ])
        .current_dir(workspace)
        .env("CARGO_TARGET_DIR", target_dir().join("lockstep"))
        .env_remove("RUSTFLAGS")
        .output()
        .expect("run cargo")
}

fn target_dir() -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("target"))
}

/// Copies the files git tracks, as they are in the working tree.
fn copy_tracked_files(repo: &Path, to: &Path) {
    let listed = Command::new("git")
        .args(["ls-files", "-z"])
        .current_dir(repo)
        .output()
        .expect("run git ls-files");
    assert!(listed.status.success(), "git ls-files failed");
    for name in listed.stdout.split(|&b| b == 0).filter(|n| !n.is_empty()) {
        let name = std::str::from_utf8(name).expect("UTF-8 path");
        let from = repo.join(name);
        if !from.is_file() {
            continue; // deleted in the working tree
        }
        let dest = to.join(name);
        std::fs::create_dir_all(dest.parent().expect("a file has a parent")).expect("mkdir");
        std::fs::copy(&from, &dest).expect("copy a tracked file");
    }
}
