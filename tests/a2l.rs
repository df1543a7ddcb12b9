//! The calibration tools' description, `generated/aer.a2l`, checked by tools that share no code
//! with the generator: a2ltool (the a2lfile crate's checker) parses it strictly, checks its
//! references and that every limit fits its type and conversion, and parses its IF_DATA XCP
//! with the A2ML the file carries; pya2ldb (`tools/check_a2l.py`) reads every CHARACTERISTIC
//! and MEASUREMENT back and compares it with this crate's own tables.
//!
//! Both tools come from the project's venv (`tools/requirements.txt`, which `.ci/run`
//! installs); without them those two tests say SKIPPED, unless `AER_REQUIRE_PYTHON` is set
//! (CI sets it), when they fail. The last test needs no Python: the file names every
//! parameter, internal and packet field exactly once.

use std::path::{Path, PathBuf};
use std::process::Command;

use aer::calibration::{ElementType, INTERNALS, Internals, PAGE_LEN, PARAMETERS, xcp};
use aer::telemetry::{TELEMETRY_FINGERPRINT, Telemetry, TelemetryHeader};
use serde_json::{Value, json};

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn a2l_path() -> PathBuf {
    root().join("generated/aer.a2l")
}

fn a2l() -> String {
    std::fs::read_to_string(a2l_path()).expect("generated/aer.a2l")
}

/// The venv's Python (or `AER_PYTHON`), when it imports pya2l, with the a2ltool beside it.
fn venv() -> Option<(PathBuf, PathBuf)> {
    let venv = root().join(".venv/bin/python");
    let python = std::env::var_os("AER_PYTHON").map_or(venv, PathBuf::from);
    let a2ltool = python.with_file_name("a2ltool");
    let usable = Command::new(&python)
        .args(["-c", "import pya2l"])
        .output()
        .is_ok_and(|o| o.status.success())
        && Command::new(&a2ltool)
            .arg("--version")
            .output()
            .is_ok_and(|o| o.status.success());
    if usable {
        return Some((python, a2ltool));
    }
    assert!(
        std::env::var_os("AER_REQUIRE_PYTHON").is_none(),
        "AER_REQUIRE_PYTHON is set but {} cannot import pya2l or has no a2ltool beside it",
        python.display()
    );
    eprintln!(
        "SKIPPED: checking generated/aer.a2l needs {} with pya2ldb and a2ltool \
         (python3 -m venv .venv && .venv/bin/pip install -r tools/requirements.txt)",
        python.display()
    );
    None
}

/// How many `/begin IF_DATA XCP` blocks `text` has.
fn xcp_blocks(text: &str) -> usize {
    text.matches("/begin IF_DATA XCP").count()
}

#[test]
fn a2ltool_checks_the_file_strictly_and_reads_its_xcp_settings() {
    let Some((_, a2ltool)) = venv() else { return };
    let dir = tempfile::tempdir().expect("temp dir");
    let cleaned = dir.path().join("cleaned.a2l");
    // --ifdata-cleanup drops every IF_DATA block the file's own A2ML cannot parse, so the
    // cleaned copy keeps them all only if every one is valid.
    let out = Command::new(&a2ltool)
        .arg(a2l_path())
        .args([
            "--check",
            "--strict",
            "--show-xcp",
            "--ifdata-cleanup",
            "-o",
        ])
        .arg(&cleaned)
        .output()
        .expect("run a2ltool");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.status.success(), "a2ltool failed:\n{text}");
    assert!(text.contains("No problems found"), "{text}");
    assert!(!text.to_lowercase().contains("warning"), "{text}");
    for setting in [
        format!("CAN id master: 0x{:X}", xcp::CAN_ID_MASTER),
        format!("CAN id slave: 0x{:X}", xcp::CAN_ID_SLAVE),
        format!("CAN baudrate: {} kbps", xcp::BIT_RATE / 1000),
        "address: 127.0.0.1".to_owned(),
        format!("port: {}", xcp::TCP_PORT),
    ] {
        assert!(
            text.contains(&setting),
            "a2ltool does not read {setting:?}:\n{text}"
        );
    }
    let cleaned = std::fs::read_to_string(&cleaned).expect("cleaned copy");
    assert_eq!(
        xcp_blocks(&cleaned),
        xcp_blocks(&a2l()),
        "an IF_DATA XCP block does not parse with the file's A2ML"
    );
    assert_eq!(
        xcp_blocks(&a2l()),
        2,
        "the calibration segment's and the module's"
    );
}

