//! `aer-codegen crate` end to end: generate a crate for the project's tricky DBC (1-bit signed,
//! odd Motorola widths, 64-bit, IEEE float/double, f32 physical values, simple and cascaded
//! extended multiplexing, 29-bit ids, a 64-byte CAN FD frame), build it with its `decode` and
//! `encode` examples, and replay cantools' vectors through them.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::OnceLock;

use aer_codegen::model::PhysType;
use serde_json::Value as Json;

fn manifest_dir() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// A user's program for a vendor's scaled signals with a "255 = SNA" sentinel (Tesla's pedal,
/// for one): the value is the physical number, as cantools decodes it, the names are recognised,
/// and an unnamed value out of range is refused as out of range. It runs when the crate is built.
const SENTINELS: &str = r#"
use tricky_can::can::Sentinels;
use tricky_can::runtime::EncodeError;

fn main() {
    let pedal = Sentinels::decode(&[100, 60]).expect("decodes");
    assert_eq!(pedal.pedal_position, 40.0, "40 %, not Unknown(100)");
    assert_eq!(pedal.temperature, 20);
    assert_eq!(Sentinels::pedal_position_label(pedal.pedal_position), None);
    let sna = Sentinels::decode(&[255, 255]).expect("decodes");
    assert_eq!(Sentinels::pedal_position_label(sna.pedal_position), Some("SNA"));
    assert_eq!(Sentinels::temperature_label(sna.temperature), Some("SNA"));
    let mut out = [0u8; 2];
    // A named value encodes whatever the range says (as in cantools); 140 % is out of range.
    assert_eq!(sna.encode(&mut out), Ok(2));
    assert_eq!(out, [255, 255]);
    let too_far = Sentinels { pedal_position: 140.0, temperature: 20 };
    assert_eq!(
        too_far.encode(&mut out),
        Err(EncodeError::OutOfRange { message: "Sentinels", signal: "PedalPosition" })
    );
}
"#;

/// Generates and builds the crate once per test run (running the sentinels example); returns
/// the decode and encode example binaries.
fn examples() -> &'static (PathBuf, PathBuf) {
    static BUILT: OnceLock<(PathBuf, PathBuf)> = OnceLock::new();
    BUILT.get_or_init(|| {
        let root = Path::new(env!("CARGO_TARGET_TMPDIR")).join("tricky_can");
        let dbc = manifest_dir().join("tests/dbc/tricky.dbc");
        aer_codegen::generate_crate(&dbc, &root, &aer_codegen::CrateOptions::default())
            .expect("tricky.dbc generates");
        std::fs::write(root.join("examples/sentinels.rs"), SENTINELS).expect("write example");
        let target = Path::new(env!("CARGO_TARGET_TMPDIR")).join("tricky_can_target");
        let status = Command::new(env!("CARGO"))
            // The optional serde derives must compile too (multiplexed Options, enums, i128).
            .args(["build", "--quiet", "--examples", "--features", "serde"])
            .current_dir(&root)
            .env("CARGO_TARGET_DIR", &target)
            .status()
            .expect("run cargo");
        assert!(status.success(), "the generated crate must build");
        let bin = |name: &str| target.join("debug/examples").join(name);
        let sentinels = Command::new(bin("sentinels"))
            .output()
            .expect("run sentinels");
        assert!(
            sentinels.status.success(),
            "{}",
            String::from_utf8_lossy(&sentinels.stderr)
        );
        (bin("decode"), bin("encode"))
    })
}

fn run(exe: &Path, input: &str) -> Vec<String> {
    let mut child = Command::new(exe)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .expect("start example");
    child
        .stdin
        .take()
        .expect("stdin")
        .write_all(input.as_bytes())
        .expect("write stdin");
    let out = child.wait_with_output().expect("example output");
    assert!(out.status.success());
    String::from_utf8(out.stdout)
        .expect("UTF-8 output")
        .lines()
        .map(str::to_owned)
        .collect()
}

fn vectors() -> Vec<Json> {
    include_str!("vectors/tricky.jsonl")
        .lines()
        .map(|l| serde_json::from_str(l).expect("JSON"))
        .collect()
}

