//! Numbers in a schema that do not fit are diagnostics, never a panic or a silently wrong type:
//! the generator's arithmetic over every numeric field of the YAML and the DBC is checked by
//! properties (extreme, tiny, negative, non-finite and ordinary values) and the cases that once
//! overflowed.

use std::path::Path;

use aer_codegen::CarSchema;
use aer_codegen::diagnostic::Diagnostics;
use aer_codegen::model::{IntType, PhysType};
use proptest::prelude::*;

/// A DBC the car's checks accept: one message the telemetry header needs nothing from.
const DBC: &str = "VERSION \"\"\n\nNS_ :\n\nBS_:\n\nBU_: ECU\n\n\
BO_ 256 Status: 8 ECU\n SG_ Speed : 0|16@1+ (0.1,0) [0|6553.5] \"km/h\" Vector__XXX\n";

const PACKET: &str = "packet:\n  name: Telemetry\n  description: Test packet.\n  \
tx_id: 0x666\n  flow_control_id: 0x777\n  period_ms: 10\n\nfields:\n";

fn car_dbc() -> aer_codegen::model::Database {
    let path = Path::new("aer.dbc");
    aer_codegen::parse_dbc(path, DBC.to_owned(), &[])
        .expect("valid")
        .0
}

/// Validates a packet with one field `value` (the YAML after `- name: value`), and renders
/// every file of the contract crate when it is valid.
fn telemetry(field: &str) -> Result<CarSchema, Diagnostics> {
    let yaml = format!("{PACKET}  - name: value\n{field}");
    let path = Path::new("telemetry.yaml");
    let db = car_dbc();
    // Labels and units (warnings) are beside the point here.
    let (telemetry, _) = aer_codegen::parse_telemetry(path, yaml, &db)?;
    let (calibration, _) = calibration(CAR_CALIBRATION.to_owned())?;
    let schema = CarSchema {
        db,
        telemetry,
        calibration,
    };
    schema.files().expect("a valid schema renders");
    Ok(schema)
}

/// The car's calibration schema, the starting point of the calibration cases.
const CAR_CALIBRATION: &str = include_str!("../../schema/calibration.yaml");

/// The car's DBC: the calibration's XCP messages are in it.
const CAR_DBC: &str = include_str!("../../schema/aer.dbc");

/// What every calibration file declares besides its parameters: an internal and the XCP
/// settings of the car's DBC.
const INTERNALS_AND_XCP: &str = "internals:\n  - { name: x, unit: V, min: 0, max: 1, description: X. }\n\
xcp:\n  bus: vehicle\n  command_message: XCP_Cmd\n  response_message: XCP_Res\n  tcp_port: 5555\n  \
max_daq: 4\n  odt_entries: 64\n  max_odt_entry_size: 4\n  events:\n    \
- { name: control, period_ms: 10, description: After each step. }\n";

fn calibration(
    yaml: String,
) -> Result<
    (
        aer_codegen::model::Calibration,
        Vec<aer_codegen::diagnostic::Diagnostic>,
    ),
    Diagnostics,
> {
    let db = aer_codegen::parse_dbc(Path::new("aer.dbc"), CAR_DBC.to_owned(), &[])
        .expect("the car's DBC")
        .0;
    aer_codegen::parse_calibration(Path::new("calibration.yaml"), yaml, &db)
}

/// Numbers as YAML and DBC files write them, from ordinary to absurd.
fn number() -> impl Strategy<Value = f64> {
    prop_oneof![
        -1000.0..1000.0f64,
        (-320i32..320, any::<bool>()).prop_map(|(e, negative)| {
            let v = 10f64.powi(e);
            if negative { -v } else { v }
        }),
        Just(0.0),
        Just(f64::MAX),
        Just(f64::MIN_POSITIVE),
        any::<f64>(),
    ]
}

/// As text a parser reads back exactly (`1e300`, `-2.5e-7`); non-finite values as YAML spells them.
fn yaml_number(v: f64) -> String {
    match v {
        v if v.is_nan() => ".nan".to_owned(),
        v if v == f64::INFINITY => ".inf".to_owned(),
        v if v == f64::NEG_INFINITY => "-.inf".to_owned(),
        v => format!("{v:e}"),
    }
}

fn first_code(result: &Result<CarSchema, Diagnostics>) -> Option<String> {
    result
        .as_ref()
        .err()
        .and_then(|d| d.0.first())
        .map(|d| d.code.to_string())
}

