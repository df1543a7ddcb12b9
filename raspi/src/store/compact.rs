//! Closed sessions, compacted: once a session is closed its rows leave the generated tables
//! for blocks of up to [`BLOCK_ROWS`] rows per table, stored column by column (integers as
//! deltas, reals as the bits that changed, each column's tags and repeated values nearly free)
//! and compressed with zstd. About 3 bytes a row of the car's traffic instead of 87, which is
//! what keeps a season on the card (docs/pi-service.md, "Disk budget").
//!
//! The session being recorded stays in plain rows (live SQL, the free-space floor's rule).
//! Blocks keep every row's id, so the forwarder's cursor, the sessions' row ranges and
//! retention's "oldest first" all work across both; [`rows_between`] reads both in id order.
//! Each block names its columns, so a block from before a schema change reads into today's
//! columns (a column it lacks is NULL). A block that does not decode is reported, not fatal.
//!
//! Block data, before zstd: for each column in the block's order, for each row, a tag
//! (0 NULL, 1 integer, 2 real, 3 text, 4 blob) and its value: an integer as the zigzag LEB128
//! difference from the column's previous integer, a real as its IEEE bits XOR the column's
//! previous real's (8 bytes LE), text and blobs as LEB128 length and bytes.

use super::session;
use aer::tables::{TABLES, Table};
use aer_host::formats::varint::{put_varint, read_varint, unzigzag, zigzag};
use rusqlite::types::Value;
use rusqlite::{Connection, params};
use std::time::{Duration, Instant};
use thiserror::Error;

/// The blocks.
pub(crate) const BLOCKS_TABLE: &str = "CREATE TABLE IF NOT EXISTS \"compacted\" (\"table_name\" TEXT NOT NULL, \"first_id\" INTEGER NOT NULL, \"last_id\" INTEGER NOT NULL, \"first_ts\" INTEGER NOT NULL, \"last_ts\" INTEGER NOT NULL, \"rows\" INTEGER NOT NULL, \"columns\" TEXT NOT NULL, \"data\" BLOB NOT NULL, PRIMARY KEY (\"table_name\", \"first_id\"))";

/// Rows per block: enough for zstd to find the repeats (3.1 B a row at 4096, 3.6 at 1000),
/// few enough that compacting one takes milliseconds on the writer thread.
pub const BLOCK_ROWS: usize = 4096;
/// The zstd level: higher levels gain a few percent for several times the CPU.
const ZSTD_LEVEL: i32 = 3;
/// A block decompresses to at most this much; more is damage.
const MAX_BLOCK_DATA: usize = 64 << 20;
/// How often the writer compacts while there is work ...
const STEP_EVERY: Duration = Duration::from_millis(100);
/// ... and for how long at most (blocks in a row), so rows waiting to be written wait little.
const STEP_FOR: Duration = Duration::from_millis(50);

const TAG_NULL: u8 = 0;
const TAG_INTEGER: u8 = 1;
const TAG_REAL: u8 = 2;
const TAG_TEXT: u8 = 3;
const TAG_BLOB: u8 = 4;

/// Why a block does not read.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum BlockError {
    #[error("compacted block {first_id} of {table} does not decompress")]
    Decompress { table: String, first_id: i64 },
    #[error("compacted block {first_id} of {table} is damaged: {why}")]
    Damaged {
        table: String,
        first_id: i64,
        why: &'static str,
    },
}

/// Rows read back, in id order: each row's id and its values in the table's local column
/// order (tags, then columns).
#[derive(Debug, Default, Clone, PartialEq)]
pub struct StoredRows {
    pub rows: Vec<(i64, Vec<Value>)>,
    /// Blocks in the range that did not decode (their rows are missing from `rows`).
    pub damaged: Vec<BlockError>,
    /// The last id of the last of those blocks, so a reader can move past them.
    pub damaged_through: Option<i64>,
}