/// The A2L data type of a parameter's elements (the enum has only the variants the page
/// uses, so it is read by name).
fn element_datatype(element: ElementType) -> &'static str {
    match format!("{element:?}").as_str() {
        "F32" => "FLOAT32_IEEE",
        "U8" => "UBYTE",
        "U16" => "UWORD",
        "U32" => "ULONG",
        "I16" => "SWORD",
        "I32" => "SLONG",
        other => panic!("no A2L type for {other}"),
    }
}

/// A packet of zeros but for the fingerprint, decoded.
fn packet(bytes: impl FnOnce(&mut [u8; Telemetry::LEN])) -> Telemetry {
    let mut raw = [0u8; Telemetry::LEN];
    raw[..4].copy_from_slice(&TELEMETRY_FINGERPRINT.to_le_bytes());
    bytes(&mut raw);
    Telemetry::unpack(&raw).expect("a packet").1
}

/// Whether the 32-bit field `name` at `byte` is an IEEE float on the wire: the decoder reads
/// the bytes of 1.0f32 there as 1.0, where a u32 would read 1065353216.
fn is_float(name: &str, byte: usize) -> bool {
    let telemetry = packet(|raw| raw[byte..byte + 4].copy_from_slice(&1.0f32.to_le_bytes()));
    serde_json::to_value(telemetry).expect("json")[name].as_f64() == Some(1.0)
}

/// Every measurement as the crate's tables say it is: the packet header, the packet's fields
/// (aer::telemetry's metadata), the internals.
fn expected_measurements() -> Vec<Value> {
    // The header as the packer writes it: sequence at byte 4, timestamp at byte 6.
    let mut raw = [0; Telemetry::LEN];
    let header = TelemetryHeader {
        sequence: 0x1234,
        timestamp_us: 0x89AB_CDEF,
    };
    packet(|_| {}).pack(header, &mut raw);
    assert_eq!(raw[4..6], 0x1234u16.to_le_bytes());
    assert_eq!(raw[6..10], 0x89AB_CDEFu32.to_le_bytes());
    let linear = |name: &str, datatype: &str, unit: &str, address: u32, (lower, upper)| {
        json!({
            "name": name, "datatype": datatype, "address": address, "lower": lower,
            "upper": upper, "unit": unit, "coeffs": [1.0, 0.0], "values": null,
            "bit_mask": null,
        })
    };
    let mut measurements = vec![
        linear(
            "telemetry.sequence",
            "UWORD",
            "",
            xcp::TELEMETRY_ADDRESS + 4,
            (0.0, f64::from(u16::MAX)),
        ),
        linear(
            "telemetry.timestamp_us",
            "ULONG",
            "us",
            xcp::TELEMETRY_ADDRESS + 6,
            (0.0, f64::from(u32::MAX)),
        ),
    ];
    for f in Telemetry::FIELDS {
        let byte = usize::from(f.start_bit / 8);
        let address = xcp::TELEMETRY_ADDRESS + u32::from(f.start_bit / 8);
        if f.len == 1 {
            measurements.push(json!({
                "name": format!("telemetry.{}", f.name), "datatype": "UBYTE",
                "address": address, "lower": 0.0, "upper": 1.0, "unit": f.unit,
                "coeffs": null, "values": null, "bit_mask": 1u32 << (f.start_bit % 8),
            }));
            continue;
        }
        let float = f.len == 32 && !f.signed && is_float(f.name, byte);
        let datatype = match (f.len, f.signed, float) {
            (_, _, true) => "FLOAT32_IEEE",
            (8, false, _) => "UBYTE",
            (8, true, _) => "SBYTE",
            (16, false, _) => "UWORD",
            (16, true, _) => "SWORD",
            (32, false, _) => "ULONG",
            _ => "SLONG",
        };
        // Without limits in the schema, the range the raw type spans.
        let (lo, hi) = if float {
            (-f64::from(f32::MAX), f64::from(f32::MAX))
        } else if f.signed {
            (
                -(2f64.powi(i32::from(f.len) - 1)),
                2f64.powi(i32::from(f.len) - 1) - 1.0,
            )
        } else {
            (0.0, 2f64.powi(i32::from(f.len)) - 1.0)
        };
        let (a, b) = if float {
            (lo, hi)
        } else {
            (lo * f.factor + f.offset, hi * f.factor + f.offset)
        };
        let names: serde_json::Map<String, Value> = f
            .labels
            .iter()
            .map(|(raw, label)| (raw.to_string(), json!(label)))
            .collect();
        let enumerated = !names.is_empty();
        measurements.push(json!({
            "name": format!("telemetry.{}", f.name), "datatype": datatype, "address": address,
            "lower": f.min.unwrap_or(a.min(b)), "upper": f.max.unwrap_or(a.max(b)),
            "unit": f.unit,
            "coeffs": if enumerated { Value::Null } else { json!([f.factor, f.offset]) },
            "values": if enumerated { Value::Object(names) } else { Value::Null },
            "bit_mask": null,
        }));
    }
    for i in &INTERNALS {
        let address = xcp::INTERNALS_ADDRESS + u32::try_from(i.offset).expect("offset");
        measurements.push(linear(
            &format!("internals.{}", i.name),
            "FLOAT32_IEEE",
            i.unit,
            address,
            (i.min, i.max),
        ));
    }
    measurements.extend(xcp_status_measurements());
    measurements
}