#[test]
fn scales_that_once_overflowed_are_diagnosed_or_typed_correctly() {
    // u32 x 1e30 reaches 4.3e39: beyond 128-bit integers, so f64 (it used to overflow).
    let wide = telemetry("    type: u32\n    scale: 1e30\n").expect("valid");
    assert_eq!(wide.telemetry.fields[0].phys, PhysType::F64);
    // i32 x -1e38: the same, negative.
    let negative = telemetry("    type: i32\n    scale: -1e38\n").expect("valid");
    assert_eq!(negative.telemetry.fields[0].phys, PhysType::F64);
    // u32 x 1e300 overflows f64 itself.
    let overflow = telemetry("    type: u32\n    scale: 1e300\n");
    assert_eq!(first_code(&overflow).as_deref(), Some("E0211"));
    let d = &overflow.as_ref().err().expect("diagnosed").0[0];
    assert!(d.message.contains("overflow f64"), "{}", d.message);
    assert_eq!(d.file, Path::new("telemetry.yaml"));
    assert!(d.line > 1, "points at the scale: {d}");
    // An offset so large that raw steps vanish in f64.
    let swamped = telemetry("    type: u16\n    offset: 1e300\n");
    assert_eq!(first_code(&swamped).as_deref(), Some("E0211"));
    // u16 with a fractional offset and a huge scale: f32 would overflow, so f64.
    let big = telemetry("    type: u16\n    scale: 1e36\n    offset: 0.5\n").expect("valid");
    assert_eq!(big.telemetry.fields[0].phys, PhysType::F64);
    // Ordinary whole scaling stays an exact integer type.
    let whole = telemetry("    type: u8\n    scale: 2\n    offset: -10\n").expect("valid");
    assert_eq!(
        whole.telemetry.fields[0].phys,
        PhysType::Int(IntType::I16),
        "-10..=500"
    );
}

