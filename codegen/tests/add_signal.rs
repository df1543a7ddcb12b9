//! The point of the project: one schema edit (a new field `shocktravel5` next to
//! `shocktravel4`) reaches every output: the firmware packer, the Pi's Deku decoder, the
//! tables (TDengine and SQLite), the MQTT payload and the calibration tools' A2L.

use std::path::Path;

use aer_codegen::CarSchema;
use aer_codegen::model::{Placement, WireType};

const SHOCKTRAVEL5: &str = "  - name: shocktravel5
    group: chassis
    label: Shock travel 5
    type: u16
    scale: 0.01
    unit: mm
    min: 0
    max: 76.2
    description: Fifth shock travel sensor.
";

fn schema_with_shocktravel5(dir: &Path) {
    let schema = Path::new(env!("CARGO_MANIFEST_DIR")).join("../schema");
    std::fs::copy(schema.join("aer.dbc"), dir.join("aer.dbc")).expect("copy aer.dbc");
    std::fs::copy(
        schema.join("calibration.yaml"),
        dir.join("calibration.yaml"),
    )
    .expect("copy calibration.yaml");
    let yaml = std::fs::read_to_string(schema.join("telemetry.yaml")).expect("read yaml");
    let anchor = "    description: Rear-right shock travel.\n";
    assert!(
        yaml.contains(anchor),
        "shocktravel4's block moved; update this test"
    );
    let edited = yaml.replacen(anchor, &format!("{anchor}{SHOCKTRAVEL5}"), 1);
    std::fs::write(dir.join("telemetry.yaml"), edited).expect("write yaml");
}

fn file<'a>(files: &'a [aer_codegen::GeneratedFile], path: &str) -> &'a str {
    &files
        .iter()
        .find(|f| f.path == Path::new(path))
        .unwrap_or_else(|| panic!("no {path}"))
        .content
}

