//! Keeps the store within its budget: rows older than the age limit go, and while the store is
//! over its size budget or the disk below its free-space floor, the oldest rows go, the ones
//! already forwarded to TDengine first. Freed pages go back to the file system. Runs on the
//! writer thread between batches, so it never races a write.

use aer::tables::TABLES;
use aer_host::clock::now_us;
use aer_host::counters::Counters;
use rusqlite::{Connection, OptionalExtension};
use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};
use tracing::{info, warn};

/// Rows removed per table per step, so one pass never holds the writer for long.
const CHUNK_ROWS: i64 = 20_000;
/// Steps per pass at most (the next pass, one interval later, goes on).
const MAX_STEPS: usize = 50;

/// The store's budget.
#[derive(Debug, Clone, PartialEq)]
pub struct Budget {
    /// The most the store may take on disk (its pages in use).
    pub max_bytes: u64,
    /// Rows older than this go, forwarded or not.
    pub max_age: Option<Duration>,
    /// Below this much free space on the store's file system, the oldest rows go.
    pub min_free_bytes: u64,
    /// How often the budget is checked.
    pub interval: Duration,
}

/// Free bytes on the file system holding a path.
type FreeSpace = Box<dyn Fn(&std::path::Path) -> Option<u64> + Send>;

/// The retention state.
pub struct Retention {
    budget: Budget,
    /// The store's file, for its WAL and its file system's free space.
    path: PathBuf,
    last: Option<Instant>,
    free_space: FreeSpace,
}

impl Retention {
    /// Retention of the store at `path` within `budget`.
    pub fn new(path: PathBuf, budget: Budget) -> Self {
        Self {
            budget,
            path,
            last: None,
            free_space: Box::new(crate::disk::free_bytes),
        }
    }

    /// The same, with `free_space` standing in for the file system's free space (tests).
    pub fn with_free_space(
        mut self,
        free_space: impl Fn(&std::path::Path) -> Option<u64> + Send + 'static,
    ) -> Self {
        self.free_space = Box::new(free_space);
        self
    }

    /// Prunes if the interval has passed since the last check.
    pub fn maybe_prune(&mut self, db: &Connection, counters: &Counters) {
        if self
            .last
            .is_some_and(|last| last.elapsed() < self.budget.interval)
        {
            return;
        }
        self.last = Some(Instant::now());
        match self.prune(db) {
            Ok(0) => {}
            Ok(rows) => {
                counters.pruned_rows.fetch_add(rows, Ordering::Relaxed);
                info!(rows, "store pruned to its budget");
            }
            Err(error) => warn!(%error, "store retention failed; retrying at the next check"),
        }
    }

    /// One pass: the age limit, then the size budget and the free-space floor. Returns the
    /// rows removed.
    pub fn prune(&self, db: &Connection) -> rusqlite::Result<u64> {
        let mut removed = 0;
        if let Some(max_age) = self.budget.max_age {
            let cutoff = now_us().saturating_sub(max_age.as_micros() as u64);
            for table in TABLES {
                let Some(last_old) = last_id_before(db, table.name, cutoff)? else {
                    continue;
                };
                removed += delete_through(db, table.name, last_old)?;
            }
        }
        for _ in 0..MAX_STEPS {
            if !self.over_budget(db)? {
                break;
            }
            let mut step = self.drop_oldest(db, true)?;
            if step == 0 {
                step = self.drop_oldest(db, false)?;
                if step > 0 {
                    warn!(
                        rows = step,
                        "store over budget with nothing forwarded left to prune: oldest rows pruned (the raw log still has their frames)"
                    );
                }
            }
            if step == 0 {
                break;
            }
            removed += step;
        }
        if removed > 0 {
            // Give the freed pages back (a store made before auto_vacuum keeps reusing them).
            db.execute_batch("PRAGMA incremental_vacuum")?;
            db.query_row("PRAGMA wal_checkpoint(TRUNCATE)", [], |_| Ok(()))?;
        }
        Ok(removed)
    }

