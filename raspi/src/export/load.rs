//! The rows an export takes, read from the store column by column with the generated column
//! types (so every writer sees exact integers, `f32` as `f32`, text as text), or decoded from
//! a recorded log into a store in memory first.

use super::ExportError;
use super::columns::{self, TableData, Values};
use crate::store::{compact, row, schema, session};
use aer::tables::{ColumnType, TABLES, Table};
use aer_host::decode::{Ingest, Record};
use aer_host::formats::candump::parse_line;
use aer_host::formats::raw_format::SegmentReader;
use aer_host::reports::counters::Counters;
use rusqlite::Connection;
use rusqlite::types::{Value, ValueRef};
use std::path::Path;
use std::sync::Arc;
use tracing::warn;

/// Which rows: a session's, and/or those within a time range (microseconds since the epoch,
/// inclusive).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Selection {
    pub session: Option<i64>,
    pub from_us: Option<i64>,
    pub to_us: Option<i64>,
}

/// Reading the store's values: typed by the generated column type.
impl Values {
    fn for_type(ty: ColumnType, capacity: usize) -> Self {
        match ty {
            ColumnType::Bool => Self::Bool(Vec::with_capacity(capacity)),
            ColumnType::U64 => Self::UInt(Vec::with_capacity(capacity)),
            ColumnType::F32 => Self::F32(Vec::with_capacity(capacity)),
            ColumnType::F64 => Self::F64(Vec::with_capacity(capacity)),
            ColumnType::VarChar(_) => Self::Text(Vec::with_capacity(capacity)),
            ColumnType::Timestamp
            | ColumnType::I8
            | ColumnType::I16
            | ColumnType::I32
            | ColumnType::I64
            | ColumnType::U8
            | ColumnType::U16
            | ColumnType::U32 => Self::Int(Vec::with_capacity(capacity)),
        }
    }

    /// Appends a stored value. SQLite keeps what it was given: integers as INTEGER, floats
    /// as REAL (an integer too wide for INTEGER was stored as REAL), text as TEXT.
    fn push(&mut self, value: ValueRef<'_>) {
        let int = match value {
            ValueRef::Integer(i) => Some(i),
            ValueRef::Real(f) => Some(f as i64),
            _ => None,
        };
        let float = match value {
            ValueRef::Integer(i) => Some(i as f64),
            ValueRef::Real(f) => Some(f),
            _ => None,
        };
        match self {
            Self::Bool(v) => v.push(int.map(|i| i != 0)),
            Self::Int(v) => v.push(int),
            Self::UInt(v) => v.push(match value {
                ValueRef::Integer(i) => Some(i as u64),
                ValueRef::Real(f) => Some(f as u64),
                _ => None,
            }),
            Self::F32(v) => v.push(float.map(|f| f as f32)),
            Self::F64(v) => v.push(float),
            Self::Text(v) => v.push(match value {
                ValueRef::Text(t) => Some(String::from_utf8_lossy(t).into_owned()),
                ValueRef::Integer(i) => Some(i.to_string()),
                ValueRef::Real(f) => Some(f.to_string()),
                _ => None,
            }),
        }
    }
}

/// Rows read from the store at a time: a little under a compacted block, so the bundled
/// session's export (tests/compaction.rs) crosses a chunk boundary inside a block.
const EXPORT_CHUNK_ROWS: usize = 4_000;

/// Reads the selected rows of every table, in the order they arrived.
pub fn tables(db: &Connection, selection: Selection) -> Result<Vec<TableData>, ExportError> {
    TABLES.iter().map(|t| table(db, t, selection)).collect()
}

