//! Renders the telemetry packet: the no_std firmware packer (`telemetry.rs`) and the Pi's Deku
//! decoder (`telemetry_deku.rs`). Both convert through the same generated per-field functions,
//! so they cannot disagree on scaling.

use askama::Template;

use super::codec::{scale_expr, unscale_expr};
use super::{doc_lines, float_lit, phys_rust};
use crate::model::{Database, PhysType, Placement, Telemetry, TelemetryField, WireType};

#[derive(Template)]
#[template(path = "telemetry.rs", escape = "none")]
pub struct TelemetryTemplate<'a> {
    pub source: &'a str,
    pub t: &'a Telemetry,
    pub fingerprint: String,
    pub enums: Vec<String>,
    pub fields: Vec<FieldView>,
    pub flag_bytes: usize,
    /// One arm per DBC message that telemetry fields mirror.
    pub mirrors: Vec<MirrorArm>,
}

/// The statements that copy one message's signals into the telemetry fields that mirror them.
pub struct MirrorArm {
    /// `AnyMessage` variant (the message's type name).
    pub variant: String,
    pub statements: Vec<String>,
}

#[derive(Template)]
#[template(path = "telemetry_deku.rs", escape = "none")]
pub struct DekuTemplate<'a> {
    pub source: &'a str,
    pub t: &'a Telemetry,
    pub fields: Vec<FieldView>,
    pub flag_bytes: usize,
}

pub struct FieldView {
    pub name: String,
    pub docs: Vec<String>,
    pub phys_ty: String,
    pub wire_ty: &'static str,
    pub meta: String,
    pub display: String,
    pub from_raw_body: String,
    pub to_raw_body: Vec<String>,
    pub pack_stmt: String,
    pub unpack_expr: String,
    pub visit_stmt: String,
    /// The field's value before any data arrived (zero, `false`, or the enum's raw 0).
    pub default_expr: String,
    pub is_flag: bool,
    /// Expression reading the raw value from `self` (a `TelemetryFrame`).
    pub deku_read: String,
    /// Statement storing the raw value of `t.<field>` into the frame under construction.
    pub deku_write: String,
}

