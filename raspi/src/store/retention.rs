//! Keeps the store within its budget: rows older than the age limit go, and while the store is
//! over its size budget the oldest rows go, the ones already forwarded to TDengine first.
//! Freed pages go back to the file system. Runs on the writer thread between batches, so it
//! never races a write.
//!
//! The free-space floor is different: the store is not the only thing on the card, so pruning
//! may not be able to reach it (a card smaller than the floor, other files filling it). Below
//! the floor only rows recorded before the session being recorded go, oldest (forwarded)
//! first, and only when removing them can bring the free space back over the floor. Otherwise
//! nothing is removed: the status and the journal say the disk is low, live telemetry and the
//! raw log go on, and a truly full disk is handled by the writer (rows dropped and counted).

use super::{compact, session};
use crate::health::Health;
use aer::tables::TABLES;
use aer_host::clock::now_us;
use aer_host::reports::counters::Counters;
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

/// What one pass did.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Pruned {
    /// Rows removed.
    pub rows: u64,
    /// Why the disk stays under the free-space floor, when pruning cannot lift it.
    pub disk_low: Option<String>,
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

    /// Prunes if the interval has passed since the last check; reports a disk that stays low
    /// on `health` (and once in the journal).
    pub(crate) fn maybe_prune(&mut self, db: &Connection, counters: &Counters, health: &Health) {
        if self
            .last
            .is_some_and(|last| last.elapsed() < self.budget.interval)
        {
            return;
        }
        self.last = Some(Instant::now());
        match self.prune(db) {
            Ok(pruned) => {
                if pruned.rows > 0 {
                    counters
                        .pruned_rows
                        .fetch_add(pruned.rows, Ordering::Relaxed);
                    info!(rows = pruned.rows, "store pruned to its budget");
                }
                match pruned.disk_low {
                    Some(why) => {
                        if health.disk.error().is_none() {
                            warn!(reason = %why, "disk low: the session being recorded is kept, live telemetry and the raw log go on");
                        }
                        health.disk.failed(&why);
                    }
                    None => {
                        if health.disk.recovered() {
                            info!("disk space back above the floor");
                        }
                    }
                }
            }
            Err(error) => warn!(%error, "store retention failed; retrying at the next check"),
        }
    }

    /// One pass: the age limit, the size budget, then the free-space floor.
    pub fn prune(&self, db: &Connection) -> rusqlite::Result<Pruned> {
        let mut pruned = Pruned::default();
        if let Some(max_age) = self.budget.max_age {
            let cutoff = now_us().saturating_sub(max_age.as_micros() as u64);
            for table in TABLES {
                let Some(last_old) = last_id_before(db, table.name, cutoff)? else {
                    continue;
                };
                pruned.rows += delete_through(db, table.name, last_old)?;
            }
        }
        for _ in 0..MAX_STEPS {
            if used_bytes(db)? <= self.budget.max_bytes {
                break;
            }
            let step = drop_oldest_either(db, &Kept::default())?;
            if step == 0 {
                break;
            }
            pruned.rows += step;
        }
        let (rows, disk_low) = self.lift_to_floor(db)?;
        pruned.rows += rows;
        pruned.disk_low = disk_low;
        if pruned.rows > 0 {
            // Give the freed pages back (a store made before auto_vacuum keeps reusing them).
            super::space::release_free_pages(db)?;
            db.query_row("PRAGMA wal_checkpoint(TRUNCATE)", [], |_| Ok(()))?;
        }
        Ok(pruned)
    }

    /// Below the free-space floor: removes rows recorded before the current session while
    /// that can lift the free space over the floor. Returns the rows removed and, if the disk
    /// stays low, why.
    fn lift_to_floor(&self, db: &Connection) -> rusqlite::Result<(u64, Option<String>)> {
        let floor = self.budget.min_free_bytes;
        let Some(free) = (self.free_space)(&self.path) else {
            return Ok((0, None));
        };
        if free >= floor {
            return Ok((0, None));
        }
        let kept = Kept::current_session(db)?;
        let used = used_bytes(db)?;
        let (older, all) = kept.older_rows(db)?;
        // Compacted blocks all precede the open session and give back what they take. Plain
        // rows are about the same size across the store: their share of the rest is what
        // removing them gives back.
        let blocks = compact::block_bytes(db)?;
        let plain = used.saturating_sub(blocks);
        let freeable = blocks
            + if all == 0 {
                0
            } else {
                u64::try_from(u128::from(plain) * u128::from(older) / u128::from(all))
                    .unwrap_or(plain)
            };
        let low = |free: u64| {
            format!(
                "{} MB free, under the {} MB floor; the session being recorded is kept",
                free / 1_000_000,
                floor / 1_000_000
            )
        };
        if free.saturating_add(freeable) < floor {
            return Ok((0, Some(low(free))));
        }
        let mut removed = 0;
        for _ in 0..MAX_STEPS {
            // Pages freed in this pass go back to the file system at its end.
            let freed = used.saturating_sub(used_bytes(db)?);
            if free.saturating_add(freed) >= floor {
                return Ok((removed, None));
            }
            let step = drop_oldest_either(db, &kept)?;
            if step == 0 {
                break;
            }
            removed += step;
        }
        let now_free = free.saturating_add(used.saturating_sub(used_bytes(db)?));
        Ok((removed, (now_free < floor).then(|| low(now_free))))
    }
}

