//! Renders the no_std codec (`runtime.rs` and the messages module) from the model.

use askama::Template;

use super::{doc_lines, float_lit};
use crate::model::{
    ByteOrder, Database, Encoding, EnumType, IntType, Message, PhysType, Signal, be_linear,
};

#[derive(Template)]
#[template(path = "runtime.rs", escape = "none")]
pub struct RuntimeTemplate<'a> {
    pub source: &'a str,
    /// Byte helpers for the telemetry packet, emitted only where a packet uses them.
    pub telemetry: bool,
}

#[derive(Template)]
#[template(path = "can.rs", escape = "none")]
pub struct CanTemplate<'a> {
    pub source: &'a str,
    pub db_name: &'a str,
    pub fingerprint: String,
    pub enums: Vec<EnumView>,
    pub messages: Vec<MessageView>,
}

pub struct EnumView {
    pub name: String,
    pub repr: &'static str,
    pub variants: Vec<VariantView>,
    pub used_by: String,
}

pub struct VariantView {
    pub ident: String,
    pub value: String,
    pub label_lit: String,
    pub label_doc: String,
}

pub struct MessageView {
    pub type_name: String,
    pub name: String,
    pub meta_static: String,
    pub docs: Vec<String>,
    pub id: String,
    pub extended: bool,
    pub len: usize,
    pub cycle_time: String,
    pub cycle_time_const: Option<u32>,
    pub comment: String,
    pub signals: Vec<SignalView>,
    /// Signals in the order decode/encode must process them (multiplexors first).
    pub ordered: Vec<SignalView>,
}

#[derive(Clone)]
pub struct SignalView {
    pub name: String,
    pub field: String,
    pub docs: Vec<String>,
    pub raw_ty: String,
    pub phys_ty: String,
    pub field_ty: String,
    pub meta: String,
    pub from_raw_body: String,
    pub to_raw_body: Vec<String>,
    pub decode_stmt: String,
    pub encode_stmt: String,
    pub visit_stmt: String,
    pub from_signals_expr: String,
    /// Names the JSON key after the DBC signal; absent multiplexed signals are left out.
    pub serde_attr: String,
}

pub fn render_runtime(source: &str, telemetry: bool) -> Result<String, askama::Error> {
    RuntimeTemplate { source, telemetry }.render()
}

pub fn render_can(db: &Database, source: &str, fingerprint: u32) -> Result<String, askama::Error> {
    let enums = db
        .enums
        .iter()
        .enumerate()
        .map(|(i, e)| enum_view(db, i, e))
        .collect();
    let messages = db.messages.iter().map(|m| message_view(db, m)).collect();
    CanTemplate {
        source,
        db_name: &db.name,
        fingerprint: format!("0x{fingerprint:08X}"),
        enums,
        messages,
    }
    .render()
}

fn enum_view(db: &Database, index: usize, e: &EnumType) -> EnumView {
    let users: Vec<String> = db
        .messages
        .iter()
        .flat_map(|m| {
            m.signals
                .iter()
                .filter(|s| s.phys == PhysType::Enum(index))
                .map(move |s| format!("`{}.{}`", m.name, s.name))
        })
        .collect();
    EnumView {
        name: e.type_name.clone(),
        repr: e.repr.rust(),
        variants: e
            .variants
            .iter()
            .map(|v| VariantView {
                ident: v.ident.clone(),
                value: v.value.to_string(),
                label_lit: format!("{:?}", v.label),
                label_doc: if v.label.trim().is_empty() {
                    "(no name)".to_owned()
                } else {
                    v.label.replace('`', "'")
                },
            })
            .collect(),
        used_by: if users.is_empty() {
            "Named values from the schema's value table.".to_owned()
        } else {
            format!("Values of {}.", users.join(", "))
        },
    }
}