fn view(db: &Database, first_flag_byte: usize, index: usize, f: &TelemetryField) -> FieldView {
    let name = &f.name;
    let phys_ty = phys_rust(db, f.phys);
    let wire_ty = f.wire.rust();
    let identity = f.scale == 1.0 && f.offset == 0.0;
    let (lo, hi) = f.wire.range();
    let (from_raw_body, to_raw_body) = match (f.phys, f.wire) {
        (PhysType::Bool, _) => ("raw".to_owned(), vec!["(v, false)".to_owned()]),
        (PhysType::Enum(_), _) => (
            format!("{phys_ty}::from_raw(raw)"),
            vec!["(v.into_raw(), false)".to_owned()],
        ),
        (PhysType::Int(t), w) if identity && t.rust() == w.rust() => {
            ("raw".to_owned(), vec!["(v, false)".to_owned()])
        }
        (PhysType::Int(t), _) => {
            let (s, o) = (f.scale as i128, f.offset as i128);
            let (plo, phi) = t.range();
            // Holds the wire and physical ranges and the intermediate `raw * scale`.
            let (a, b) = (lo * s, hi * s);
            let arith = super::int_arith(lo.min(plo).min(a).min(b), hi.max(phi).max(a).max(b));
            let mut from = format!("{arith}::from(raw)");
            if s != 1 {
                from = format!("{from} * {s}");
            }
            from.push_str(&super::signed_term(o));
            let to = if s == 1 {
                format!("{arith}::from(v){}", super::signed_term(-o))
            } else {
                format!(
                    "runtime::div_round(i128::from(v){}, {s})",
                    super::signed_term(-o)
                )
            };
            (
                format!("({from}) as {phys_ty}"),
                vec![
                    format!("let raw = {to};"),
                    format!("let clamped = raw.clamp({lo}, {hi});"),
                    format!("(clamped as {wire_ty}, clamped != raw)"),
                ],
            )
        }
        (PhysType::F32 | PhysType::F64, wire) => {
            let v64 = if f.phys == PhysType::F32 {
                "f64::from(v)"
            } else {
                "v"
            };
            let scaled = scale_expr("f64::from(raw)", f.scale, f.offset);
            let from = if f.phys == PhysType::F32 {
                format!("({scaled}) as f32")
            } else {
                scaled
            };
            let unscaled = unscale_expr(v64, f.scale, f.offset);
            match wire {
                WireType::F32 if f.phys == PhysType::F32 && identity => {
                    ("raw".to_owned(), vec!["(v, false)".to_owned()])
                }
                WireType::F32 => (from, vec![format!("(({unscaled}) as f32, false)")]),
                _ => (
                    from,
                    vec![
                        format!("let raw = runtime::round({unscaled});"),
                        "if raw.is_nan() {\nreturn (0, true);\n}".to_owned(),
                        format!(
                            "let clamped = raw.clamp({}, {});",
                            float_lit(lo as f64),
                            float_lit(hi as f64)
                        ),
                        format!("(clamped as {wire_ty}, clamped != raw)"),
                    ],
                ),
            }
        }
    };
    let (pack_stmt, unpack_expr, start_bit) = match f.placement {
        Placement::Bytes(at) => (
            format!("runtime::put(out, {at}, &raw.to_le_bytes());"),
            format!("Self::{name}_from_raw({wire_ty}::from_le_bytes(runtime::take(data, {at})))"),
            at * 8,
        ),
        Placement::Bit(byte, bit) => (
            format!(
                "if raw {{\nif let Some(b) = out.get_mut({byte}) {{\n*b |= 1 << {bit};\n}}\n}}"
            ),
            format!(
                "Self::{name}_from_raw(data.get({byte}).is_some_and(|b| b & (1 << {bit}) != 0))"
            ),
            byte * 8 + usize::from(bit),
        ),
    };
    let pack_stmt = format!(
        "let (raw, clamped) = Self::{name}_to_raw(self.{name});\nsaturated += u8::from(clamped);\n{pack_stmt}"
    );
    let (value_expr, label_expr) = match f.phys {
        PhysType::Enum(_) => ("Value::from(v.into_raw())", "v.label()"),
        _ => ("Value::from(v)", "None"),
    };
    let visit_stmt = format!(
        "let v = self.{name};\nvisitor.signal(&TELEMETRY_FIELDS[{index}], {value_expr}, {label_expr});"
    );
    let labels = super::labels_lit(db, f.phys);
    let opt = |v: Option<f64>| v.map_or("None".to_owned(), |x| format!("Some({})", float_lit(x)));
    let meta = format!(
        "SignalMeta {{ name: {:?}, unit: {:?}, comment: {:?}, start_bit: {start_bit}, len: {}, byte_order: ByteOrder::LittleEndian, signed: {}, factor: {}, offset: {}, min: {}, max: {}, labels: &[{labels}], multiplexed: false }}",
        f.name,
        f.unit,
        f.description,
        f.wire.bits(),
        matches!(f.wire, WireType::I8 | WireType::I16 | WireType::I32),
        float_lit(f.scale),
        float_lit(f.offset),
        opt(f.min),
        opt(f.max)
    );
    let display = format!(
        "FieldDisplay {{ group: {:?}, label: {:?}, warn: {}, critical: {}, warn_below: {}, critical_below: {} }}",
        f.group,
        f.display.label.clone().unwrap_or_else(|| f.name.clone()),
        opt(f.display.warn),
        opt(f.display.critical),
        opt(f.display.warn_below),
        opt(f.display.critical_below)
    );
    let mut docs = doc_lines(&f.description);
    if !docs.is_empty() {
        docs.push(String::new());
    }
    let mut facts = match f.placement {
        Placement::Bytes(at) => format!("Wire: `{wire_ty}` at byte {at}"),
        Placement::Bit(byte, bit) => format!("Wire: flag in bit {bit} of byte {byte}"),
    };
    facts.push_str(&super::scaling_doc(f.scale, f.offset));
    if !f.unit.is_empty() {
        facts.push_str(&format!(", unit `{}`", f.unit));
    }
    if let Some(src) = &f.source {
        facts.push_str(&format!(", mirrors `{src}`"));
    }
    facts.push('.');
    docs.push(facts);
    let (deku_read, deku_write) = match f.placement {
        Placement::Bit(byte, bit) => {
            let i = byte - first_flag_byte;
            (
                format!("self.flags[{i}] & (1 << {bit}) != 0"),
                format!(
                    "if {}::{name}_to_raw(t.{name}).0 {{\nflags[{i}] |= 1 << {bit};\n}}",
                    "Telemetry"
                ),
            )
        }
        Placement::Bytes(_) => (
            format!("self.{name}"),
            format!("{name}: Telemetry::{name}_to_raw(t.{name}).0,"),
        ),
    };
    let default_expr = match f.phys {
        PhysType::Bool => "false".to_owned(),
        PhysType::Int(_) => "0".to_owned(),
        PhysType::F32 | PhysType::F64 => "0.0".to_owned(),
        PhysType::Enum(_) => format!("{phys_ty}::from_raw(0)"),
    };
    FieldView {
        name: name.clone(),
        docs,
        default_expr,
        phys_ty,
        wire_ty,
        meta,
        display,
        from_raw_body,
        to_raw_body,
        pack_stmt,
        unpack_expr,
        visit_stmt,
        is_flag: f.wire == WireType::Flag,
        deku_read,
        deku_write,
    }
}