fn candump(v: &Json) -> String {
    let id = v["id"].as_u64().expect("id");
    let data = v["data"].as_str().expect("data").to_uppercase();
    let ident = if v["extended"] == Json::Bool(true) {
        format!("{id:08X}")
    } else {
        format!("{id:03X}")
    };
    let sep = if data.len() > 16 { "##0" } else { "#" };
    format!("(1700000000.000001) can0 {ident}{sep}{data}")
}

/// How far an `f32` physical value may be from cantools' `f64` one.
#[derive(Debug, Clone, Copy)]
enum Tolerance {
    /// An integer on the wire: half a raw step.
    HalfStep(f64),
    /// An IEEE float on the wire, scaled: `f32` rounding, relative to the value.
    F32Rounding,
}

impl Tolerance {
    fn allows(self, want: f64, got: f64) -> bool {
        let limit = match self {
            Tolerance::HalfStep(t) => t,
            // Two f32 roundings (raw, then physical) of at most 2^-24 each.
            Tolerance::F32Rounding => want.abs() * 2f64.powi(-23),
        };
        (want - got).abs() <= limit
    }
}

/// Per (message, signal), for signals the schema asks to hold in `f32`.
fn f32_tolerances() -> BTreeMap<(String, String), Tolerance> {
    let (db, _) =
        aer_codegen::load_dbc(&manifest_dir().join("tests/dbc/tricky.dbc")).expect("loads");
    db.messages
        .iter()
        .flat_map(|m| {
            m.signals
                .iter()
                .filter(|s| s.phys == PhysType::F32)
                .map(|s| {
                    let tolerance = if s.is_float_raw() {
                        Tolerance::F32Rounding
                    } else {
                        Tolerance::HalfStep(s.factor.abs() / 2.0)
                    };
                    ((m.name.clone(), s.name.clone()), tolerance)
                })
        })
        .collect()
}

/// Asserts that our decoded `got` signals are cantools' `want`, within `f32` tolerances.
fn assert_signals_agree(
    name: &str,
    want: &serde_json::Map<String, Json>,
    got: &serde_json::Map<String, Json>,
    tolerance: &BTreeMap<(String, String), Tolerance>,
    context: &str,
) {
    assert_eq!(
        want.keys().collect::<Vec<_>>(),
        got.keys().collect::<Vec<_>>(),
        "{name}: {context}"
    );
    for (sig, w) in want {
        let g = &got[sig];
        match tolerance.get(&(name.to_owned(), sig.clone())) {
            Some(tol) => {
                let (w, g) = (w.as_f64().expect("num"), g.as_f64().expect("num"));
                assert!(tol.allows(w, g), "{name}.{sig}: cantools {w}, ours {g}");
            }
            None => assert_eq!(w.as_f64(), g.as_f64(), "{name}.{sig} in {context}"),
        }
    }
}

#[test]
fn decode_example_agrees_with_cantools() {
    let (decode, _) = examples();
    let vectors = vectors();
    let input: String = vectors.iter().map(|v| candump(v) + "\n").collect();
    let lines = run(decode, &input);
    assert_eq!(lines.len(), vectors.len(), "one output line per input line");
    let tolerance = f32_tolerances();
    assert!(!tolerance.is_empty());
    for (v, line) in vectors.iter().zip(&lines) {
        let got: Json = serde_json::from_str(line).expect("decode prints JSON");
        let name = v["name"].as_str().expect("name");
        assert_eq!(got["name"], v["name"], "{line}");
        assert_eq!(got["t"].as_f64(), Some(1_700_000_000.000_001));
        assert_signals_agree(
            name,
            v["signals"].as_object().expect("obj"),
            got["signals"].as_object().expect("obj"),
            &tolerance,
            line,
        );
    }
}

