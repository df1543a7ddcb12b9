//! Render: the model -> source files, through askama templates (one per output).

pub mod codec;
pub mod column_type;
pub mod docs;
pub mod fragment;
pub mod meta;
pub mod mqtt;
pub mod standalone;
pub mod tables;
pub mod telemetry;

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