fn message_view(db: &Database, m: &Message) -> MessageView {
    let signals: Vec<SignalView> = m
        .signals
        .iter()
        .enumerate()
        .map(|(i, s)| signal_view(db, m, i, s))
        .collect();
    let ordered = m
        .eval_order
        .iter()
        .filter_map(|&i| signals.get(i).cloned())
        .collect();
    let mut docs = m.comment.as_deref().map(doc_lines).unwrap_or_default();
    if !docs.is_empty() {
        docs.push(String::new());
    }
    let kind = if m.extended { "extended" } else { "standard" };
    let mut facts = format!(
        "`{}`: {kind} id 0x{:X}, {} bytes{}",
        m.name,
        m.id,
        m.len,
        if m.fd { " (CAN FD)" } else { "" }
    );
    if let Some(ms) = m.cycle_time_ms {
        facts.push_str(&format!(", every {ms} ms"));
    }
    if let Some(tx) = &m.transmitter {
        facts.push_str(&format!(", sent by {tx}"));
    }
    facts.push('.');
    docs.push(facts);
    MessageView {
        type_name: m.type_name.clone(),
        name: format!("{:?}", m.name),
        meta_static: format!("{}_SIGNALS", crate::naming::screaming(&m.type_name)),
        docs,
        id: format!("0x{:X}", m.id),
        extended: m.extended,
        len: m.len,
        cycle_time: m
            .cycle_time_ms
            .map_or("None".to_owned(), |c| format!("Some({c})")),
        cycle_time_const: m.cycle_time_ms,
        comment: format!("{:?}", m.comment.as_deref().unwrap_or("")),
        signals,
        ordered,
    }
}

pub(crate) fn phys_rust_signal(db: &Database, s: &Signal) -> String {
    super::phys_rust(db, s.phys)
}

fn raw_rust(s: &Signal) -> &'static str {
    match s.encoding {
        Encoding::Float32 => "f32",
        Encoding::Float64 => "f64",
        _ => s.raw_int().rust(),
    }
}

/// `x * factor + offset` in source form, leaving out identity steps.
pub(crate) fn scale_expr(x: &str, factor: f64, offset: f64) -> String {
    let mut e = x.to_owned();
    if factor != 1.0 {
        e = format!("{e} * {}", float_lit(factor));
    }
    if offset != 0.0 {
        e = format!("{e} + {}", float_lit(offset));
    }
    e
}

/// `(x - offset) / factor` in source form, leaving out identity steps.
pub(crate) fn unscale_expr(x: &str, factor: f64, offset: f64) -> String {
    let mut e = x.to_owned();
    if offset != 0.0 {
        e = format!("({e} - {})", float_lit(offset));
    }
    if factor != 1.0 {
        e = format!("{e} / {}", float_lit(factor));
    }
    e
}

fn identity(s: &Signal) -> bool {
    s.factor == 1.0 && s.offset == 0.0
}