fn flag_count(t: &Telemetry) -> usize {
    t.fields.iter().filter(|f| f.wire == WireType::Flag).count()
}

fn field_views(db: &Database, t: &Telemetry) -> Vec<FieldView> {
    let first_flag = first_flag_byte(t);
    t.fields
        .iter()
        .enumerate()
        .map(|(i, f)| view(db, first_flag, i, f))
        .collect()
}

/// Byte offset of the first flag byte (flags follow every byte-aligned field).
fn first_flag_byte(t: &Telemetry) -> usize {
    t.len - flag_count(t).div_ceil(8)
}

pub fn render(
    db: &Database,
    t: &Telemetry,
    source: &str,
    fingerprint: u32,
) -> Result<String, askama::Error> {
    let mut enums: Vec<String> = t
        .fields
        .iter()
        .filter_map(|f| match f.phys {
            PhysType::Enum(i) => db.enums.get(i).map(|e| e.type_name.clone()),
            _ => None,
        })
        .collect();
    enums.sort();
    enums.dedup();
    TelemetryTemplate {
        source,
        t,
        fingerprint: format!("0x{fingerprint:08X}"),
        enums,
        fields: field_views(db, t),
        flag_bytes: flag_count(t).div_ceil(8),
        mirrors: mirror_arms(db, t),
    }
    .render()
}

/// Groups the fields that mirror DBC signals by message, in DBC message order.
fn mirror_arms(db: &Database, t: &Telemetry) -> Vec<MirrorArm> {
    db.messages
        .iter()
        .filter_map(|message| {
            let statements: Vec<String> = t
                .fields
                .iter()
                .filter_map(|field| {
                    let (msg, sig) = field.source.as_deref()?.split_once('.')?;
                    if msg != message.name {
                        return None;
                    }
                    let signal = message.signals.iter().find(|s| s.name == sig)?;
                    let value = if signal.phys == field.phys {
                        "v".to_owned()
                    } else {
                        format!("v as {}", phys_rust(db, field.phys))
                    };
                    Some(if signal.mux.is_some() {
                        format!(
                            "if let Some(v) = m.{} {{\nself.{} = {value};\n}}",
                            signal.field, field.name
                        )
                    } else if value == "v" {
                        format!("self.{} = m.{};", field.name, signal.field)
                    } else {
                        format!(
                            "self.{} = m.{} as {};",
                            field.name,
                            signal.field,
                            phys_rust(db, field.phys)
                        )
                    })
                })
                .collect();
            (!statements.is_empty()).then(|| MirrorArm {
                variant: message.type_name.clone(),
                statements,
            })
        })
        .collect()
}

pub fn render_deku(db: &Database, t: &Telemetry, source: &str) -> Result<String, askama::Error> {
    DekuTemplate {
        source,
        t,
        fields: field_views(db, t),
        flag_bytes: flag_count(t).div_ceil(8),
    }
    .render()
}
