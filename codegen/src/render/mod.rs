//! Render: the model -> source files, through askama templates (one per output).

pub mod codec;
pub mod local_store;
pub mod mqtt;
pub mod standalone;
pub mod tdengine;
pub mod telemetry;

/// Formats a float as a Rust literal that reads back to exactly the same value.
pub fn float_lit(v: f64) -> String {
    let s = format!("{v:?}");
    if s.contains(['.', 'e', 'E', 'N', 'i']) {
        s
    } else {
        format!("{s}.0")
    }
}

/// Splits a schema comment into doc-comment lines.
pub fn doc_lines(text: &str) -> Vec<String> {
    text.lines().map(|l| l.trim_end().to_owned()).collect()
}

/// The Rust type of a physical value.
pub fn phys_rust(db: &crate::model::Database, phys: crate::model::PhysType) -> String {
    use crate::model::PhysType;
    match phys {
        PhysType::Bool => "bool".into(),
        PhysType::Int(t) => t.rust().into(),
        PhysType::F32 => "f32".into(),
        PhysType::F64 => "f64".into(),
        PhysType::Enum(i) => db
            .enums
            .get(i)
            .map_or("u64".into(), |e| e.type_name.clone()),
    }
}

/// `+ 40` / `- 40` (nothing for zero): a signed term that reads naturally after an expression.
pub fn signed_term(v: i128) -> String {
    match v {
        0 => String::new(),
        v if v < 0 => format!(" - {}", v.unsigned_abs()),
        v => format!(" + {v}"),
    }
}

/// The smallest signed type for integer scaling arithmetic over `lo..=hi` (raw and physical
/// ranges together): `i32` where it suffices, since wider math is multi-word on the Cortex-M7.
pub fn int_arith(lo: i128, hi: i128) -> &'static str {
    if lo >= i128::from(i32::MIN) && hi <= i128::from(i32::MAX) {
        "i32"
    } else if lo >= i128::from(i64::MIN) && hi <= i128::from(i64::MAX) {
        "i64"
    } else {
        "i128"
    }
}

/// `physical = raw * 0.25 - 40`, for docs (empty for identity scaling).
pub fn scaling_doc(factor: f64, offset: f64) -> String {
    if factor == 1.0 && offset == 0.0 {
        return String::new();
    }
    let factor = if factor == 1.0 {
        String::new()
    } else {
        format!(" * {}", float_lit(factor))
    };
    let offset = match offset {
        0.0 => String::new(),
        o if o < 0.0 => format!(" - {}", float_lit(-o)),
        o => format!(" + {}", float_lit(o)),
    };
    format!(", physical = raw{factor}{offset}")
}

/// `(0, "OFF"), (1, "ON")`: the named raw values of an enum type, for metadata literals.
pub fn labels_lit(db: &crate::model::Database, phys: crate::model::PhysType) -> String {
    match phys {
        crate::model::PhysType::Enum(i) => db.enums.get(i).map_or(String::new(), |e| {
            e.variants
                .iter()
                .map(|v| format!("({}, {:?})", v.value, v.label))
                .collect::<Vec<_>>()
                .join(", ")
        }),
        _ => String::new(),
    }
}
