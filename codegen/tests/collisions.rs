//! Names from a vendor's DBC that meet once converted to Rust (value tables, messages and
//! signals whose names differ only in case or underscores, a message named like an enum, names
//! the generated code uses itself, keywords, a field that meets another's raw-bits local) are
//! renamed deterministically, each rename is a W0204 naming what was renamed, and the crate
//! builds with warnings denied and decodes with the right types.

use std::path::Path;
use std::process::{Command, Stdio};

use std::io::Write as _;

fn dbc() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/dbc/collisions.dbc")
}

#[test]
fn every_rename_is_reported_and_the_same_each_time() {
    let (db, warnings) = aer_codegen::load_dbc(&dbc()).expect("loads");
    let renamed: Vec<&str> = warnings
        .iter()
        .filter(|w| w.code == "W0204")
        .map(|w| w.message.as_str())
        .collect();
    for expected in [
        "value table `GearState` would be the Rust type `GearState`, a name already taken (line 10); it is `GearState2`",
        "value table `gear_state` would be the Rust type `GearState`, a name already taken (line 10); it is `GearState3`",
        "value table `Value` would be the Rust type `Value`, a name the generated code uses itself; it is `Value2`",
        "signal `speed` would be the Rust field `speed`, but signal `Speed` (line 17) already takes it; it is `speed2`",
        "signal `SPEED_` would be the Rust field `speed`, but signal `Speed` (line 17) already takes it; it is `speed3`",
        "signal `ts` would be the Rust field `ts`, but the store reserves it for its own column; it is `ts2`",
        "signal `Gear` would be the Rust field `gear`, but signal `Gear_bits` (line 23) already takes it; it is `gear2`",
        "message `EngineData` would be the Rust type `EngineData`, a name already taken (line 16); it is `EngineData0x101`",
        "message `Status` would be the Rust type `Status`, a name already taken (line 13); it is `Status0x102`",
        "signal `Mode_bits` would be the Rust field `mode_bits`, but signal `Mode` (line 30) already takes it; it is `mode_bits2`",
        "message `Result` would be the Rust type `Result`, a name the generated code uses itself; it is `Result0x103`",
        "the enum of signal `X` of message `AbC` would be the Rust type `AbCX`, a name already taken (line 51); it is `AbCX2`",
    ] {
        assert!(
            renamed.contains(&expected),
            "missing: {expected}\nin {renamed:#?}"
        );
    }
    assert_eq!(renamed.len(), 12, "{renamed:#?}");
    // Deterministic: the same file gives the same names.
    let (again, _) = aer_codegen::load_dbc(&dbc()).expect("loads");
    assert_eq!(db, again);
    // Each value list keeps the table with its own values (it once took the first table whose
    // name met, with other labels).
    let gear = |message: &str| {
        let m = db
            .messages
            .iter()
            .find(|m| m.name == message)
            .expect("message");
        let s = m.signals.iter().find(|s| s.name == "Gear").expect("Gear");
        match s.phys {
            aer_codegen::model::PhysType::Enum(i) => db.enums[i].type_name.clone(),
            other => panic!("Gear is {other:?}"),
        }
    };
    assert_eq!(gear("Engine_Data"), "GearState");
    assert_eq!(gear("EngineData"), "GearState2");
    let items: std::collections::HashSet<&str> =
        db.messages.iter().map(|m| m.item_name.as_str()).collect();
    assert_eq!(
        items.len(),
        db.messages.len(),
        "table and topic names are unique"
    );
}

#[test]
fn the_crate_builds_with_warnings_denied_and_decodes() {
    let root = Path::new(env!("CARGO_TARGET_TMPDIR")).join("collisions_can");
    aer_codegen::generate_crate(&dbc(), &root, &aer_codegen::CrateOptions::default())
        .expect("generates");
    let code = std::fs::read_to_string(root.join("src/can.rs")).expect("can.rs");
    assert!(
        code.contains("pub fn type_from_raw(raw: u8) -> u8"),
        "no `type__from_raw`"
    );
    let target = Path::new(env!("CARGO_TARGET_TMPDIR")).join("collisions_can_target");
    let status = Command::new(env!("CARGO"))
        .args(["build", "--quiet", "--examples", "--features", "serde"])
        .current_dir(&root)
        .env("CARGO_TARGET_DIR", &target)
        .env("RUSTFLAGS", "-D warnings")
        .status()
        .expect("run cargo");
    assert!(
        status.success(),
        "the generated crate must build without warnings"
    );
    let mut child = Command::new(target.join("debug/examples/decode"))
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .expect("decode example");
    child
        .stdin
        .take()
        .expect("stdin")
        .write_all(b"(0.000000) can0 100#0102030405060708\n(0.000000) can0 101#0200000000000000\n")
        .expect("write");
    let out = child.wait_with_output().expect("output");
    let text = String::from_utf8(out.stdout).expect("UTF-8");
    assert!(
        text.contains(r#""signals": {"Speed": 1, "speed": 2, "SPEED_": 3, "type": 4, "match": 0, "ts": 5, "Gear_bits": 6, "Gear": 3}"#),
        "{text}"
    );
    assert!(
        text.contains(r#""name": "EngineData", "signals": {"Gear": 2}"#),
        "{text}"
    );
}