fn signal_view(db: &Database, m: &Message, index: usize, s: &Signal) -> SignalView {
    let raw_ty = raw_rust(s).to_owned();
    let phys_ty = phys_rust_signal(db, s);
    let optional = s.mux.is_some();
    let field_ty = if optional {
        format!("Option<{phys_ty}>")
    } else {
        phys_ty.clone()
    };
    let msg = format!("{:?}", m.name);
    let sig = format!("{:?}", s.name);
    let f = &s.field;
    let meta_ref = format!(
        "&{}_SIGNALS[{index}]",
        crate::naming::screaming(&m.type_name)
    );

    // `@` stands for the operand in these expression templates.
    let (read_bits, write_bits) = match s.byte_order {
        ByteOrder::LittleEndian => (
            format!("bits::read_le(data, {}, {})", s.start_bit, s.len),
            format!("bits::write_le(out, {}, {}, @);", s.start_bit, s.len),
        ),
        ByteOrder::BigEndian => (
            format!("bits::read_be(data, {}, {})", be_linear(s.start_bit), s.len),
            format!(
                "bits::write_be(out, {}, {}, @);",
                be_linear(s.start_bit),
                s.len
            ),
        ),
    };
    let raw_int = s.raw_int();
    let (raw_from_bits, bits_from_raw) = match s.encoding {
        Encoding::Float32 => (
            "f32::from_bits(@ as u32)".to_owned(),
            "u64::from(@.to_bits())".to_owned(),
        ),
        Encoding::Float64 => ("f64::from_bits(@)".to_owned(), "@.to_bits()".to_owned()),
        Encoding::Signed if raw_int == IntType::I64 => (
            format!("bits::sign_extend(@, {})", s.len),
            "@ as u64".to_owned(),
        ),
        Encoding::Signed => (
            format!("bits::sign_extend(@, {}) as {raw_ty}", s.len),
            "@ as u64".to_owned(),
        ),
        Encoding::Unsigned if raw_int == IntType::U64 => ("@".to_owned(), "@".to_owned()),
        Encoding::Unsigned => (format!("@ as {raw_ty}"), "u64::from(@)".to_owned()),
    };
    let sub = |template: &str, operand: &str| template.replace('@', operand);
    let from_bits = |bits: &str| format!("Self::{f}_from_raw({})", sub(&raw_from_bits, bits));
    let to_bits = |phys: &str| sub(&bits_from_raw, &format!("Self::{f}_to_raw({phys})?"));

    let condition = s.mux.as_ref().map_or(String::new(), |c| {
        let sel = m.signals.get(c.selector);
        let local = sel.map_or("selector".to_owned(), |x| format!("{}_bits", x.field));
        let pats: Vec<String> = c
            .ranges
            .iter()
            .map(|&(lo, hi)| {
                if lo == hi {
                    lo.to_string()
                } else {
                    format!("{lo}..={hi}")
                }
            })
            .collect();
        if sel.is_some_and(|x| x.mux.is_some()) {
            format!("matches!({local}, Some({}))", pats.join(" | "))
        } else {
            format!("matches!({local}, {})", pats.join(" | "))
        }
    });

    let (decode_stmt, encode_stmt) = match (optional, s.is_multiplexor) {
        (false, false) => (
            format!("let {f} = {};", from_bits(&read_bits)),
            sub(&write_bits, &to_bits(&format!("self.{f}"))),
        ),
        (false, true) => (
            format!(
                "let {f}_bits = {read_bits};\n        let {f} = {};",
                from_bits(&format!("{f}_bits"))
            ),
            format!(
                "let {f}_bits = {};\n        {}",
                to_bits(&format!("self.{f}")),
                sub(&write_bits, &format!("{f}_bits"))
            ),
        ),
        (true, is_mux) => {
            let missing = format!("EncodeError::MissingSignal {{ message: {msg}, signal: {sig} }}");
            let unselected =
                format!("EncodeError::NotSelected {{ message: {msg}, signal: {sig} }}");
            let checked = format!(
                "match ({condition}, self.{f}) {{\n            (true, Some(v)) => Some({}),\n            (false, None) => None,\n            (true, None) => return Err({missing}),\n            (false, Some(_)) => return Err({unselected}),\n        }}",
                to_bits("v")
            );
            if is_mux {
                (
                    format!(
                        "let {f}_bits = if {condition} {{ Some({read_bits}) }} else {{ None }};\n        let {f} = {f}_bits.map(|bits| {});",
                        from_bits("bits")
                    ),
                    format!(
                        "let {f}_bits = {checked};\n        if let Some(bits) = {f}_bits {{\n            {}\n        }}",
                        sub(&write_bits, "bits")
                    ),
                )
            } else {
                (
                    format!(
                        "let {f} = if {condition} {{ Some({}) }} else {{ None }};",
                        from_bits(&read_bits)
                    ),
                    format!(
                        "if let Some(bits) = {checked} {{\n            {}\n        }}",
                        sub(&write_bits, "bits")
                    ),
                )
            }
        }
    };

    let (from_raw_body, to_raw_body) = conversions(db, s, &raw_ty, &phys_ty, &msg, &sig);

    let integral_scale = s.factor.fract() == 0.0 && s.offset.fract() == 0.0;
    let (value_expr, label_expr, from_value) = match s.phys {
        PhysType::Enum(i) => {
            let repr = db.enums.get(i).map_or("u64", |e| e.repr.rust());
            let value = if identity(s) {
                "Value::from(v.into_raw())".to_owned()
            } else if integral_scale {
                format!(
                    "Value::Int(i128::from(v.into_raw()) * {} + {})",
                    s.factor as i128, s.offset as i128
                )
            } else {
                format!(
                    "Value::Float({})",
                    scale_expr("v.into_raw() as f64", s.factor, s.offset)
                )
            };
            let from = if identity(s) {
                format!("v.to_int::<{repr}>().map({phys_ty}::from_raw)")
            } else {
                format!(
                    "v.unscale::<{repr}>({}, {}).map({phys_ty}::from_raw)",
                    float_lit(s.factor),
                    float_lit(s.offset)
                )
            };
            (value, "v.label()".to_owned(), from)
        }
        PhysType::Bool => ("Value::from(v)".into(), "None".into(), "v.to_bool()".into()),
        PhysType::Int(t) => (
            "Value::from(v)".into(),
            "None".into(),
            format!("v.to_int::<{}>()", t.rust()),
        ),
        PhysType::F32 => (
            "Value::from(v)".into(),
            "None".into(),
            "Some(v.to_f32())".into(),
        ),
        PhysType::F64 => (
            "Value::from(v)".into(),
            "None".into(),
            "Some(v.to_f64())".into(),
        ),
    };
    let visit_stmt = if optional {
        format!(
            "if let Some(v) = self.{f} {{\n            visitor.signal({meta_ref}, {value_expr}, {label_expr});\n        }}"
        )
    } else {
        format!(
            "let v = self.{f};\n        visitor.signal({meta_ref}, {value_expr}, {label_expr});"
        )
    };
    let invalid = format!("EncodeError::InvalidValue {{ message: {msg}, signal: {sig} }}");
    let from_signals_expr = if optional {
        format!(
            "match source.value({meta_ref}) {{\n                Some(v) => Some({from_value}.ok_or({invalid})?),\n                None => None,\n            }}"
        )
    } else {
        format!(
            "{{\n                let v = source.value({meta_ref}).ok_or(EncodeError::MissingSignal {{ message: {msg}, signal: {sig} }})?;\n                {from_value}.ok_or({invalid})?\n            }}"
        )
    };

    let mut docs = s.comment.as_deref().map(doc_lines).unwrap_or_default();
    if !docs.is_empty() {
        docs.push(String::new());
    }
    let mut facts = format!(
        "`{}`: {} bit{} from bit {} ({}), {}",
        s.name,
        s.len,
        if s.len == 1 { "" } else { "s" },
        s.start_bit,
        if s.byte_order == ByteOrder::LittleEndian {
            "Intel"
        } else {
            "Motorola"
        },
        match s.encoding {
            Encoding::Unsigned => "unsigned",
            Encoding::Signed => "signed",
            Encoding::Float32 => "IEEE float",
            Encoding::Float64 => "IEEE double",
        }
    );
    facts.push_str(&super::scaling_doc(s.factor, s.offset));
    if let (Some(lo), Some(hi)) = (s.min, s.max) {
        facts.push_str(&format!(", range [{}, {}]", float_lit(lo), float_lit(hi)));
    }
    if !s.unit.is_empty() {
        facts.push_str(&format!(", unit `{}`", s.unit.replace('`', "'")));
    }
    facts.push('.');
    docs.push(facts);
    if let Some(c) = &s.mux {
        let sel = m.signals.get(c.selector).map_or("?", |x| x.name.as_str());
        let vals: Vec<String> = c
            .ranges
            .iter()
            .map(|&(lo, hi)| {
                if lo == hi {
                    lo.to_string()
                } else {
                    format!("{lo}-{hi}")
                }
            })
            .collect();
        docs.push(format!("Present only when `{sel}` is {}.", vals.join(", ")));
    }

    SignalView {
        name: s.name.clone(),
        field: s.field.clone(),
        docs,
        raw_ty,
        phys_ty,
        field_ty,
        meta: signal_meta(db, s),
        from_raw_body,
        to_raw_body,
        decode_stmt,
        encode_stmt,
        visit_stmt,
        from_signals_expr,
        serde_attr: if optional {
            format!(
                "#[cfg_attr(feature = \"serde\", serde(rename = {:?}, default, skip_serializing_if = \"Option::is_none\"))]",
                s.name
            )
        } else {
            format!(
                "#[cfg_attr(feature = \"serde\", serde(rename = {:?}))]",
                s.name
            )
        },
    }
}

