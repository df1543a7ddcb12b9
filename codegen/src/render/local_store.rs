//! Renders the Pi's local store schema (SQLite): the same tables as TDengine, so rows can be
//! forwarded column for column, plus a row id the forwarder's persisted cursor points at.

use askama::Template;

use super::tdengine::{Table, tables};
use crate::model::{Database, Telemetry};

#[derive(Template)]
#[template(path = "local_store.rs", escape = "none")]
pub struct LocalStoreRust<'a> {
    pub source: &'a str,
    pub tables: Vec<LocalTable>,
}

#[derive(Template)]
#[template(path = "sqlite.sql", escape = "none")]
pub struct LocalStoreSql<'a> {
    pub source: &'a str,
    pub tables: Vec<LocalTable>,
}

pub struct LocalTable {
    pub name: String,
    pub const_name: String,
    pub doc: String,
    /// (name, SQLite type) in order: tags first, then the TDengine columns.
    pub columns: Vec<(String, String)>,
    pub create: String,
    pub index: String,
    pub insert: String,
}

/// SQLite storage class that holds a TDengine column's values exactly.
fn sqlite_type(tdengine: &str) -> &'static str {
    match tdengine {
        "FLOAT" | "DOUBLE" => "REAL",
        t if t.starts_with("VARCHAR") => "TEXT",
        // TIMESTAMP (microseconds), BOOL and every integer type fit a 64-bit INTEGER.
        _ => "INTEGER",
    }
}

fn local(table: Table) -> LocalTable {
    let columns: Vec<(String, String)> = table
        .tags
        .iter()
        .chain(&table.columns)
        .map(|(n, t)| {
            let ty = if n == "ts" {
                "INTEGER".to_owned()
            } else {
                sqlite_type(t).to_owned()
            };
            (n.clone(), ty)
        })
        .collect();
    let defs: Vec<String> = columns
        .iter()
        .map(|(n, t)| {
            let required = table.tags.iter().any(|(tag, _)| tag == n) || n == "ts";
            format!("\"{n}\" {t}{}", if required { " NOT NULL" } else { "" })
        })
        .collect();
    let create = format!(
        "CREATE TABLE IF NOT EXISTS \"{}\" (\"id\" INTEGER PRIMARY KEY, {})",
        table.name,
        defs.join(", ")
    );
    let index = format!(
        "CREATE INDEX IF NOT EXISTS \"{0}_ts\" ON \"{0}\" (\"ts\")",
        table.name
    );
    let names: Vec<String> = columns.iter().map(|(n, _)| format!("\"{n}\"")).collect();
    let marks: Vec<String> = (1..=columns.len()).map(|i| format!("?{i}")).collect();
    let insert = format!(
        "INSERT INTO \"{}\" ({}) VALUES ({})",
        table.name,
        names.join(", "),
        marks.join(", ")
    );
    LocalTable {
        const_name: table.const_name,
        name: table.name,
        doc: table.doc,
        columns,
        create,
        index,
        insert,
    }
}

pub fn render_rust(db: &Database, t: &Telemetry, source: &str) -> Result<String, askama::Error> {
    LocalStoreRust {
        source,
        tables: tables(db, t).into_iter().map(local).collect(),
    }
    .render()
}

pub fn render_sql(db: &Database, t: &Telemetry, source: &str) -> Result<String, askama::Error> {
    LocalStoreSql {
        source,
        tables: tables(db, t).into_iter().map(local).collect(),
    }
    .render()
}