/// Reads up to `limit` rows of `table` with ids in `first..=last`, from blocks and plain rows
/// alike, in id order, from one snapshot of the store: the writer may be compacting rows from
/// one into the other meanwhile, and a reader that saw both states would miss them.
pub fn rows_between(
    db: &Connection,
    table: &Table,
    first: i64,
    last: i64,
    limit: usize,
) -> rusqlite::Result<StoredRows> {
    // A savepoint outside a transaction is a read transaction; inside one, it nests.
    db.execute_batch("SAVEPOINT aer_rows_between")?;
    let rows = read_rows(db, table, first, last, limit);
    let released = db.execute_batch("RELEASE aer_rows_between");
    let rows = rows?;
    released?;
    Ok(rows)
}

fn read_rows(
    db: &Connection,
    table: &Table,
    first: i64,
    last: i64,
    limit: usize,
) -> rusqlite::Result<StoredRows> {
    let mut out = StoredRows::default();
    let columns: Vec<&str> = table.local_columns().map(|c| c.name).collect();
    let mut blocks = db.prepare_cached(
        "SELECT first_id, last_id, rows, columns, data FROM compacted \
         WHERE table_name = ?1 AND last_id >= ?2 AND first_id <= ?3 ORDER BY first_id",
    )?;
    let mut found = blocks.query(params![table.name, first, last])?;
    while let Some(block) = found.next()? {
        if out.rows.len() >= limit {
            break;
        }
        let first_id: i64 = block.get(0)?;
        let last_id: i64 = block.get(1)?;
        let count: i64 = block.get(2)?;
        let names: String = block.get(3)?;
        let data = block.get_ref(4)?.as_blob()?;
        match decode(data, &names, usize::try_from(count).unwrap_or(0), &columns) {
            Ok(rows) => out.rows.extend(
                rows.into_iter()
                    .filter(|(id, _)| (first..=last).contains(id))
                    .take(limit - out.rows.len()),
            ),
            Err(why) => {
                out.damaged.push(why.in_block(table.name, first_id));
                out.damaged_through = Some(last_id);
            }
        }
    }
    out.rows.extend(plain_rows(db, table, first, last, limit)?);
    out.rows.sort_by_key(|(id, _)| *id);
    out.rows.truncate(limit);
    Ok(out)
}

/// Lowest and highest row id of `table`, blocks included.
pub(crate) fn id_bounds(
    db: &Connection,
    table: &str,
) -> rusqlite::Result<(Option<i64>, Option<i64>)> {
    db.query_row(
        &format!(
            "SELECT min(lo), max(hi) FROM (SELECT min(id) AS lo, max(id) AS hi FROM \"{table}\" \
             UNION ALL SELECT min(first_id), max(last_id) FROM compacted WHERE table_name = ?1)"
        ),
        [table],
        |row| Ok((row.get(0)?, row.get(1)?)),
    )
}

/// The last id of `table`'s blocks written wholly before `cutoff_us`.
pub(crate) fn last_id_of_blocks_before(
    db: &Connection,
    table: &str,
    cutoff_us: i64,
) -> rusqlite::Result<Option<i64>> {
    db.query_row(
        "SELECT max(last_id) FROM compacted WHERE table_name = ?1 AND last_ts < ?2",
        params![table, cutoff_us],
        |row| row.get(0),
    )
}

/// The last id of `table`'s oldest block, if it has any.
pub(crate) fn oldest_block_end(db: &Connection, table: &str) -> rusqlite::Result<Option<i64>> {
    db.query_row(
        "SELECT last_id FROM compacted WHERE table_name = ?1 ORDER BY first_id LIMIT 1",
        [table],
        |row| row.get(0),
    )
    .or_else(|error| match error {
        rusqlite::Error::QueryReturnedNoRows => Ok(None),
        other => Err(other),
    })
}