    /// Over the size budget (pages in use; the WAL, at most a checkpoint's worth, aside) or
    /// under the free-space floor.
    fn over_budget(&self, db: &Connection) -> rusqlite::Result<bool> {
        let used = used_bytes(db)?;
        let free = (self.free_space)(&self.path).unwrap_or(u64::MAX);
        Ok(used > self.budget.max_bytes || free < self.budget.min_free_bytes)
    }

    /// Removes a chunk of the oldest rows of every table: only rows already forwarded to
    /// TDengine if `forwarded_only`, else the oldest of all.
    fn drop_oldest(&self, db: &Connection, forwarded_only: bool) -> rusqlite::Result<u64> {
        let mut removed = 0;
        for table in TABLES {
            let forwarded: Option<i64> = db
                .query_row(
                    "SELECT last_id FROM forward_cursor WHERE table_name = ?1",
                    [table.name],
                    |row| row.get(0),
                )
                .optional()?;
            let bounds: (Option<i64>, Option<i64>) = db.query_row(
                &format!("SELECT min(id), max(id) FROM \"{}\"", table.name),
                [],
                |row| Ok((row.get(0)?, row.get(1)?)),
            )?;
            let (Some(oldest), Some(newest)) = bounds else {
                continue;
            };
            // A twentieth of the table a step: the budget is met without overshooting it.
            let step = ((newest - oldest + 1) / 20).clamp(100, CHUNK_ROWS);
            let through = oldest + step - 1;
            removed += match (forwarded, forwarded_only) {
                (Some(cursor), true) if cursor >= oldest => {
                    delete_through(db, table.name, through.min(cursor))?
                }
                (_, true) => 0,
                (_, false) => delete_through(db, table.name, through)?,
            };
        }
        Ok(removed)
    }
}

/// The last row id of `table` written before `cutoff_us`: rows arrive in time order, so ids
/// are searched (the store keeps no time index, which would cost a write per commit).
fn last_id_before(db: &Connection, table: &str, cutoff_us: u64) -> rusqlite::Result<Option<i64>> {
    let bounds: (Option<i64>, Option<i64>) = db.query_row(
        &format!("SELECT min(id), max(id) FROM \"{table}\""),
        [],
        |row| Ok((row.get(0)?, row.get(1)?)),
    )?;
    let (Some(mut lo), Some(mut hi)) = bounds else {
        return Ok(None);
    };
    let cutoff = i64::try_from(cutoff_us).unwrap_or(i64::MAX);
    let ts_at = |id: i64| -> rusqlite::Result<Option<i64>> {
        db.query_row(
            &format!("SELECT ts FROM \"{table}\" WHERE id >= ?1 ORDER BY id LIMIT 1"),
            [id],
            |row| row.get(0),
        )
        .optional()
    };
    if ts_at(lo)?.is_none_or(|ts| ts >= cutoff) {
        return Ok(None);
    }
    // Invariant: the row at or after `lo` is older than the cutoff.
    while lo < hi {
        let mid = lo + (hi - lo + 1) / 2;
        if ts_at(mid)?.is_some_and(|ts| ts < cutoff) {
            lo = mid;
        } else {
            hi = mid - 1;
        }
    }
    Ok(Some(lo))
}

/// Deletes `table`'s rows with ids up to `last`, a chunk at a time.
fn delete_through(db: &Connection, table: &str, last: i64) -> rusqlite::Result<u64> {
    let mut removed = 0u64;
    loop {
        let deleted = db.execute(
            &format!(
                "DELETE FROM \"{table}\" WHERE id IN (SELECT id FROM \"{table}\" WHERE id <= ?1 ORDER BY id LIMIT ?2)"
            ),
            [last, CHUNK_ROWS],
        )?;
        removed += deleted as u64;
        if (deleted as i64) < CHUNK_ROWS {
            return Ok(removed);
        }
    }
}

/// Bytes of the store's pages in use.
fn used_bytes(db: &Connection) -> rusqlite::Result<u64> {
    let pragma = |name: &str| -> rusqlite::Result<u64> {
        db.query_row(&format!("PRAGMA {name}"), [], |row| row.get::<_, i64>(0))
            .map(|v| u64::try_from(v).unwrap_or(0))
    };
    let pages = pragma("page_count")?.saturating_sub(pragma("freelist_count")?);
    Ok(pages * pragma("page_size")?)
}