#[test]
fn encode_example_agrees_with_cantools() {
    let (_, encode) = examples();
    let vectors = vectors();
    let input: String = vectors
        .iter()
        .map(|v| {
            serde_json::json!({"id": v["id"], "extended": v["extended"], "signals": v["signals"]})
                .to_string()
                + "\n"
        })
        .collect();
    let lines = run(encode, &input);
    assert_eq!(lines.len(), vectors.len());
    let tolerance = f32_tolerances();
    // An `f32` physical value of an IEEE float signal cannot hold cantools' `f64` input, so
    // those frames differ in the last bits: they are decoded again and compared by value.
    let rounded: Vec<&str> = tolerance
        .iter()
        .filter(|(_, t)| matches!(t, Tolerance::F32Rounding))
        .map(|((message, _), _)| message.as_str())
        .collect();
    let (mut compared, mut refused) = (0, 0);
    let mut by_value = Vec::new();
    for (v, line) in vectors.iter().zip(&lines) {
        let name = v["name"].as_str().expect("name");
        match v["encoded"].as_str() {
            Some(_) if rounded.contains(&name) => {
                assert!(line.starts_with("(0.000000) can0 "), "{line} for {v}");
                by_value.push((v, line.replacen("(0.000000)", "(1700000000.000001)", 1)));
            }
            Some(hex) => {
                let want = candump(
                    &serde_json::json!({"id": v["id"], "extended": v["extended"], "data": hex}),
                );
                let want = want.split_once(' ').expect("space").1;
                assert_eq!(line.split_once(' ').map(|x| x.1), Some(want), "{v}");
                assert!(line.starts_with("(0.000000) can0 "));
                compared += 1;
            }
            None => {
                assert!(
                    line.starts_with("{\"error\""),
                    "cantools refused, ours gave {line} for {v}"
                );
                refused += 1;
            }
        }
    }
    assert!(
        compared > 500 && refused > 0 && !by_value.is_empty(),
        "{compared} compared, {refused} refused, {} by value",
        by_value.len()
    );
    let input: String = by_value
        .iter()
        .map(|(_, line)| format!("{line}\n"))
        .collect();
    let decoded = run(examples().0.as_path(), &input);
    assert_eq!(decoded.len(), by_value.len());
    for ((v, _), line) in by_value.iter().zip(&decoded) {
        let got: Json = serde_json::from_str(line).expect("decode prints JSON");
        assert_signals_agree(
            v["name"].as_str().expect("name"),
            v["signals"].as_object().expect("obj"),
            got["signals"].as_object().expect("obj"),
            &tolerance,
            line,
        );
    }
}

#[test]
fn bad_candump_lines_give_one_error_line_each() {
    let (decode, _) = examples();
    let input = [
        "",
        "garbage",
        "(1700000000.5) can0 100",
        "(1700000000.5) can0 1000#00",
        "(1700000000.5) can0 800#00",
        "(1700000000.5) can0 7FF#0011",
        "(1700000000.5) can0 100#0",
        "(1700000000.5) can0 100#R",
        "(1700000000.5) can0 100#00",
        "(170000x000.5) can0 100#0000000000000000",
        "(1700000000.5) can0 108##1",
    ]
    .join("\n");
    let lines = run(decode, &(input + "\n"));
    assert_eq!(lines.len(), 11);
    let errors: Vec<String> = lines
        .iter()
        .map(|l| {
            let j: Json = serde_json::from_str(l).unwrap_or_else(|e| panic!("{l}: {e}"));
            j["error"]
                .as_str()
                .unwrap_or_else(|| panic!("not an error: {l}"))
                .to_owned()
        })
        .collect();
    assert!(
        errors[3].contains("3 (standard) or 8 (extended)"),
        "{errors:?}"
    );
    assert!(errors[4].contains("not a valid CAN id"), "{errors:?}");
    assert!(
        errors[5].contains("unknown standard id 0x7FF"),
        "{errors:?}"
    );
    assert!(errors[7].contains("remote frame"), "{errors:?}");
    assert!(
        errors[8].contains("payload is 1 bytes, the message needs 8"),
        "{errors:?}"
    );
    let short: Json = serde_json::from_str(&lines[8]).expect("json");
    assert_eq!(short["id"], 256);
    assert_eq!(short["t"].as_f64(), Some(1_700_000_000.5));
}