#[test]
fn a_factor_whose_physical_values_overflow_is_an_error_in_a_dbc() {
    let text = DBC.replace("(0.1,0)", "(1e305,0)");
    let path = Path::new("vendor.dbc");
    let Err(diags) = aer_codegen::parse_dbc(path, text, &[]) else {
        panic!("accepted a factor that overflows");
    };
    assert_eq!(diags.0[0].code, "E0113");
    assert!(diags.0[0].message.contains("overflow f64"));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]

    #[test]
    fn any_numbers_in_a_telemetry_field_give_a_type_or_a_diagnostic(
        wire in prop::sample::select(vec!["u8", "u16", "u32", "i8", "i16", "i32", "f32", "flag"]),
        scale in prop::option::of(number()),
        offset in prop::option::of(number()),
        min in prop::option::of(number()),
        max in prop::option::of(number()),
    ) {
        let mut field = format!("    type: {wire}\n");
        for (key, value) in [("scale", scale), ("offset", offset), ("min", min), ("max", max)] {
            if let Some(v) = value {
                field.push_str(&format!("    {key}: {}\n", yaml_number(v)));
            }
        }
        if let Ok(schema) = telemetry(&field) {
            // A type that holds every physical value: integers exactly, floats finitely.
            let f = &schema.telemetry.fields[0];
            let (lo, hi) = f.wire.range();
            let extremes = [lo as f64 * f.scale + f.offset, hi as f64 * f.scale + f.offset];
            match f.phys {
                PhysType::Int(t) => {
                    let (tlo, thi) = t.range();
                    for x in extremes {
                        prop_assert!(tlo as f64 <= x && x <= thi as f64, "{x} in {t:?}");
                    }
                }
                PhysType::F32 if f.wire.bits() <= 24 => {
                    for x in extremes {
                        prop_assert!(x.abs() <= f64::from(f32::MAX), "{x} in f32");
                    }
                }
                _ => {}
            }
        }
    }

    #[test]
    fn any_numbers_in_a_calibration_parameter_give_a_page_or_a_diagnostic(
        element in prop::sample::select(vec!["f32", "u8", "u16", "u32", "i16", "i32"]),
        default in number(),
        min in number(),
        max in number(),
    ) {
        let yaml = format!(
            "calibration: {{ name: ccm }}\nparameters:\n  - {{ name: value, label: Value, \
             group: test, unit: V, type: {element}, default: {}, min: {}, max: {}, \
             change: driving, description: A value. }}\n{INTERNALS_AND_XCP}",
            yaml_number(default), yaml_number(min), yaml_number(max),
        );
        if let Ok((c, _)) = calibration(yaml) {
            // What the generator accepts holds in its type, within its limits.
            let p = &c.parameters[0];
            let (low, high) = p.element.range();
            prop_assert!(low <= p.min && p.min < p.max && p.max <= high, "{p:?}");
            prop_assert!((p.min..=p.max).contains(&p.defaults[0]), "{p:?}");
            if p.element.is_integer() {
                prop_assert_eq!(p.defaults[0].fract(), 0.0);
            }
            prop_assert_eq!(c.page_len, p.len());
        }
    }

    #[test]
    fn any_numbers_in_the_xcp_settings_give_a_slave_or_a_diagnostic(
        port in number(),
        daq in number(),
        entries in number(),
        entry_size in number(),
        period in number(),
        (min, max) in (number(), number()),
    ) {
        let yaml = format!(
            "calibration: {{ name: ccm }}\nparameters:\n  - {{ name: value, label: Value, \
             group: test, unit: V, type: f32, default: 1, min: 0, max: 2, change: driving, \
             description: A value. }}\ninternals:\n  - {{ name: x, unit: V, min: {}, max: {}, \
             description: X. }}\nxcp:\n  command_message: XCP_Cmd\n  response_message: XCP_Res\n  \
             tcp_port: {}\n  max_daq: {}\n  odt_entries: {}\n  max_odt_entry_size: {}\n  \
             events:\n    - {{ name: e, period_ms: {}, description: E. }}\n",
            yaml_number(min), yaml_number(max), yaml_number(port), yaml_number(daq),
            yaml_number(entries), yaml_number(entry_size), yaml_number(period),
        );
        if let Ok((c, _)) = calibration(yaml) {
            // What the generator accepts is what the slave and an A2L can state.
            let x = &c.xcp;
            prop_assert!(x.tcp_port > 0 && (1..=252).contains(&x.max_daq));
            prop_assert!(x.odt_entries >= x.max_daq && (4..=7).contains(&x.max_odt_entry_size));
            prop_assert!(x.events[0].time_cycle().is_some());
            let i = &c.internals[0];
            prop_assert!(i.min < i.max && i.min.abs() <= f64::from(f32::MAX));
            prop_assert!(i.max.abs() <= f64::from(f32::MAX));
        }
    }

    #[test]
    fn any_numbers_in_a_dbc_signal_give_a_codec_or_a_diagnostic(
        id in prop_oneof![3 => 0u32..0x800, 1 => any::<u32>()],
        size in prop_oneof![Just(8u32), 0u32..72],
        start in prop_oneof![3 => 0u32..48, 1 => 0u32..600],
        len in prop_oneof![3 => 1u32..=16, 1 => 0u32..72],
        intel in any::<bool>(),
        signed in any::<bool>(),
        factor in number(),
        offset in number(),
        min in number(),
        max in number(),
        values in prop::collection::vec(any::<i64>(), 0..4),
        cycle in any::<i64>(),
    ) {
        let number = |v: f64| if v.is_finite() { format!("{v:e}") } else { "0".to_owned() };
        // Mostly a range the right way round, so that more cases get past it.
        let (min, max) = if min <= max { (min, max) } else { (max, min) };
        let order = if intel { 1 } else { 0 };
        let sign = if signed { '-' } else { '+' };
        let labels: String = values.iter().map(|v| format!("{v} \"V{v}\" ")).collect();
        let text = format!(
            "VERSION \"\"\n\nNS_ :\n\nBS_:\n\nBU_: ECU\n\n\
             BO_ {id} M: {size} ECU\n SG_ S : {start}|{len}@{order}{sign} ({},{}) [{}|{}] \"\" ECU\n\n\
             BA_DEF_ BO_ \"GenMsgCycleTime\" INT 0 0;\nBA_ \"GenMsgCycleTime\" BO_ {id} {cycle};\n\
             VAL_ {id} S {labels};\n",
            number(factor), number(offset), number(min), number(max),
        );
        let path = Path::new("vendor.dbc");
        if let Ok((db, _)) = aer_codegen::parse_dbc(path, text, &[]) {
            aer_codegen::codec_files(&db, "vendor.dbc", "Test codec.", "vendor_can")
                .expect("a valid DBC renders");
        }
    }
}