/// Removes `table`'s blocks that end at or before `last`; returns the rows they held.
pub(crate) fn delete_blocks_through(
    db: &Connection,
    table: &str,
    last: i64,
) -> rusqlite::Result<u64> {
    let rows: i64 = db.query_row(
        "SELECT coalesce(sum(rows), 0) FROM compacted WHERE table_name = ?1 AND last_id <= ?2",
        params![table, last],
        |row| row.get(0),
    )?;
    db.execute(
        "DELETE FROM compacted WHERE table_name = ?1 AND last_id <= ?2",
        params![table, last],
    )?;
    Ok(u64::try_from(rows).unwrap_or(0))
}

/// Bytes the blocks' data takes.
pub(crate) fn block_bytes(db: &Connection) -> rusqlite::Result<u64> {
    let bytes: i64 = db.query_row(
        "SELECT coalesce(sum(length(data)), 0) FROM compacted",
        [],
        |row| row.get(0),
    )?;
    Ok(u64::try_from(bytes).unwrap_or(0))
}

/// The writer's compaction: a block at a time, between batches, while closed sessions have
/// plain rows.
#[derive(Debug, Default)]
pub struct Compaction {
    last: Option<Instant>,
    /// The table the next step starts looking at (round robin).
    next_table: usize,
    /// With no session open, every row counts as closed (`aer-raspi compact` with the service
    /// stopped); otherwise nothing is compacted then.
    offline: bool,
}

impl Compaction {
    /// Compaction with the service stopped: with no session open, every row is closed.
    pub fn everything_closed() -> Self {
        Self {
            offline: true,
            ..Self::default()
        }
    }

    /// Compacts blocks for up to [`STEP_FOR`] if due; returns the rows compacted.
    pub(crate) fn maybe_step(&mut self, db: &mut Connection) -> rusqlite::Result<u64> {
        if self.last.is_some_and(|last| last.elapsed() < STEP_EVERY) {
            return Ok(0);
        }
        let started = Instant::now();
        self.last = Some(started);
        let mut total = 0;
        loop {
            let rows = self.step(db)?;
            total += rows;
            if rows == 0 || started.elapsed() >= STEP_FOR {
                return Ok(total);
            }
        }
    }

    /// Compacts the oldest plain rows of closed sessions of the next table that has any, one
    /// block's worth, in one transaction; returns the rows compacted (0: nothing to do).
    pub fn step(&mut self, db: &mut Connection) -> rusqlite::Result<u64> {
        let transaction = db.transaction()?;
        // The service always records a session: without one it is not running (offline), or
        // could not record one, and then its rows are left alone.
        let open = session::current(&transaction)?;
        if open.is_none() && !self.offline {
            return Ok(0);
        }
        for offset in 0..TABLES.len() {
            let index = (self.next_table + offset) % TABLES.len();
            let Some(table) = TABLES.get(index) else {
                continue;
            };
            let recorded = match open {
                Some(open) => session::rows(&transaction, open, table.name)?,
                None => None,
            };
            let through = recorded.map_or(i64::MAX, |(first, _)| first - 1);
            let compacted = compact_block(&transaction, table, through)?;
            if compacted > 0 {
                self.next_table = (index + 1) % TABLES.len();
                transaction.commit()?;
                // Give the pages back to the file system.
                super::space::release_free_pages(db)?;
                return Ok(compacted);
            }
        }
        Ok(0)
    }
}