#[test]
fn a_new_field_reaches_every_tier() {
    let dir = tempfile::tempdir().expect("temp dir");
    schema_with_shocktravel5(dir.path());
    let before = CarSchema::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../schema"))
        .expect("car schema");
    let after = CarSchema::load(dir.path()).expect("edited schema is valid");

    // The model: two more bytes, right after shocktravel4, and a new fingerprint.
    let field =
        |s: &CarSchema, name: &str| s.telemetry.fields.iter().find(|f| f.name == name).cloned();
    let new = field(&after, "shocktravel5").expect("the new field");
    let Placement::Bytes(st4) = field(&after, "shocktravel4")
        .expect("shocktravel4")
        .placement
    else {
        panic!("shocktravel4 is a value");
    };
    assert_eq!(new.placement, Placement::Bytes(st4 + 2));
    assert_eq!(new.wire, WireType::U16);
    assert_eq!(after.telemetry.len, before.telemetry.len + 2);
    let fp = |s: &CarSchema| aer_codegen::telemetry_fingerprint(&s.db, &s.telemetry);
    assert_ne!(
        fp(&after),
        fp(&before),
        "a firmware without the field must be rejected by the Pi"
    );

    let files = after.files().expect("renders");
    let len = after.telemetry.len;

    // Firmware packer: a typed field (no default: builders must fill it) and its conversion.
    let packer = file(&files, "telemetry.rs");
    assert!(packer.contains("pub shocktravel5: f32,"), "packer struct");
    assert!(
        packer.contains("pub fn shocktravel5_to_raw(v: f32) -> (u16, bool)"),
        "packer conversion"
    );
    assert!(
        packer.contains(&format!("pub const LEN: usize = {len};")),
        "packet length"
    );
    assert!(
        packer.contains("Self::shocktravel5_to_raw(self.shocktravel5)"),
        "pack writes it"
    );

    // Pi's Deku decoder: the raw field, converted through the packer's own function.
    let deku = file(&files, "telemetry_deku.rs");
    assert!(deku.contains("pub shocktravel5: u16,"), "deku field");
    assert!(
        deku.contains("shocktravel5: Telemetry::shocktravel5_from_raw(self.shocktravel5),"),
        "deku conversion"
    );

    // TDengine: a column in the telemetry super table, so the Pi can ALTER a live database.
    let sql = file(&files, "sql/tdengine.sql");
    let telemetry_table = sql
        .lines()
        .find(|l| l.contains("CREATE STABLE IF NOT EXISTS `telemetry`"))
        .expect("telemetry table");
    assert!(
        telemetry_table.contains("`shocktravel5` FLOAT"),
        "{telemetry_table}"
    );
    assert!(
        file(&files, "tables.rs")
            .contains(r#"Column { name: "shocktravel5", ty: ColumnType::F32 }"#)
    );
    // The Pi's SQLite store: the same column.
    assert!(file(&files, "sql/sqlite.sql").contains(r#""shocktravel5" REAL"#));

    // MQTT: the telemetry topic's payload is the packet struct, serialized with every field.
    let mqtt = file(&files, "mqtt.rs");
    assert!(mqtt.contains("pub const TELEMETRY: Topic<Sample<TelemetryRecord>>"));
    assert!(mqtt.contains("pub telemetry: Telemetry,"));
    assert!(packer.contains("#[cfg_attr(feature = \"serde\", derive(serde::Serialize, serde::Deserialize))]\npub struct Telemetry {"));

    // The A2L: a MEASUREMENT at its byte in the packet (the telemetry area at 0x20000), with its
    // wire type, scaling, unit and range; and a new EPK, so a tool holding the old description
    // notices.
    let a2l = file(&files, "aer.a2l");
    let measurement = format!(
        "    /begin MEASUREMENT telemetry.shocktravel5 \"Fifth shock travel sensor.\"\n      \
         UWORD cm.mm 0 0 0 76.2\n      ECU_ADDRESS 0x{:X}\n    /end MEASUREMENT\n",
        0x2_0000 + st4 + 2
    );
    assert!(a2l.contains(&measurement), "{measurement}");
    assert!(a2l.contains("/begin COMPU_METHOD cm.mm \"raw * 0.01 + 0, mm\"\n      LINEAR \"%12.2\" \"mm\"\n      COEFFS_LINEAR 0.01 0\n"));
    assert!(a2l.contains(&format!("VARIABLES RAM INTERN 0x20000 {len} ")));
    let epk = |s: &CarSchema| {
        format!(
            "EPK \"AER {:08X} {:08X}\"",
            fp(s),
            aer_codegen::calibration_fingerprint(&s.calibration)
        )
    };
    assert!(a2l.contains(&epk(&after)), "{}", epk(&after));
    assert_ne!(epk(&after), epk(&before));
}

#[test]
fn telemetry_mistakes_are_reported_with_lines() {
    let dir = tempfile::tempdir().expect("temp dir");
    schema_with_shocktravel5(dir.path());
    let path = dir.path().join("telemetry.yaml");
    let yaml = std::fs::read_to_string(&path).expect("read");
    let cases = [
        (
            "signal: MCU1.MCU_MotorState",
            "signal: MCU1.MCU_MotorStatee",
            "E0203",
            "has no signal `MCU_MotorStatee`",
        ),
        (
            "signal: MCU1.MCU_MotorState",
            "signal: MCU9.MCU_MotorState",
            "E0203",
            "no message `MCU9`",
        ),
        (
            "    type: u8\n    scale: 0.4",
            "    type: u9\n    scale: 0.4",
            "E0204",
            "unknown type `u9`",
        ),
        (
            "  - name: bse_rear",
            "  - name: bse_front",
            "E0206",
            "defined twice",
        ),
        (
            "  - name: soc",
            "  - name: Soc",
            "E0206",
            "`Soc` is not usable",
        ),
        (
            "    max: 76.2\n    description: Fifth",
            "    max: 900\n    description: Fifth",
            "E0213",
            "range [0, 900]",
        ),
        (
            "display: { warn: 250, critical: 300 }",
            "display: { warn: 350, critical: 300 }",
            "E0214",
            "warn above critical (350 > 300)",
        ),
        (
            "tx_id: 0x666",
            "tx_id: 0x1666",
            "E0212",
            "not an 11-bit CAN id",
        ),
        (
            "  timeout_ms: 200",
            "  timeout_ms: 5",
            "E0216",
            "`timeout_ms` 5 is shorter than the packet's period (10 ms)",
        ),
        (
            "  bus: vehicle",
            "  bus: vehicel",
            "E0215",
            "bus `vehicel`, which no DBC message names",
        ),
        (
            "  sender: CCM",
            "  sender: VCU",
            "E0217",
            "sender `VCU` is not a node of the DBC",
        ),
        (
            "    scale: 0.001\n    unit: V\n    min: 0\n    max: 5\n    description: Front",
            "    sacle: 0.001\n    unit: V\n    min: 0\n    max: 5\n    description: Front",
            "E0202",
            "sacle",
        ),
    ];
    for (from, to, code, text) in cases {
        assert!(yaml.contains(from), "fixture moved: {from}");
        let edited = yaml.replacen(from, to, 1);
        std::fs::write(&path, &edited).expect("write");
        let line = edited
            .lines()
            .collect::<Vec<_>>()
            .iter()
            .rposition(|l| {
                to.lines()
                    .next()
                    .is_some_and(|first| l.trim() == first.trim())
            })
            .map(|i| i + 1);
        let Err(aer_codegen::Error::Schema(diags)) = CarSchema::load(dir.path()) else {
            panic!("{to:?} was accepted");
        };
        let d = diags
            .0
            .iter()
            .find(|d| d.code == code)
            .unwrap_or_else(|| panic!("no {code} for {to:?}: {diags}"));
        assert!(
            d.message.contains(text) || d.to_string().contains(text),
            "{to:?}: {d}"
        );
        // Range errors point at the field; syntax and packet errors at their own keys.
        let line = if code == "E0213" {
            edited
                .lines()
                .position(|l| l == "  - name: shocktravel5")
                .map(|i| i + 1)
        } else if code == "E0214" {
            edited
                .lines()
                .position(|l| l == "  - name: pack_current")
                .map(|i| i + 1)
        } else {
            line
        };
        if code != "E0202" && code != "E0212" {
            assert_eq!(Some(d.line), line, "{to:?}: {d}");
        }
        assert!(d.file.ends_with("telemetry.yaml"));
    }
    // An oversized packet: 2100 u16 fields exceed ISO-TP's 4095 bytes.
    let mut big = yaml.clone();
    for i in 0..2100 {
        big.push_str(&format!("  - {{ name: extra{i}, type: u16 }}\n"));
    }
    std::fs::write(&path, big).expect("write");
    let Err(aer_codegen::Error::Schema(diags)) = CarSchema::load(dir.path()) else {
        panic!("an oversized packet was accepted");
    };
    assert!(
        diags
            .0
            .iter()
            .any(|d| d.code == "E0209" && d.message.contains("ISO-TP carries at most 4095")),
        "{diags}"
    );
}

/// The car's schema labels every field and gives every number a unit: people read them in
/// the pit view, the exports and the bus documentation. Leaving one out is a warning, and
/// the car's schema denies warnings.
#[test]
fn a_field_without_label_or_unit_is_refused_for_the_car() {
    let dir = tempfile::tempdir().expect("temp dir");
    schema_with_shocktravel5(dir.path());
    let path = dir.path().join("telemetry.yaml");
    let yaml = std::fs::read_to_string(&path).expect("read");
    for (from, code, text) in [
        (
            "    label: Shock travel 5\n",
            "W0207",
            "`shocktravel5` has no label",
        ),
        (
            "    unit: mm\n    min: 0\n    max: 76.2\n    description: Fifth",
            "W0208",
            "`shocktravel5` has no unit",
        ),
    ] {
        let edited = yaml.replacen(from, from.split_once('\n').map_or("", |(_, rest)| rest), 1);
        assert_ne!(edited, yaml, "fixture moved: {from}");
        std::fs::write(&path, &edited).expect("write");
        let Err(aer_codegen::Error::DeniedWarnings(warnings)) = CarSchema::load(dir.path()) else {
            panic!("{code} was not denied");
        };
        assert!(
            warnings
                .iter()
                .any(|w| w.code == code && w.message.contains(text)),
            "{code}: {warnings:?}"
        );
        let line = edited
            .lines()
            .position(|l| l == "  - name: shocktravel5")
            .map(|i| i + 1);
        assert!(
            warnings.iter().all(|w| Some(w.line) == line),
            "{warnings:?}"
        );
    }
}

/// The vehicle bus keeps room for the team's next sensors: the car's schema plans
/// `headroom_bytes` of growth, and the build warns (W0211, denied for the car) when the packet
/// grown by it would load its bus above the warning threshold. The room itself is generated
/// into the bus documentation.
#[test]
fn the_planned_headroom_is_kept_on_the_telemetry_bus() {
    let dir = tempfile::tempdir().expect("temp dir");
    schema_with_shocktravel5(dir.path());
    let path = dir.path().join("telemetry.yaml");
    let yaml = std::fs::read_to_string(&path).expect("read");
    let schema = CarSchema::load(dir.path()).expect("the car's schema with room to spare");
    assert!(
        schema.telemetry.headroom_bytes >= 8,
        "room for at least four 16-bit sensors"
    );
    let files = schema.files().expect("render");
    let can = file(&files, "docs/can.md");
    assert!(
        can.contains(&format!(
            "with the packet {} bytes longer",
            schema.telemetry.headroom_bytes
        )),
        "the room is documented:\n{can}"
    );

    // Planning far more growth than the bus has room for is denied, at the key.
    let from = format!("  headroom_bytes: {}", schema.telemetry.headroom_bytes);
    assert!(yaml.contains(&from), "fixture moved: {from}");
    let edited = yaml.replacen(&from, "  headroom_bytes: 200", 1);
    std::fs::write(&path, &edited).expect("write");
    let Err(aer_codegen::Error::DeniedWarnings(warnings)) = CarSchema::load(dir.path()) else {
        panic!("a plan the bus cannot hold was not denied");
    };
    let line = edited
        .lines()
        .position(|l| l == "  headroom_bytes: 200")
        .map(|i| i + 1);
    assert!(
        warnings.iter().any(|w| w.code == "W0211"
            && Some(w.line) == line
            && w.message.contains("bus `vehicle` keeps no room")),
        "{warnings:?}"
    );

    // `aer-codegen check` finds it as the build does, given the folder or the DBC in it.
    for target in [dir.path().to_path_buf(), dir.path().join("aer.dbc")] {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_aer-codegen"))
            .arg("check")
            .arg(&target)
            .output()
            .expect("run aer-codegen");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && stderr.contains("W0211"),
            "check {}: {stderr}",
            target.display()
        );
    }
}
