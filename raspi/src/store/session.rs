//! Sessions: who drove where, which run, and what the pit noted, stored with the data.
//!
//! The service opens a session when it starts (metadata from `[session]` in its config or the
//! command line) and closes it when it stops; `aer-raspi session new` starts the next one
//! while it runs (driver change, next run) and `aer-raspi session set` fills in or corrects
//! the metadata. The writer records, per session and table, the first and last row id it
//! committed, so an export of a session takes exactly its rows (replays carry recorded
//! timestamps, so time alone could not tell two replays of one log apart).

use rusqlite::{Connection, OptionalExtension, params};
use serde::Deserialize;

/// One row per session.
pub(crate) const SESSIONS_TABLE: &str = "CREATE TABLE IF NOT EXISTS \"sessions\" (\"id\" INTEGER PRIMARY KEY, \"started_us\" INTEGER NOT NULL, \"ended_us\" INTEGER, \"source\" TEXT NOT NULL, \"driver\" TEXT NOT NULL DEFAULT '', \"track\" TEXT NOT NULL DEFAULT '', \"run\" INTEGER, \"notes\" TEXT NOT NULL DEFAULT '', \"clock\" TEXT NOT NULL DEFAULT '')";

/// Each session's rows: per table, the first and last row id committed while it was open.
pub(crate) const SESSION_ROWS_TABLE: &str = "CREATE TABLE IF NOT EXISTS \"session_rows\" (\"session_id\" INTEGER NOT NULL, \"table_name\" TEXT NOT NULL, \"first_id\" INTEGER NOT NULL, \"last_id\" INTEGER NOT NULL, PRIMARY KEY (\"session_id\", \"table_name\"))";

/// What the pit records about a session. Every key is optional.
#[derive(Debug, Clone, Default, PartialEq, Eq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Metadata {
    pub driver: String,
    pub track: String,
    pub run: Option<u32>,
    pub notes: String,
}

/// Changes to a session's metadata: `None` leaves a value as it is.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Changes {
    pub driver: Option<String>,
    pub track: Option<String>,
    pub run: Option<u32>,
    pub notes: Option<String>,
}

impl Changes {
    /// The metadata with these changes applied.
    pub fn apply(&self, mut metadata: Metadata) -> Metadata {
        if let Some(driver) = &self.driver {
            driver.clone_into(&mut metadata.driver);
        }
        if let Some(track) = &self.track {
            track.clone_into(&mut metadata.track);
        }
        if self.run.is_some() {
            metadata.run = self.run;
        }
        if let Some(notes) = &self.notes {
            notes.clone_into(&mut metadata.notes);
        }
        metadata
    }
}

/// A stored session.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Session {
    pub id: i64,
    pub started_us: i64,
    /// `None` while open (or if the service was killed; the next start closes it).
    pub ended_us: Option<i64>,
    /// What fed the service: `live`, `replay`, `demo` or `export`.
    pub source: String,
    pub metadata: Metadata,
    /// Whether the wall clock was synchronized when the session began
    /// ([`super::clock::state`]; empty for sessions from before it was recorded).
    pub clock: String,
}

impl Session {
    /// The receive times (us since the epoch, both ends included) of what belongs to this
    /// session: from its start to just before its end, where the next one starts. The store
    /// files rows by it (`Filing::session_of`) and the export takes the raw log's frames by
    /// it, so every format of a session holds the same traffic. `None` at the end: still open.
    pub fn window(&self) -> (u64, Option<u64>) {
        let micros = |us: i64| u64::try_from(us).unwrap_or(0);
        (
            micros(self.started_us),
            self.ended_us.map(|end| micros(end).saturating_sub(1)),
        )
    }
}

/// Closes any session left open (a crash) at `now_us` and opens a new one.
pub fn begin(
    db: &Connection,
    metadata: &Metadata,
    source: &str,
    now_us: i64,
) -> rusqlite::Result<i64> {
    db.execute(
        "UPDATE sessions SET ended_us = ?1 WHERE ended_us IS NULL",
        [now_us],
    )?;
    db.execute(
        "INSERT INTO sessions (started_us, source, driver, track, run, notes, clock) VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7)",
        params![
            now_us,
            source,
            metadata.driver,
            metadata.track,
            metadata.run,
            metadata.notes,
            super::clock::state()
        ],
    )?;
    Ok(db.last_insert_rowid())
}

/// Closes the open session at `now_us` and opens the next with `metadata`, from the same
/// source (`aer-raspi session new` while the service runs: the run goes on, under a new
/// label). Without an open session, the next is `live`.
pub fn hand_over(db: &Connection, metadata: &Metadata, now_us: i64) -> rusqlite::Result<i64> {
    let source: Option<String> = db
        .query_row(
            "SELECT source FROM sessions WHERE ended_us IS NULL ORDER BY id DESC LIMIT 1",
            [],
            |r| r.get(0),
        )
        .optional()?;
    begin(db, metadata, source.as_deref().unwrap_or("live"), now_us)
}

