//! The generated local-store schema works in a real SQLite: every table is created, a telemetry
//! packet goes in through the generated insert statement and comes back with the same values, and
//! a store from an older build gains a missing column.

use aer::runtime::{SignalMeta, SignalVisitor, Value};
use aer::tables::{self, TABLES};
use aer::telemetry::{TELEMETRY_FINGERPRINT, Telemetry};
use rusqlite::types::Value as Sql;

fn open() -> rusqlite::Connection {
    let db = rusqlite::Connection::open_in_memory().expect("in-memory SQLite");
    for table in TABLES {
        let statement = table.sqlite.create;
        db.execute(statement, [])
            .unwrap_or_else(|e| panic!("{}: {e}\n{statement}", table.name));
    }
    db
}

struct Row(Vec<Sql>);

impl SignalVisitor for Row {
    fn signal(&mut self, _s: &'static SignalMeta, value: Value, _label: Option<&'static str>) {
        self.0.push(match value {
            Value::Int(i) => Sql::Integer(i64::try_from(i).expect("fits")),
            Value::Float(f) => Sql::Real(f),
        });
    }
}

#[test]
fn every_table_is_valid_sqlite_and_mirrors_tdengine() {
    let db = open();
    for table in TABLES {
        let columns: Vec<(String, String)> = db
            .prepare("SELECT name, type FROM pragma_table_info(?1)")
            .and_then(|mut s| {
                s.query_map([table.name], |r| Ok((r.get(0)?, r.get(1)?)))?
                    .collect()
            })
            .expect("table exists");
        // id, then tags and columns with their SQLite types.
        let expected: Vec<(String, String)> = std::iter::once(("id".into(), "INTEGER".into()))
            .chain(
                table
                    .local_columns()
                    .map(|c| (c.name.to_owned(), c.ty.sqlite().to_owned())),
            )
            .collect();
        assert_eq!(columns, expected, "{}", table.name);
        assert_eq!(
            table.sqlite.insert.matches('?').count(),
            table.local_columns().count()
        );
    }
}

#[test]
fn a_packet_round_trips_through_the_store() {
    let db = open();
    let mut bytes = [0x33u8; Telemetry::LEN];
    bytes[..4].copy_from_slice(&TELEMETRY_FINGERPRINT.to_le_bytes());
    let (header, snapshot) = Telemetry::unpack(&bytes).expect("valid");

    let mut row = Row(vec![
        Sql::Text("car1".into()),
        Sql::Integer(i64::from(TELEMETRY_FINGERPRINT)),
        Sql::Integer(1_763_683_200_000_000),
        Sql::Integer(i64::from(header.sequence)),
        Sql::Integer(i64::from(header.timestamp_us)),
    ]);
    snapshot.visit(&mut row);
    let inserted = db
        .execute(
            tables::TELEMETRY.sqlite.insert,
            rusqlite::params_from_iter(row.0.iter()),
        )
        .expect("insert");
    assert_eq!(inserted, 1);

    let names: Vec<String> = tables::TELEMETRY
        .local_columns()
        .map(|c| format!("\"{}\"", c.name))
        .collect();
    let back: Vec<Sql> = db
        .query_row(
            &format!("SELECT {} FROM telemetry WHERE id = 1", names.join(", ")),
            [],
            |r| (0..names.len()).map(|i| r.get::<_, Sql>(i)).collect(),
        )
        .expect("row");
    assert_eq!(back, row.0, "every value comes back exactly");
}

#[test]
fn an_older_store_gains_missing_columns() {
    let db = rusqlite::Connection::open_in_memory().expect("SQLite");
    // A store from a build whose packet had no fields yet.
    db.execute(
        "CREATE TABLE \"telemetry\" (\"id\" INTEGER PRIMARY KEY, \"car_id\" TEXT NOT NULL, \"schema_fingerprint\" INTEGER NOT NULL, \"ts\" INTEGER NOT NULL)",
        [],
    )
    .expect("old table");
    let existing: Vec<String> = db
        .prepare("SELECT name FROM pragma_table_info('telemetry')")
        .and_then(|mut s| s.query_map([], |r| r.get(0))?.collect())
        .expect("columns");
    let existing: Vec<&str> = existing.iter().map(String::as_str).collect();
    let missing: Vec<_> = tables::TELEMETRY.missing_columns(&existing).collect();
    assert_eq!(missing.len(), tables::TELEMETRY.columns.len() - 1);
    for column in missing {
        db.execute(&tables::TELEMETRY.sqlite_add_column(column), [])
            .expect("ALTER TABLE");
    }
    let n: i64 = db
        .query_row(
            "SELECT count(*) FROM pragma_table_info('telemetry')",
            [],
            |r| r.get(0),
        )
        .expect("count");
    assert_eq!(n as usize, 1 + tables::TELEMETRY.local_columns().count());
}