/// The rows the free-space floor may not remove: per table, the first row id of the session
/// being recorded.
#[derive(Debug, Default)]
struct Kept {
    first_ids: Vec<(&'static str, i64)>,
}

impl Kept {
    /// The open session's rows (none kept when no session is open).
    fn current_session(db: &Connection) -> rusqlite::Result<Self> {
        let mut first_ids = Vec::new();
        if let Some(id) = session::current(db)? {
            for table in TABLES {
                // A table the session has no rows in yet: all of its rows are older.
                if let Some((first, _)) = session::rows(db, id, table.name)? {
                    first_ids.push((table.name, first));
                }
            }
        }
        Ok(Self { first_ids })
    }

    /// The first id kept in `table` (`i64::MAX`: none).
    fn first_in(&self, table: &str) -> i64 {
        self.first_ids
            .iter()
            .find(|(name, _)| *name == table)
            .map_or(i64::MAX, |(_, first)| *first)
    }

    /// Plain rows that may go, and all plain rows, over every table.
    fn older_rows(&self, db: &Connection) -> rusqlite::Result<(u64, u64)> {
        let (mut older, mut all) = (0u64, 0u64);
        for table in TABLES {
            let (may_go, total): (i64, i64) = db.query_row(
                &format!(
                    "SELECT count(*) FILTER (WHERE id < ?1), count(*) FROM \"{}\"",
                    table.name
                ),
                [self.first_in(table.name)],
                |row| Ok((row.get(0)?, row.get(1)?)),
            )?;
            older += u64::try_from(may_go).unwrap_or(0);
            all += u64::try_from(total).unwrap_or(0);
        }
        Ok((older, all))
    }
}

/// Removes a chunk of the oldest rows not `kept`, the ones already forwarded first (a warning
/// says when rows not yet forwarded go). Returns the rows removed.
fn drop_oldest_either(db: &Connection, kept: &Kept) -> rusqlite::Result<u64> {
    let step = drop_oldest(db, true, kept)?;
    if step > 0 {
        return Ok(step);
    }
    let step = drop_oldest(db, false, kept)?;
    if step > 0 {
        warn!(
            rows = step,
            "store over budget with nothing forwarded left to prune: oldest rows pruned (the raw log still has their frames)"
        );
    }
    Ok(step)
}

/// Removes a chunk of the oldest rows of every table, never those `kept`: only rows already
/// forwarded to TDengine if `forwarded_only`, else the oldest of all.
fn drop_oldest(db: &Connection, forwarded_only: bool, kept: &Kept) -> rusqlite::Result<u64> {
    let mut removed = 0;
    for table in TABLES {
        let forwarded: Option<i64> = db
            .query_row(
                "SELECT last_id FROM forward_cursor WHERE table_name = ?1",
                [table.name],
                |row| row.get(0),
            )
            .optional()?;
        let (Some(oldest), Some(newest)) = compact::id_bounds(db, table.name)? else {
            continue;
        };
        let last_allowed = kept.first_in(table.name).saturating_sub(1);
        if last_allowed < oldest {
            continue;
        }
        // A twentieth of the table a step: the budget is met without overshooting it; a
        // compacted block goes whole.
        let step = ((newest - oldest + 1) / 20).clamp(100, CHUNK_ROWS);
        let block_end = compact::oldest_block_end(db, table.name)?.unwrap_or(i64::MIN);
        let through = (oldest + step - 1).max(block_end).min(last_allowed);
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

/// The last row id of `table` written before `cutoff_us` (of a compacted block, the last of
/// the newest block wholly before it): rows arrive in time order, so ids are searched (the
/// store keeps no time index, which would cost a write per commit).
fn last_id_before(db: &Connection, table: &str, cutoff_us: u64) -> rusqlite::Result<Option<i64>> {
    let cutoff = i64::try_from(cutoff_us).unwrap_or(i64::MAX);
    let in_blocks = compact::last_id_of_blocks_before(db, table, cutoff)?;
    let bounds: (Option<i64>, Option<i64>) = db.query_row(
        &format!("SELECT min(id), max(id) FROM \"{table}\""),
        [],
        |row| Ok((row.get(0)?, row.get(1)?)),
    )?;
    let (Some(mut lo), Some(mut hi)) = bounds else {
        return Ok(in_blocks);
    };
    let ts_at = |id: i64| -> rusqlite::Result<Option<i64>> {
        db.query_row(
            &format!("SELECT ts FROM \"{table}\" WHERE id >= ?1 ORDER BY id LIMIT 1"),
            [id],
            |row| row.get(0),
        )
        .optional()
    };
    if ts_at(lo)?.is_none_or(|ts| ts >= cutoff) {
        return Ok(in_blocks);
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

/// Deletes `table`'s rows with ids up to `last`, a chunk at a time, and its compacted blocks
/// that end by then.
fn delete_through(db: &Connection, table: &str, last: i64) -> rusqlite::Result<u64> {
    let mut removed = compact::delete_blocks_through(db, table, last)?;
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