/// The open session as the writer files rows into it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Filing {
    /// The open session.
    pub id: i64,
    /// When it began.
    pub started_us: i64,
    /// The session it took over from, when it began as that one ended with the same source
    /// (`session new` while the service ran): rows received before `started_us` and committed
    /// after belong to that one.
    pub took_over: Option<i64>,
}

impl Filing {
    /// The session a row received at `ts_us` belongs to, by the one rule every export format
    /// follows: the session open when it was received ([`Session::window`]).
    pub fn session_of(&self, ts_us: u64) -> i64 {
        match self.took_over {
            Some(before) if i64::try_from(ts_us).is_ok_and(|ts| ts < self.started_us) => before,
            _ => self.id,
        }
    }
}

/// The open session and what it took over from, if any.
pub(crate) fn filing(db: &Connection) -> rusqlite::Result<Option<Filing>> {
    let open: Option<(i64, i64, String)> = db
        .prepare_cached(
            "SELECT id, started_us, source FROM sessions WHERE ended_us IS NULL ORDER BY id DESC LIMIT 1",
        )?
        .query_row([], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?)))
        .optional()?;
    let Some((id, started_us, source)) = open else {
        return Ok(None);
    };
    let took_over = db
        .prepare_cached(
            "SELECT id FROM sessions WHERE id < ?1 AND ended_us = ?2 AND source = ?3 ORDER BY id DESC LIMIT 1",
        )?
        .query_row(params![id, started_us, source], |r| r.get(0))
        .optional()?;
    Ok(Some(Filing {
        id,
        started_us,
        took_over,
    }))
}

/// Closes the open session (the service's, or the one `aer-raspi session new` started while
/// it ran).
pub fn end(db: &Connection, now_us: i64) -> rusqlite::Result<()> {
    db.execute(
        "UPDATE sessions SET ended_us = ?1 WHERE ended_us IS NULL",
        [now_us],
    )?;
    Ok(())
}

/// The open session, if any (the newest, should a crash have left several).
pub fn current(db: &Connection) -> rusqlite::Result<Option<i64>> {
    db.query_row(
        "SELECT max(id) FROM sessions WHERE ended_us IS NULL",
        [],
        |r| r.get(0),
    )
}

/// Applies `changes` to session `id`; false if there is no such session.
pub fn change(db: &Connection, id: i64, changes: &Changes) -> rusqlite::Result<bool> {
    let Some(session) = get(db, id)? else {
        return Ok(false);
    };
    let m = changes.apply(session.metadata);
    db.execute(
        "UPDATE sessions SET driver = ?1, track = ?2, run = ?3, notes = ?4 WHERE id = ?5",
        params![m.driver, m.track, m.run, m.notes, id],
    )?;
    Ok(true)
}

fn from_row(r: &rusqlite::Row<'_>) -> rusqlite::Result<Session> {
    Ok(Session {
        id: r.get(0)?,
        started_us: r.get(1)?,
        ended_us: r.get(2)?,
        source: r.get(3)?,
        metadata: Metadata {
            driver: r.get(4)?,
            track: r.get(5)?,
            run: r.get(6)?,
            notes: r.get(7)?,
        },
        clock: r.get(8)?,
    })
}

/// Records a step of the wall clock (`step_us`, seen at `at_us`) in the open session; false if none is open.
pub fn record_clock_step(db: &Connection, at_us: i64, step_us: i64) -> rusqlite::Result<bool> {
    let Some(session) = current(db)? else {
        return Ok(false);
    };
    db.execute(
        "INSERT INTO session_clock (session_id, at_us, step_us) VALUES (?1, ?2, ?3)",
        params![session, at_us, step_us],
    )?;
    Ok(true)
}

/// The wall clock's steps while session `id` was open, oldest first: (when, by how much), microseconds.
pub fn clock_steps(db: &Connection, id: i64) -> rusqlite::Result<Vec<(i64, i64)>> {
    let mut statement = db
        .prepare("SELECT at_us, step_us FROM session_clock WHERE session_id = ?1 ORDER BY rowid")?;
    let steps = statement.query_map([id], |r| Ok((r.get(0)?, r.get(1)?)))?;
    steps.collect()
}

/// The columns of a session, as [`from_row`] reads them.
const COLUMNS: &str =
    "SELECT s.id, s.started_us, s.ended_us, s.source, s.driver, s.track, s.run, s.notes, s.clock";

/// Session `id`.
pub fn get(db: &Connection, id: i64) -> rusqlite::Result<Option<Session>> {
    db.query_row(
        &format!("{COLUMNS} FROM sessions s WHERE s.id = ?1"),
        [id],
        from_row,
    )
    .optional()
}