/// Bodies of `<field>_from_raw(raw) -> Phys` and `<field>_to_raw(v) -> Result<Raw, _>`.
fn conversions(
    db: &Database,
    s: &Signal,
    raw_ty: &str,
    phys_ty: &str,
    msg: &str,
    sig: &str,
) -> (String, Vec<String>) {
    let out_of_range = format!("EncodeError::OutOfRange {{ message: {msg}, signal: {sig} }}");
    let mut to_raw = Vec::new();
    let phys_as_f64 = match s.phys {
        PhysType::Bool => "f64::from(u8::from(v))".to_owned(),
        PhysType::Int(
            IntType::U8 | IntType::U16 | IntType::U32 | IntType::I8 | IntType::I16 | IntType::I32,
        ) => "f64::from(v)".to_owned(),
        PhysType::Int(_) => "v as f64".to_owned(),
        PhysType::F32 => "f64::from(v)".to_owned(),
        PhysType::F64 => "v".to_owned(),
        PhysType::Enum(_) => scale_expr("raw as f64", s.factor, s.offset),
    };
    if let (Some(lo), Some(hi)) = (s.min, s.max) {
        let check = format!(
            "runtime::check_range({phys_as_f64}, {}, {}, {}, {msg}, {sig})?;",
            float_lit(lo),
            float_lit(hi),
            float_lit(s.factor.abs() * 1e-6)
        );
        // Values the schema names are valid whatever the range says (255 = "SNA" beyond
        // [0|100], say); only unnamed raw values are range-checked (cantools does the same).
        to_raw.push(match s.phys {
            PhysType::Enum(_) => format!("if let {phys_ty}::Unknown(raw) = v {{\n{check}\n}}"),
            _ => check,
        });
    }
    let (raw_lo, raw_hi) = s.raw_range();
    let raw_int = s.raw_int();
    let full_width = (raw_lo, raw_hi) == raw_int.range();
    // Checks an integer `raw` of the raw type against the signal's bit width.
    let fit = |expr: &str| {
        if full_width {
            format!("Ok({expr})")
        } else {
            format!(
                "let raw = {expr};\nif ({raw_lo}..={raw_hi}).contains(&raw) {{ Ok(raw) }} else {{ Err({out_of_range}) }}"
            )
        }
    };
    let ident = identity(s);
    let from_raw = match s.phys {
        PhysType::Bool => {
            to_raw.push("Ok(u8::from(v))".into());
            "raw != 0".to_owned()
        }
        PhysType::Enum(i) => {
            let repr = db.enums.get(i).map(|e| e.repr).unwrap_or(IntType::U64);
            if repr == raw_int {
                to_raw.push(fit("v.into_raw()"));
                format!("{phys_ty}::from_raw(raw)")
            } else {
                to_raw.push(format!(
                    "let raw = {raw_ty}::try_from(v.into_raw()).map_err(|_| {out_of_range})?;"
                ));
                to_raw.push(fit("raw"));
                format!("{phys_ty}::from_raw({}::from(raw))", repr.rust())
            }
        }
        PhysType::Int(t) if ident => {
            if t == raw_int {
                to_raw.push(fit("v"));
                "raw".to_owned()
            } else {
                to_raw.push(format!(
                    "let raw = {raw_ty}::try_from(v).map_err(|_| {out_of_range})?;"
                ));
                to_raw.push(fit("raw"));
                format!("{phys_ty}::from(raw)")
            }
        }
        PhysType::Int(t) => {
            let f = s.factor as i128;
            let o = s.offset as i128;
            let (plo, phi) = t.range();
            // Holds the raw type (for `From`), the physical range and the intermediate
            // `raw * factor`.
            let (tlo, thi) = raw_int.range();
            let (a, b) = (raw_lo * f, raw_hi * f);
            let arith = super::int_arith(tlo.min(plo).min(a).min(b), thi.max(phi).max(a).max(b));
            let unscaled = if f == 1 {
                format!("{arith}::from(v){}", super::signed_term(-o))
            } else if o == 0 {
                format!("runtime::div_round(i128::from(v), {f})")
            } else {
                format!(
                    "runtime::div_round(i128::from(v){}, {f})",
                    super::signed_term(-o)
                )
            };
            to_raw.push(format!("let raw = {unscaled};"));
            to_raw.push(format!(
                "let raw = {raw_ty}::try_from(raw).map_err(|_| {out_of_range})?;"
            ));
            to_raw.push(fit("raw"));
            let mut e = format!("{arith}::from(raw)");
            if f != 1 {
                e = format!("{e} * {f}");
            }
            e.push_str(&super::signed_term(o));
            format!("({e}) as {phys_ty}")
        }
        PhysType::F32 | PhysType::F64 if s.is_float_raw() => {
            let raw_expr = match (s.encoding, s.phys) {
                (Encoding::Float32, PhysType::F32) if ident => "v".to_owned(),
                (Encoding::Float32, PhysType::F32) => format!(
                    "{} as f32",
                    unscale_expr("f64::from(v)", s.factor, s.offset)
                ),
                (Encoding::Float32, _) => {
                    format!("({}) as f32", unscale_expr("v", s.factor, s.offset))
                }
                _ => unscale_expr("v", s.factor, s.offset),
            };
            to_raw.push(format!("Ok({raw_expr})"));
            match (s.encoding, s.phys) {
                (Encoding::Float32, PhysType::F32) if ident => "raw".to_owned(),
                (Encoding::Float32, PhysType::F32) => format!(
                    "({}) as f32",
                    scale_expr("f64::from(raw)", s.factor, s.offset)
                ),
                (Encoding::Float32, _) => scale_expr("f64::from(raw)", s.factor, s.offset),
                _ => scale_expr("raw", s.factor, s.offset),
            }
        }
        PhysType::F32 | PhysType::F64 => {
            let v64 = if s.phys == PhysType::F32 {
                "f64::from(v)"
            } else {
                "v"
            };
            // Bounds are powers of two, exact in f64: `raw < hi` rejects 2^64 for a u64.
            let hi_excl = if s.encoding == Encoding::Signed {
                1i128 << (s.len - 1)
            } else {
                1i128 << s.len
            };
            to_raw.push(format!(
                "let raw = runtime::round({});",
                unscale_expr(v64, s.factor, s.offset)
            ));
            to_raw.push(format!(
                "if ({}..{}).contains(&raw) {{ Ok(raw as {raw_ty}) }} else {{ Err({out_of_range}) }}",
                float_lit(raw_lo as f64),
                float_lit(hi_excl as f64)
            ));
            let raw_f = match raw_int {
                IntType::U8
                | IntType::U16
                | IntType::U32
                | IntType::I8
                | IntType::I16
                | IntType::I32 => "f64::from(raw)",
                _ => "raw as f64",
            };
            if s.phys == PhysType::F32 {
                format!("({}) as f32", scale_expr(raw_f, s.factor, s.offset))
            } else {
                scale_expr(raw_f, s.factor, s.offset)
            }
        }
    };
    (from_raw, to_raw)
}

fn signal_meta(db: &Database, s: &Signal) -> String {
    let labels = super::labels_lit(db, s.phys);
    let opt = |v: Option<f64>| v.map_or("None".to_owned(), |x| format!("Some({})", float_lit(x)));
    format!(
        "SignalMeta {{ name: {:?}, unit: {:?}, comment: {:?}, start_bit: {}, len: {}, byte_order: ByteOrder::{}, signed: {}, factor: {}, offset: {}, min: {}, max: {}, labels: &[{labels}], multiplexed: {} }}",
        s.name,
        s.unit,
        s.comment.as_deref().unwrap_or(""),
        s.start_bit,
        s.len,
        if s.byte_order == ByteOrder::LittleEndian {
            "LittleEndian"
        } else {
            "BigEndian"
        },
        s.encoding == Encoding::Signed,
        float_lit(s.factor),
        float_lit(s.offset),
        opt(s.min),
        opt(s.max),
        s.mux.is_some()
    )
}
