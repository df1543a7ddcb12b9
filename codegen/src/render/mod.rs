//! Render: the model -> source files, through askama templates (one per output).

pub(crate) mod a2l;
pub(crate) mod calibration;
pub(crate) mod codec;
pub(crate) mod docs;
pub(crate) mod fragment;
pub(crate) mod meta;
pub(crate) mod mqtt;
pub(crate) mod standalone;
pub(crate) mod tables;
pub(crate) mod telemetry;

/// Splits a schema comment into doc-comment lines.
pub(crate) fn doc_lines(text: &str) -> Vec<String> {
    text.lines().map(|l| l.trim_end().to_owned()).collect()
}

/// The Rust type of a physical value.
pub(crate) fn phys_rust(db: &crate::model::Database, phys: crate::model::PhysType) -> String {
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
