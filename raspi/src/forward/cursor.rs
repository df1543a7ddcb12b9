//! The forwarder's position in the store: per table, the last row TDengine has (or that was
//! set aside), persisted in the store itself so an outage or a reboot loses nothing.

use crate::store::compact::{self, BlockError};
use aer::tables::TABLES;
use aer_host::clock::now_us;
use rusqlite::Connection;
use rusqlite::types::Value as Sql;

/// Rows of one table after the cursor, in id order.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct Batch {
    /// Each row's id in the store.
    pub ids: Vec<i64>,
    /// Each row's values without `id`: tags, then columns.
    pub rows: Vec<Vec<Sql>>,
    /// Compacted blocks after the cursor that did not decode: their rows cannot be sent.
    pub damaged: Vec<BlockError>,
    damaged_through: Option<i64>,
}

impl Batch {
    /// The cursor once the batch is done: its last row, or past the damaged blocks it met.
    pub fn last_id(&self) -> Option<i64> {
        self.ids.last().copied().max(self.damaged_through)
    }
}

/// Reads up to `limit` rows of table `table` (its index in `TABLES`) after the cursor.
pub fn next_batch(db: &Connection, table: usize, limit: usize) -> rusqlite::Result<Batch> {
    let Some(local) = TABLES.get(table) else {
        return Ok(Batch::default());
    };
    let cursor: i64 = db
        .query_row(
            "SELECT last_id FROM forward_cursor WHERE table_name = ?1",
            [local.name],
            |row| row.get(0),
        )
        .or_else(|error| match error {
            rusqlite::Error::QueryReturnedNoRows => Ok(0),
            other => Err(other),
        })?;
    let stored = compact::rows_between(db, local, cursor.saturating_add(1), i64::MAX, limit)?;
    let (ids, rows) = stored.rows.into_iter().unzip();
    Ok(Batch {
        ids,
        rows,
        damaged: stored.damaged,
        damaged_through: stored.damaged_through,
    })
}

/// Moves `table`'s cursor to `last_id`.
pub fn advance(db: &Connection, table: usize, last_id: i64) -> rusqlite::Result<()> {
    let Some(local) = TABLES.get(table) else {
        return Ok(());
    };
    db.execute(
        "INSERT INTO forward_cursor (table_name, last_id) VALUES (?1, ?2) \
         ON CONFLICT(table_name) DO UPDATE SET last_id = excluded.last_id",
        rusqlite::params![local.name, last_id],
    )?;
    Ok(())
}

/// Records rows of `table` TDengine refused, with its reason; the rows stay in the store.
pub(crate) fn set_aside(
    db: &Connection,
    table: usize,
    rows: &[(i64, String)],
) -> rusqlite::Result<()> {
    let Some(local) = TABLES.get(table) else {
        return Ok(());
    };
    let at = i64::try_from(now_us()).unwrap_or(i64::MAX);
    let mut statement = db.prepare_cached(
        "INSERT OR REPLACE INTO forward_set_aside (table_name, row_id, error, at_us) VALUES (?1, ?2, ?3, ?4)",
    )?;
    for (id, error) in rows {
        statement.execute(rusqlite::params![local.name, id, error, at])?;
    }
    Ok(())
}