/// Moves up to [`BLOCK_ROWS`] of `table`'s oldest plain rows with ids up to `through` into a
/// block; returns how many.
fn compact_block(db: &Connection, table: &Table, through: i64) -> rusqlite::Result<u64> {
    let rows = plain_rows(db, table, i64::MIN, through, BLOCK_ROWS)?;
    let (Some((first_id, _)), Some((last_id, _))) = (rows.first(), rows.last()) else {
        return Ok(0);
    };
    let (first_id, last_id) = (*first_id, *last_id);
    let ts_at = table.tags.len();
    let ts = |row: Option<&(i64, Vec<Value>)>| match row.and_then(|(_, v)| v.get(ts_at)) {
        Some(Value::Integer(ts)) => *ts,
        _ => 0,
    };
    let (first_ts, last_ts) = (ts(rows.first()), ts(rows.last()));
    let data = zstd::bulk::compress(&encode(&rows), ZSTD_LEVEL)
        .map_err(|e| rusqlite::Error::ToSqlConversionFailure(Box::new(e)))?;
    let header: Vec<&str> = std::iter::once("id")
        .chain(table.local_columns().map(|c| c.name))
        .collect();
    db.execute(
        "INSERT INTO compacted (table_name, first_id, last_id, first_ts, last_ts, rows, columns, data) \
         VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8)",
        params![
            table.name,
            first_id,
            last_id,
            first_ts,
            last_ts,
            rows.len() as i64,
            header.join(","),
            data
        ],
    )?;
    db.execute(
        &format!("DELETE FROM \"{}\" WHERE id BETWEEN ?1 AND ?2", table.name),
        params![first_id, last_id],
    )?;
    Ok(rows.len() as u64)
}

/// Up to `limit` of `table`'s plain rows with ids in `first..=last`, in id order: each id and
/// its values in the table's local column order.
fn plain_rows(
    db: &Connection,
    table: &Table,
    first: i64,
    last: i64,
    limit: usize,
) -> rusqlite::Result<Vec<(i64, Vec<Value>)>> {
    let names: Vec<String> = table
        .local_columns()
        .map(|c| format!("\"{}\"", c.name))
        .collect();
    let mut statement = db.prepare_cached(&format!(
        "SELECT id, {} FROM \"{}\" WHERE id BETWEEN ?1 AND ?2 ORDER BY id LIMIT ?3",
        names.join(", "),
        table.name
    ))?;
    let mut found = statement.query(params![
        first,
        last,
        i64::try_from(limit).unwrap_or(i64::MAX)
    ])?;
    let mut rows = Vec::new();
    while let Some(row) = found.next()? {
        let values = (1..=names.len())
            .map(|i| row.get::<_, Value>(i))
            .collect::<rusqlite::Result<Vec<_>>>()?;
        rows.push((row.get(0)?, values));
    }
    Ok(rows)
}

/// The block data of `rows` (id, then values), column by column.
fn encode(rows: &[(i64, Vec<Value>)]) -> Vec<u8> {
    let width = rows.first().map_or(0, |(_, v)| v.len() + 1);
    let mut out = Vec::with_capacity(rows.len() * width * 2);
    for column in 0..width {
        let (mut last_integer, mut last_real) = (0i64, 0u64);
        for (id, values) in rows {
            let value = match column.checked_sub(1) {
                None => &Value::Integer(*id),
                Some(i) => values.get(i).unwrap_or(&Value::Null),
            };
            match value {
                Value::Null => out.push(TAG_NULL),
                Value::Integer(v) => {
                    out.push(TAG_INTEGER);
                    put_varint(&mut out, zigzag(v.wrapping_sub(last_integer)));
                    last_integer = *v;
                }
                Value::Real(v) => {
                    out.push(TAG_REAL);
                    out.extend_from_slice(&(v.to_bits() ^ last_real).to_le_bytes());
                    last_real = v.to_bits();
                }
                Value::Text(text) => {
                    out.push(TAG_TEXT);
                    put_varint(&mut out, text.len() as u64);
                    out.extend_from_slice(text.as_bytes());
                }
                Value::Blob(blob) => {
                    out.push(TAG_BLOB);
                    put_varint(&mut out, blob.len() as u64);
                    out.extend_from_slice(blob);
                }
            }
        }
    }
    out
}

