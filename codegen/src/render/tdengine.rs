//! Renders the TDengine schema: the database fit for a Raspberry Pi, one super table for the
//! telemetry packet and one per CAN message, with lossless column types.

use askama::Template;

use crate::model::{Database, IntType, PhysType, Telemetry};
use crate::naming::snake;

#[derive(Template)]
#[template(path = "tdengine.rs", escape = "none")]
pub struct TdengineRust<'a> {
    pub source: &'a str,
    pub database: &'a str,
    pub create_database: String,
    pub tables: Vec<Table>,
}

#[derive(Template)]
#[template(path = "tdengine.sql", escape = "none")]
pub struct TdengineSql<'a> {
    pub source: &'a str,
    pub create_database: String,
    pub tables: Vec<Table>,
}

pub struct Table {
    pub name: String,
    pub const_name: String,
    pub doc: String,
    pub columns: Vec<(String, String)>,
    pub tags: Vec<(String, String)>,
    pub create: String,
    pub insert: String,
}

/// Database name on the server.
pub const DATABASE: &str = "aer";

/// One vgroup, a 16 MB write buffer, microsecond timestamps: a database a Pi can hold.
fn create_database() -> String {
    format!(
        "CREATE DATABASE IF NOT EXISTS `{DATABASE}` PRECISION 'us' VGROUPS 1 REPLICA 1 BUFFER 16 PAGES 64 CACHEMODEL 'last_row' KEEP 3650"
    )
}

/// The column type that holds every physical value exactly.
pub fn sql_type(db: &Database, phys: PhysType) -> &'static str {
    let int = |t: IntType| match t {
        IntType::U8 => "TINYINT UNSIGNED",
        IntType::U16 => "SMALLINT UNSIGNED",
        IntType::U32 => "INT UNSIGNED",
        IntType::U64 => "BIGINT UNSIGNED",
        IntType::I8 => "TINYINT",
        IntType::I16 => "SMALLINT",
        IntType::I32 => "INT",
        IntType::I64 => "BIGINT",
        // Wider than any TDengine integer: the decimal text is exact.
        IntType::U128 | IntType::I128 => "VARCHAR(40)",
    };
    match phys {
        PhysType::Bool => "BOOL",
        PhysType::F32 => "FLOAT",
        PhysType::F64 => "DOUBLE",
        PhysType::Int(t) => int(t),
        // Enums are stored as their raw value; labels come from the schema.
        PhysType::Enum(i) => db.enums.get(i).map_or("BIGINT", |e| int(e.repr)),
    }
}

fn table(
    name: String,
    doc: String,
    columns: Vec<(String, String)>,
    tags: Vec<(String, String)>,
) -> Table {
    let cols: Vec<String> = columns.iter().map(|(n, t)| format!("`{n}` {t}")).collect();
    let tag_cols: Vec<String> = tags.iter().map(|(n, t)| format!("`{n}` {t}")).collect();
    let create = format!(
        "CREATE STABLE IF NOT EXISTS `{name}` ({}) TAGS ({})",
        cols.join(", "),
        tag_cols.join(", ")
    );
    let marks = |n: usize| vec!["?"; n].join(", ");
    let insert = format!(
        "INSERT INTO ? USING `{name}` TAGS ({}) VALUES ({})",
        marks(tags.len()),
        marks(columns.len())
    );
    Table {
        const_name: name.to_ascii_uppercase(),
        name,
        doc,
        columns,
        tags,
        create,
        insert,
    }
}

pub(crate) fn tables(db: &Database, t: &Telemetry) -> Vec<Table> {
    let car = ("car_id".to_owned(), "VARCHAR(32)".to_owned());
    let schema = ("schema_fingerprint".to_owned(), "INT UNSIGNED".to_owned());
    let mut columns = vec![
        ("ts".to_owned(), "TIMESTAMP".to_owned()),
        ("sequence".to_owned(), "SMALLINT UNSIGNED".to_owned()),
        ("timestamp_us".to_owned(), "INT UNSIGNED".to_owned()),
    ];
    columns.extend(
        t.fields
            .iter()
            .map(|f| (f.name.clone(), sql_type(db, f.phys).to_owned())),
    );
    let mut out = vec![table(
        "telemetry".to_owned(),
        format!(
            "The telemetry packet ({}), one row per packet.",
            t.type_name
        ),
        columns,
        vec![car.clone(), schema.clone()],
    )];
    for m in &db.messages {
        let mut columns = vec![("ts".to_owned(), "TIMESTAMP".to_owned())];
        columns.extend(m.signals.iter().map(|s| {
            (
                s.field.trim_end_matches('_').to_owned(),
                sql_type(db, s.phys).to_owned(),
            )
        }));
        out.push(table(
            format!("can_{}", snake(&m.name).trim_end_matches('_')),
            format!("CAN message `{}` (0x{:X}), one row per frame; multiplexed signals are NULL when absent.", m.name, m.id),
            columns,
            vec![car.clone(), ("bus".to_owned(), "VARCHAR(16)".to_owned()), schema.clone()],
        ));
    }
    out
}

pub fn render_rust(db: &Database, t: &Telemetry, source: &str) -> Result<String, askama::Error> {
    TdengineRust {
        source,
        database: DATABASE,
        create_database: create_database(),
        tables: tables(db, t),
    }
    .render()
}

pub fn render_sql(db: &Database, t: &Telemetry, source: &str) -> Result<String, askama::Error> {
    TdengineSql {
        source,
        create_database: create_database(),
        tables: tables(db, t),
    }
    .render()
}