/// Every session, oldest first.
pub fn list(db: &Connection) -> rusqlite::Result<Vec<Session>> {
    let mut statement = db.prepare(&format!("{COLUMNS} FROM sessions s ORDER BY s.id"))?;
    let sessions = statement.query_map([], from_row)?;
    sessions.collect()
}

/// Every session, oldest first, with the rows it recorded (the width of its row ranges, every
/// table; retention may have removed the oldest since).
pub fn list_with_rows(db: &Connection) -> rusqlite::Result<Vec<(Session, u64)>> {
    let mut statement = db.prepare(&format!(
        "{}, coalesce((SELECT sum(last_id - first_id + 1) FROM session_rows r WHERE r.session_id = s.id), 0) \
         FROM sessions s ORDER BY s.id",
        COLUMNS
    ))?;
    let sessions = statement.query_map([], |r| {
        let rows: i64 = r.get(9)?;
        Ok((from_row(r)?, u64::try_from(rows).unwrap_or(0)))
    })?;
    sessions.collect()
}

/// Records that rows `first_id..=last_id` of `table` were committed while session `id` was
/// open (widening what is already recorded).
pub(crate) fn record_rows(
    db: &Connection,
    id: i64,
    table: &str,
    first_id: i64,
    last_id: i64,
) -> rusqlite::Result<()> {
    db.prepare_cached(
        "INSERT INTO session_rows (session_id, table_name, first_id, last_id) VALUES (?1, ?2, ?3, ?4) \
         ON CONFLICT (session_id, table_name) DO UPDATE SET \
         first_id = min(first_id, excluded.first_id), last_id = max(last_id, excluded.last_id)",
    )?
    .execute(params![id, table, first_id, last_id])?;
    Ok(())
}

/// The row ids of `table` that belong to session `id`, if it has any.
pub fn rows(db: &Connection, id: i64, table: &str) -> rusqlite::Result<Option<(i64, i64)>> {
    db.query_row(
        "SELECT first_id, last_id FROM session_rows WHERE session_id = ?1 AND table_name = ?2",
        params![id, table],
        |r| Ok((r.get(0)?, r.get(1)?)),
    )
    .optional()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn store() -> Connection {
        let db = Connection::open_in_memory().expect("memory");
        db.execute(SESSIONS_TABLE, []).expect("sessions");
        db.execute(SESSION_ROWS_TABLE, []).expect("rows");
        db
    }

    #[test]
    fn a_new_session_closes_the_one_a_crash_left_open() {
        let db = store();
        let first = begin(&db, &Metadata::default(), "live", 10).expect("begin");
        let meta = Metadata {
            driver: "Ana".into(),
            track: "Skidpad".into(),
            run: Some(3),
            notes: "new tyres".into(),
        };
        let second = begin(&db, &meta, "live", 20).expect("begin");
        let sessions = list(&db).expect("list");
        assert_eq!(sessions.len(), 2);
        assert_eq!(sessions[0].ended_us, Some(20));
        assert_eq!(sessions[1].metadata, meta);
        assert_eq!(current(&db).expect("current"), Some(second));
        end(&db, 30).expect("end");
        assert_eq!(current(&db).expect("current"), None);
        assert_ne!(first, second);
    }

    #[test]
    fn changes_touch_only_what_they_name_and_ranges_only_widen() {
        let db = store();
        let id = begin(&db, &Metadata::default(), "live", 0).expect("begin");
        let changes = Changes {
            driver: Some("Ben".into()),
            run: Some(4),
            ..Changes::default()
        };
        assert!(change(&db, id, &changes).expect("change"));
        assert!(!change(&db, id + 1, &changes).expect("change"));
        let notes = Changes {
            notes: Some("rain".into()),
            ..Changes::default()
        };
        assert!(change(&db, id, &notes).expect("change"));
        let session = get(&db, id).expect("get").expect("exists");
        assert_eq!(
            (
                session.metadata.driver.as_str(),
                session.metadata.run,
                session.metadata.notes.as_str()
            ),
            ("Ben", Some(4), "rain")
        );
        record_rows(&db, id, "telemetry", 5, 9).expect("rows");
        record_rows(&db, id, "telemetry", 10, 20).expect("rows");
        record_rows(&db, id, "telemetry", 7, 8).expect("rows");
        assert_eq!(rows(&db, id, "telemetry").expect("rows"), Some((5, 20)));
        record_rows(&db, id, "can_pcc_status", 1, 4).expect("rows");
        let empty = begin(&db, &Metadata::default(), "live", 40).expect("begin");
        let counted: Vec<(i64, u64)> = list_with_rows(&db)
            .expect("list")
            .into_iter()
            .map(|(s, rows)| (s.id, rows))
            .collect();
        assert_eq!(counted, [(id, 16 + 4), (empty, 0)]);
        assert_eq!(rows(&db, id, "can_vcu1").expect("rows"), None);
    }
}