/// The XCP slave's block as the slave lays it out (`aer_xcp::status`), its codes named as the
/// slave's tables name them.
fn xcp_status_measurements() -> Vec<Value> {
    use aer_xcp::protocol::{cmd, err};
    use aer_xcp::status::{FIELDS, Kind, Names};
    let table = |list: &[(u8, &str)]| -> Value {
        list.iter()
            .map(|(raw, name)| (raw.to_string(), json!(name)))
            .collect::<serde_json::Map<_, _>>()
            .into()
    };
    let mut items: serde_json::Map<String, Value> = PARAMETERS
        .iter()
        .enumerate()
        .map(|(index, p)| (index.to_string(), json!(p.name)))
        .collect();
    items.insert(aer_xcp::Detail::NO_ITEM.to_string(), json!("none"));
    FIELDS
        .iter()
        .map(|field| {
            let (datatype, lower, upper) = match field.kind {
                Kind::U8 => ("UBYTE", 0.0, f64::from(u8::MAX)),
                Kind::U16 => ("UWORD", 0.0, f64::from(u16::MAX)),
                Kind::U32 => ("ULONG", 0.0, f64::from(u32::MAX)),
                Kind::F32 => ("FLOAT32_IEEE", -f64::from(f32::MAX), f64::from(f32::MAX)),
            };
            let values = match field.names {
                Names::Command => table(&cmd::NAMES),
                Names::Error => table(&err::NAMES),
                Names::Reason => table(&aer_xcp::reason::ALL),
                Names::Item => Value::Object(items.clone()),
                Names::None => Value::Null,
            };
            json!({
                "name": format!("xcp.{}", field.name), "datatype": datatype,
                "address": xcp::XCP_STATUS_ADDRESS + field.offset,
                "lower": lower, "upper": upper, "unit": "",
                "coeffs": if values.is_null() { json!([1.0, 0.0]) } else { Value::Null },
                "values": values, "bit_mask": null,
            })
        })
        .collect()
}

