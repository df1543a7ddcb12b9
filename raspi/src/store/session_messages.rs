//! Each session's CAN messages as the store took them: per bus and message, the frames
//! committed, when the first and the last came (so the measured rate, beside the schema's
//! cycle time), and how many the schema's counter, checksum and freshness limit flagged. One
//! row per session, bus and message, added to with every commit, so the table stays small
//! however long the session runs. `aer-raspi session messages` prints it.

use super::row::{Row, RowData};
use aer_host::reports::traffic;
use rusqlite::{Connection, params};
use std::collections::HashMap;
use std::sync::Arc;

/// One row per session, bus and message.
pub(crate) const SESSION_MESSAGES_TABLE: &str = "CREATE TABLE IF NOT EXISTS \"session_messages\" (\"session_id\" INTEGER NOT NULL, \"bus\" TEXT NOT NULL, \"message\" TEXT NOT NULL, \"frames\" INTEGER NOT NULL, \"first_us\" INTEGER NOT NULL, \"last_us\" INTEGER NOT NULL, \"checksum_failures\" INTEGER NOT NULL, \"counter_repeats\" INTEGER NOT NULL, \"counter_jumps\" INTEGER NOT NULL, \"late_frames\" INTEGER NOT NULL, PRIMARY KEY (\"session_id\", \"bus\", \"message\"))";

/// Adds a batch's counts to what the session already has.
const UPSERT: &str = "INSERT INTO session_messages (session_id, bus, message, frames, first_us, last_us, checksum_failures, counter_repeats, counter_jumps, late_frames) VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10) ON CONFLICT (session_id, bus, message) DO UPDATE SET frames = frames + excluded.frames, first_us = min(first_us, excluded.first_us), last_us = max(last_us, excluded.last_us), checksum_failures = checksum_failures + excluded.checksum_failures, counter_repeats = counter_repeats + excluded.counter_repeats, counter_jumps = counter_jumps + excluded.counter_jumps, late_frames = late_frames + excluded.late_frames";

/// One message on one bus in one session.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct MessageStats {
    pub bus: String,
    /// The message's name in the schema.
    pub message: String,
    /// Frames the store committed.
    pub frames: u64,
    /// Receive time of the first and the last (us since the epoch).
    pub first_us: i64,
    pub last_us: i64,
    pub checksum_failures: u64,
    pub counter_repeats: u64,
    pub counter_jumps: u64,
    /// Frames later than the message's freshness limit after the previous one.
    pub late_frames: u64,
}

impl MessageStats {
    /// Frames per second between the first frame and the last (`None` below two frames).
    pub fn measured_hz(&self) -> Option<f64> {
        let us = |t: i64| u64::try_from(t).unwrap_or(0);
        traffic::measured_hz(self.frames, us(self.first_us), us(self.last_us))
    }

    /// What the schema's cycle time implies (`None` for a message sent on demand, or one of
    /// another schema).
    pub fn declared_hz(&self) -> Option<f64> {
        aer::can::MESSAGES
            .iter()
            .find(|m| m.name == self.message)
            .and_then(|m| traffic::declared_hz(m))
    }
}

/// A batch's CAN rows summed per bus and message, for [`Tally::record`].
#[derive(Debug, Default)]
pub(crate) struct Tally(HashMap<(Arc<str>, &'static str), MessageStats>);

impl Tally {
    /// Counts `row` if it is a CAN frame.
    pub(crate) fn add(&mut self, row: &Row) {
        let RowData::Can {
            bus,
            message,
            check,
        } = &row.data
        else {
            return;
        };
        let ts = i64::try_from(row.ts_us).unwrap_or(i64::MAX);
        let stats = self
            .0
            .entry((bus.clone(), message.meta().name))
            .or_insert_with(|| MessageStats {
                first_us: ts,
                last_us: ts,
                ..MessageStats::default()
            });
        stats.frames += 1;
        stats.first_us = stats.first_us.min(ts);
        stats.last_us = stats.last_us.max(ts);
        stats.checksum_failures += u64::from(check.checksum_failed);
        stats.counter_repeats += u64::from(check.counter_repeated);
        stats.counter_jumps += u64::from(check.counter_jumped);
        stats.late_frames += u64::from(check.late);
    }

    /// Adds the counts to session `session`'s rows.
    pub(crate) fn record(&self, db: &Connection, session: i64) -> rusqlite::Result<()> {
        if self.0.is_empty() {
            return Ok(());
        }
        let mut upsert = db.prepare_cached(UPSERT)?;
        let int = |n: u64| i64::try_from(n).unwrap_or(i64::MAX);
        for ((bus, message), s) in &self.0 {
            upsert.execute(params![
                session,
                &**bus,
                message,
                int(s.frames),
                s.first_us,
                s.last_us,
                int(s.checksum_failures),
                int(s.counter_repeats),
                int(s.counter_jumps),
                int(s.late_frames),
            ])?;
        }
        Ok(())
    }
}

/// Session `session`'s messages, by bus and name.
pub fn list(db: &Connection, session: i64) -> rusqlite::Result<Vec<MessageStats>> {
    let mut query = db.prepare(
        "SELECT bus, message, frames, first_us, last_us, checksum_failures, counter_repeats, \
         counter_jumps, late_frames FROM session_messages WHERE session_id = ?1 \
         ORDER BY bus, message",
    )?;
    let count = |v: i64| u64::try_from(v).unwrap_or(0);
    query
        .query_map([session], |r| {
            Ok(MessageStats {
                bus: r.get(0)?,
                message: r.get(1)?,
                frames: count(r.get(2)?),
                first_us: r.get(3)?,
                last_us: r.get(4)?,
                checksum_failures: count(r.get(5)?),
                counter_repeats: count(r.get(6)?),
                counter_jumps: count(r.get(7)?),
                late_frames: count(r.get(8)?),
            })
        })?
        .collect()
}