#[test]
fn bad_json_lines_give_one_error_line_each() {
    let (_, encode) = examples();
    let input = [
        "not json",
        r#"{"id": 999}"#,
        r#"{"id": 262, "signals": {"Mux": 0, "Always": 1}}"#,
        r#"{"id": 262, "signals": {"Mux": 0, "PageA": 1.0, "PageB": 3, "Always": 1}}"#,
        r#"{"id": 262, "signals": {"Mux": 0, "PageA": 1.0, "Always": 1, "Typo": 1}}"#,
        r#"{"id": 256, "signals": {"OneBitSignedIntel": 1, "OneBitSignedMoto": 0, "OddSignedMoto": 0, "OddUnsignedIntel": 0, "ScaledInt": 0, "NegativeScale": 0, "type": 0}}"#,
        r#"{"id": 262, "signals": {"Mux": "PAGE_B", "PageB": -5, "Always": 255}}"#,
    ]
    .join("\n");
    let lines = run(encode, &(input + "\n"));
    assert_eq!(lines.len(), 7);
    assert!(lines[0].contains("invalid JSON"), "{lines:?}");
    assert!(lines[1].contains("no message has id 999"), "{lines:?}");
    assert!(
        lines[2].contains("SimpleMux.PageA: value missing"),
        "{lines:?}"
    );
    assert!(
        lines[3].contains("SimpleMux.PageB: set, but its multiplexor selects other signals"),
        "{lines:?}"
    );
    assert!(lines[4].contains("no signal `Typo`"), "{lines:?}");
    // A 1-bit signed signal holds 0 and -1 only.
    assert!(
        lines[5].contains("Widths.OneBitSignedIntel: value out of range"),
        "{lines:?}"
    );
    // Enum values by name; -5 as 24-bit two's complement, Motorola from bit 0 of byte 1
    // (the frame cantools encodes for the same values).
    assert_eq!(lines[6], "(0.000000) can0 106#0101FFFFF60000FF");
}

/// A vendor's file with known defects (overlapping signals, a 29-bit id without the extended
/// flag): refused by default, generated with `--allow`, each defect reported as a warning that
/// says how it is handled; the crate decodes the frames as written.
#[test]
fn a_vendor_file_with_allowed_defects_generates_and_decodes_as_written() {
    use aer_codegen::diagnostic::Code;
    let dbc = manifest_dir().join("tests/dbc/vendor_defects.dbc");
    let refused = aer_codegen::load_dbc(&dbc).expect_err("errors by default");
    let codes: Vec<&str> = refused.0.iter().map(|d| d.code.as_str()).collect();
    assert_eq!(codes, ["E0107", "E0101"], "{refused}");

    let root = Path::new(env!("CARGO_TARGET_TMPDIR")).join("vendor_defects_can");
    let options = aer_codegen::CrateOptions {
        allow: vec![Code::SignalOverlap, Code::IdOutOfRange],
        ..Default::default()
    };
    let report = aer_codegen::generate_crate(&dbc, &root, &options).expect("generates");
    let warned: Vec<(&str, &str)> = report
        .warnings
        .iter()
        .map(|d| (d.code.as_str(), d.help.as_str()))
        .collect();
    assert!(
        warned
            .iter()
            .any(|(c, h)| *c == "E0107" && h.contains("as written")),
        "{warned:?}"
    );
    assert!(
        warned
            .iter()
            .any(|(c, h)| *c == "E0101" && h.contains("extended")),
        "{warned:?}"
    );
    // Its own target directory: the tricky crate's test builds an example of the same name
    // meanwhile, and one folder would let either test run the other crate's decoder.
    let target = Path::new(env!("CARGO_TARGET_TMPDIR")).join("vendor_defects_can_target");
    let status = Command::new(env!("CARGO"))
        .args(["build", "--quiet", "--example", "decode"])
        .current_dir(&root)
        .env("CARGO_TARGET_DIR", &target)
        .status()
        .expect("run cargo");
    assert!(status.success(), "the generated crate must build");
    let lines = run(
        &target.join("debug/examples/decode"),
        "(1.000000) can0 12C#ABCD\n(1.000000) can0 18FEF100#2A\n(1.000000) can0 12C#AB\n",
    );
    let json: Vec<Json> = lines
        .iter()
        .map(|l| serde_json::from_str(l).expect("JSON"))
        .collect();
    assert_eq!(json[0]["signals"]["Low"], 0xAB);
    assert_eq!(
        json[0]["signals"]["Straddling"], 0xDA,
        "bits 4-11 as written"
    );
    assert_eq!(json[1]["name"], "UnflaggedExtended");
    assert_eq!(json[1]["extended"], true);
    assert_eq!(json[1]["signals"]["Value"], 42);
    assert!(
        json[2]["error"].is_string(),
        "a short frame is an error line, not a panic"
    );
}