/// What tools/check_a2l.py compares the file with, from the crate's own constants.
fn expected() -> Value {
    let characteristics: Vec<Value> = PARAMETERS
        .iter()
        .filter(|p| p.axis_of.is_none())
        .map(|p| {
            let kind = match (p.axis, p.elements.is_empty()) {
                (Some(_), _) => "CURVE",
                (None, true) => "VALUE",
                (None, false) => "VAL_BLK",
            };
            json!({
                "name": format!("calibration.{}", p.name),
                "type": kind,
                "address": xcp::CALIBRATION_ADDRESS + u32::try_from(p.offset).expect("offset"),
                "datatype": element_datatype(p.element),
                "lower": p.min,
                "upper": p.max,
                "unit": p.unit,
                "coeffs": [1.0, 0.0],
                "count": p.count,
                "axis": p.axis.map(|a| format!("calibration.{}", a.parameter)),
                "axis_input": p.axis.map(|a| format!("internals.{}", a.input)),
                "axis_unit": p.axis.map(|a| a.unit),
            })
        })
        .collect();
    // A curve's axis points: tunable, in the page right after the curve.
    let axis_points: Vec<Value> = PARAMETERS
        .iter()
        .filter_map(|p| {
            let curve = PARAMETERS.iter().find(|c| Some(c.name) == p.axis_of)?;
            let axis = curve.axis?;
            Some(json!({
                "name": format!("calibration.{}", p.name),
                "address": xcp::CALIBRATION_ADDRESS + u32::try_from(p.offset).expect("offset"),
                "datatype": element_datatype(p.element),
                "lower": p.min,
                "upper": p.max,
                "unit": p.unit,
                "count": p.count,
                "input": format!("internals.{}", axis.input),
            }))
        })
        .collect();
    json!({
        "epk": xcp::EPK,
        "epk_address": xcp::EPK_ADDRESS,
        "memory_segments": {
            "calibration": [xcp::CALIBRATION_ADDRESS, PAGE_LEN],
            "telemetry": [xcp::TELEMETRY_ADDRESS, Telemetry::LEN],
            "internals": [xcp::INTERNALS_ADDRESS, Internals::LEN],
            "epk": [xcp::EPK_ADDRESS, xcp::EPK.len()],
            "xcp": [xcp::XCP_STATUS_ADDRESS, xcp::XCP_STATUS_LEN],
        },
        "characteristics": characteristics,
        "axis_points": axis_points,
        "measurements": expected_measurements(),
    })
}

/// tools/check_a2l.py on `a2l` against the crate's tables: whether it agreed, and its report.
fn check_a2l(python: &Path, dir: &Path, a2l: &Path) -> (bool, String) {
    let expected_path = dir.join("expected.json");
    std::fs::write(
        &expected_path,
        serde_json::to_string_pretty(&expected()).expect("json"),
    )
    .expect("write the expectation");
    let out = Command::new(python)
        .arg(root().join("tools/check_a2l.py"))
        .arg(a2l)
        .arg(&expected_path)
        .output()
        .expect("run tools/check_a2l.py");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (out.status.success(), text)
}

#[test]
fn pya2ldb_reads_back_what_the_crate_says() {
    let Some((python, _)) = venv() else { return };
    let dir = tempfile::tempdir().expect("temp dir");
    let (agreed, text) = check_a2l(&python, dir.path(), &a2l_path());
    assert!(agreed, "{text}");
    assert!(text.contains("as the crate says"), "{text}");

    // The checker itself: a file that disagrees fails, naming every difference.
    let edits = [
        ("ECU_ADDRESS 0x2000A\n", "ECU_ADDRESS 0x2000B\n"),
        ("COEFFS_LINEAR 0.4 0\n", "COEFFS_LINEAR 0.5 0\n"),
        (
            "VALUE 0x10028 rl.f32 0 cm.Nm 0 2000\n",
            "VALUE 0x10028 rl.f32 0 cm.Nm 0 2500\n",
        ),
        ("internals.slip_ratio", "internals.slip_estimate"),
        (
            "COM_AXIS internals.front_wheel_speed",
            "COM_AXIS internals.driver_torque_nm",
        ),
        ("ECU_ADDRESS 0x50006\n", "ECU_ADDRESS 0x50007\n"),
    ];
    let mut tampered = a2l();
    for (from, to) in edits {
        assert!(tampered.contains(from), "fixture moved: {from}");
        tampered = tampered.replace(from, to);
    }
    let path = dir.path().join("tampered.a2l");
    std::fs::write(&path, tampered).expect("write the tampered copy");
    let (agreed, text) = check_a2l(&python, dir.path(), &path);
    assert!(!agreed, "{text}");
    for difference in [
        "MEASUREMENT telemetry.apps_travel: address 131083, expected 131082",
        "MEASUREMENT telemetry.apps_travel: conversion coefficients [0.5, 0.0], expected [0.4, 0.0]",
        "CHARACTERISTIC calibration.launch_kp: upper limit 2500.0, expected 2000.0",
        "MEASUREMENT internals.slip_ratio is missing",
        "MEASUREMENT internals.slip_estimate is not in the crate's tables",
        "CHARACTERISTIC calibration.launch_slip_target: axis input 'internals.driver_torque_nm', expected 'internals.front_wheel_speed'",
        "MEASUREMENT xcp.refused_reason: address 327687, expected 327686",
    ] {
        assert!(text.contains(difference), "{difference:?} not in:\n{text}");
    }
}