/// Why block data does not decode (the block is named by the caller).
#[derive(Debug)]
enum DecodeError {
    Decompress,
    Damaged(&'static str),
}

impl DecodeError {
    fn in_block(self, table: &str, first_id: i64) -> BlockError {
        match self {
            Self::Decompress => BlockError::Decompress {
                table: table.to_owned(),
                first_id,
            },
            Self::Damaged(why) => BlockError::Damaged {
                table: table.to_owned(),
                first_id,
                why,
            },
        }
    }
}

/// A block's `count` rows, their values put in `columns`' order (names the block lacks are
/// NULL; columns it has that `columns` lacks are dropped).
fn decode(
    data: &[u8],
    names: &str,
    count: usize,
    columns: &[&str],
) -> Result<Vec<(i64, Vec<Value>)>, DecodeError> {
    let data = zstd::bulk::decompress(data, MAX_BLOCK_DATA).map_err(|_| DecodeError::Decompress)?;
    let names: Vec<&str> = names.split(',').collect();
    if names.first() != Some(&"id") {
        return Err(DecodeError::Damaged("first column is not the id"));
    }
    // Each value takes at least its tag: a count beyond the data is damage, not an allocation.
    if count.saturating_mul(names.len()) > data.len() {
        return Err(DecodeError::Damaged("more rows than data"));
    }
    let mut rows: Vec<(i64, Vec<Value>)> = (0..count)
        .map(|_| (0, vec![Value::Null; columns.len()]))
        .collect();
    let mut reader = Reader {
        data: &data,
        pos: 0,
    };
    for (index, name) in names.iter().enumerate() {
        let target = columns.iter().position(|c| c == name);
        let (mut last_integer, mut last_real) = (0i64, 0u64);
        for (id, values) in &mut rows {
            let value = match reader.byte()? {
                TAG_NULL => Value::Null,
                TAG_INTEGER => {
                    last_integer = last_integer.wrapping_add(unzigzag(reader.varint()?));
                    Value::Integer(last_integer)
                }
                TAG_REAL => {
                    last_real ^= reader.word()?;
                    Value::Real(f64::from_bits(last_real))
                }
                TAG_TEXT => {
                    let len = usize::try_from(reader.varint()?).unwrap_or(usize::MAX);
                    let text = std::str::from_utf8(reader.bytes(len)?)
                        .map_err(|_| DecodeError::Damaged("text not UTF-8"))?;
                    Value::Text(text.to_owned())
                }
                TAG_BLOB => {
                    let len = usize::try_from(reader.varint()?).unwrap_or(usize::MAX);
                    Value::Blob(reader.bytes(len)?.to_vec())
                }
                _ => return Err(DecodeError::Damaged("unknown value tag")),
            };
            if index == 0 {
                let Value::Integer(row_id) = value else {
                    return Err(DecodeError::Damaged("an id is not an integer"));
                };
                *id = row_id;
            } else if let Some(slot) = target.and_then(|t| values.get_mut(t)) {
                *slot = value;
            }
        }
    }
    if reader.pos != data.len() {
        return Err(DecodeError::Damaged("data after the last column"));
    }
    Ok(rows)
}

struct Reader<'a> {
    data: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    fn bytes(&mut self, len: usize) -> Result<&'a [u8], DecodeError> {
        let end = self
            .pos
            .checked_add(len)
            .ok_or(DecodeError::Damaged("length too large"))?;
        let bytes = self
            .data
            .get(self.pos..end)
            .ok_or(DecodeError::Damaged("cut short"))?;
        self.pos = end;
        Ok(bytes)
    }

    fn byte(&mut self) -> Result<u8, DecodeError> {
        self.bytes(1)
            .map(|b| b.first().copied().unwrap_or_default())
    }

    fn word(&mut self) -> Result<u64, DecodeError> {
        let mut word = [0u8; 8];
        word.copy_from_slice(self.bytes(8)?);
        Ok(u64::from_le_bytes(word))
    }

    fn varint(&mut self) -> Result<u64, DecodeError> {
        let (data, pos) = (self.data, &mut self.pos);
        read_varint(|| {
            let byte = data.get(*pos).copied();
            *pos += 1;
            byte
        })
        .ok_or(DecodeError::Damaged("varint cut short or too long"))
    }
}