/// Reads the selected rows of `table`, in the order they arrived.
pub fn table(
    db: &Connection,
    table: &'static Table,
    selection: Selection,
) -> Result<TableData, ExportError> {
    let (first, last) = match selection.session {
        // A session without rows in this table selects none (an empty id range).
        Some(id) => session::rows(db, id, table.name)?.unwrap_or((1, 0)),
        None => (i64::MIN, i64::MAX),
    };
    let (from, to) = (
        selection.from_us.unwrap_or(i64::MIN),
        selection.to_us.unwrap_or(i64::MAX),
    );
    let ts_at = table.tags.len();
    let in_time = |values: &Vec<Value>| match values.get(ts_at) {
        Some(Value::Integer(ts)) => (from..=to).contains(ts),
        _ => false,
    };
    let mut values: Vec<Values> = table
        .local_columns()
        .map(|c| Values::for_type(c.ty, 0))
        .collect();
    let mut n = 0;
    // Closed sessions are compacted into blocks: read through the store's own reader, a chunk
    // at a time, so only the typed columns grow with the session.
    let mut next = first;
    loop {
        let stored = compact::rows_between(db, table, next, last, EXPORT_CHUNK_ROWS)?;
        for damaged in &stored.damaged {
            warn!(error = %damaged, "a compacted block does not decode: its rows are missing from the export");
        }
        let read_through = stored
            .rows
            .last()
            .map(|(id, _)| *id)
            .max(stored.damaged_through);
        for (_, row) in stored.rows.iter().filter(|(_, v)| in_time(v)) {
            for (column, value) in values.iter_mut().zip(row) {
                column.push(ValueRef::from(value));
            }
            n += 1;
        }
        match read_through {
            Some(id) if id < last => next = id + 1,
            _ => break,
        }
    }
    let mut data = TableData {
        table,
        rows: n,
        columns: Vec::new(),
        values,
    };
    columns::convert(&mut data);
    Ok(data)
}

/// Decodes a candump log or a raw log segment into a store in memory, as the service would
/// have stored it for car `car_id`. Lines or blocks that do not parse are counted in the
/// returned counters (`bad_lines`), as in a replay.
pub fn from_log(path: &Path, car_id: &str) -> Result<(Connection, Arc<Counters>), ExportError> {
    let data = std::fs::read(path).map_err(|source| ExportError::Read {
        path: path.to_owned(),
        source,
    })?;
    let db = Connection::open_in_memory()?;
    schema::create_tables(&db)?;
    let counters = Arc::new(Counters::default());
    let mut ingest = Ingest::new(counters.clone());
    let car: Arc<str> = car_id.into();
    let mut buses: Vec<Arc<str>> = Vec::new();
    let mut bus_index = |name: &str| -> u8 {
        let index = buses.iter().position(|b| &**b == name).unwrap_or_else(|| {
            buses.push(name.into());
            buses.len() - 1
        });
        u8::try_from(index).unwrap_or(u8::MAX)
    };
    let mut frames = Vec::new();
    match SegmentReader::new(&data) {
        Ok(reader) => {
            for item in reader {
                match item {
                    Ok(raw) => {
                        let mut frame = raw.frame;
                        frame.bus = bus_index(&raw.interface);
                        frames.push(frame);
                    }
                    Err(_) => {
                        Counters::bump(&counters.bad_lines);
                    }
                }
            }
        }
        Err(_) => {
            let text = String::from_utf8_lossy(&data);
            for line in text.lines().filter(|l| !l.trim().is_empty()) {
                match parse_line(line, &mut bus_index) {
                    Ok(frame) => frames.push(frame),
                    Err(_) => {
                        Counters::bump(&counters.bad_lines);
                    }
                }
            }
        }
    }
    let mut rows = Vec::new();
    for frame in &frames {
        ingest.on_frame(
            frame,
            |record| {
                if matches!(record, Record::Telemetry { .. } | Record::Can { .. }) {
                    rows.push(row::row(&record, &car, &buses));
                }
            },
            |_, _| {},
        );
    }
    let mut db = db;
    crate::store::writer::commit(&mut db, &rows)?;
    Ok((db, counters))
}