/// The lines that open an object of `kind` named `name`.
fn definitions(a2l: &str, kind: &str, name: &str) -> usize {
    let open = format!("/begin {kind} {name} ");
    a2l.lines()
        .filter(|l| l.trim_start().starts_with(&open))
        .count()
}

#[test]
fn the_a2l_names_every_parameter_internal_and_field_once() {
    let a2l = a2l();
    for p in &PARAMETERS {
        let name = format!("calibration.{}", p.name);
        // A curve's tunable axis points are an AXIS_PTS, every other parameter a
        // CHARACTERISTIC.
        let kind = if p.axis_of.is_some() {
            "AXIS_PTS"
        } else {
            "CHARACTERISTIC"
        };
        assert_eq!(definitions(&a2l, kind, &name), 1, "{name}");
    }
    let fields = Telemetry::FIELDS.iter().map(|f| f.name);
    let telemetry = ["sequence", "timestamp_us"].into_iter().chain(fields);
    for name in telemetry.map(|n| format!("telemetry.{n}")) {
        assert_eq!(definitions(&a2l, "MEASUREMENT", &name), 1, "{name}");
    }
    for i in &INTERNALS {
        let name = format!("internals.{}", i.name);
        assert_eq!(definitions(&a2l, "MEASUREMENT", &name), 1, "{name}");
    }
    // Nothing else: every object is one of the crate's.
    let count = |kind: &str| a2l.matches(&format!("/begin {kind} ")).count();
    let axes = PARAMETERS.iter().filter(|p| p.axis_of.is_some()).count();
    assert_eq!(count("CHARACTERISTIC"), PARAMETERS.len() - axes);
    assert_eq!(count("AXIS_PTS"), axes);
    assert_eq!(
        count("MEASUREMENT"),
        2 + Telemetry::FIELDS.len() + INTERNALS.len() + aer_xcp::status::FIELDS.len()
    );
    // The identifiers a tool checks at connection, and the ids it talks on.
    assert!(a2l.contains(&format!("EPK \"{}\"", xcp::EPK)));
    assert!(a2l.contains(&format!("ADDR_EPK 0x{:X}", xcp::EPK_ADDRESS)));
    assert!(a2l.contains(&format!("CAN_ID_MASTER 0x{:X}", xcp::CAN_ID_MASTER)));
    assert!(a2l.contains(&format!("CAN_ID_SLAVE 0x{:X}", xcp::CAN_ID_SLAVE)));
    assert!(a2l.contains(&format!(
        "COMMUNICATION_MODE_SUPPORTED BLOCK MASTER {} {}",
        xcp::MAX_BS,
        xcp::MIN_ST
    )));
    for (channel, e) in xcp::EVENTS.iter().enumerate() {
        assert!(
            a2l.contains(&format!("/begin EVENT \"{}\"", e.name))
                && a2l.contains(&format!("\" {channel} DAQ ")),
            "event {}",
            e.name
        );
    }
}
