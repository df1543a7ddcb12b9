//! What happened during a session besides its data, each with when: the lap marks (the
//! driver's or the pit's), every `problems` entry of the status as it appeared and cleared,
//! the drops and integrity counts as they grew, a looping replay's loop points. The run report
//! (`aer-raspi report`) lists them and times the laps with the marks; `aer-raspi session
//! events` prints them.

use rusqlite::{Connection, params};

/// One row per event, in the session open when the store took it.
pub(crate) const EVENTS_TABLE: &str = "CREATE TABLE IF NOT EXISTS \"session_events\" (\"session_id\" INTEGER NOT NULL, \"at_us\" INTEGER NOT NULL, \"kind\" TEXT NOT NULL, \"name\" TEXT NOT NULL, \"text\" TEXT NOT NULL DEFAULT '')";

/// What an event records.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Kind {
    /// Someone ended the lap in progress (`name`: who, `driver` or `pit`).
    Mark,
    /// A `problems` entry of the status appeared or changed (`name`: the entry, `text`: it).
    Problem,
    /// A `problems` entry cleared.
    Cleared,
    /// A counter of drops or faults grew (`name`: the counter, `text`: by how much).
    Counted,
    /// A looping replay started its log again (the demo's loop point).
    Loop,
}

impl Kind {
    /// The name the store and the report use.
    pub const fn name(self) -> &'static str {
        match self {
            Self::Mark => "mark",
            Self::Problem => "problem",
            Self::Cleared => "cleared",
            Self::Counted => "counted",
            Self::Loop => "loop",
        }
    }

    fn from_name(name: &str) -> Option<Self> {
        [
            Self::Mark,
            Self::Problem,
            Self::Cleared,
            Self::Counted,
            Self::Loop,
        ]
        .into_iter()
        .find(|kind| kind.name() == name)
    }
}

/// One event.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Event {
    /// When (us since the epoch, the Pi's clock).
    pub at_us: i64,
    pub kind: Kind,
    pub name: String,
    pub text: String,
}

/// Adds `events` to session `session` inside the caller's transaction.
pub(crate) fn insert(db: &Connection, session: i64, events: &[Event]) -> rusqlite::Result<()> {
    let mut insert = db.prepare_cached(
        "INSERT INTO session_events (session_id, at_us, kind, name, text) VALUES (?1, ?2, ?3, ?4, ?5)",
    )?;
    for e in events {
        insert.execute(params![session, e.at_us, e.kind.name(), e.name, e.text])?;
    }
    Ok(())
}

/// Session `session`'s events in the order they were recorded.
pub fn list(db: &Connection, session: i64) -> rusqlite::Result<Vec<Event>> {
    let mut query = db.prepare(
        "SELECT at_us, kind, name, text FROM session_events WHERE session_id = ?1 ORDER BY rowid",
    )?;
    let rows = query.query_map([session], |r| {
        let kind: String = r.get(1)?;
        Ok(Event {
            at_us: r.get(0)?,
            // A kind this build does not know (a newer build's store) reads as a count: the
            // text stays visible.
            kind: Kind::from_name(&kind).unwrap_or(Kind::Counted),
            name: r.get(2)?,
            text: r.get(3)?,
        })
    })?;
    rows.collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn events_read_back_per_session_in_order() {
        let db = Connection::open_in_memory().expect("memory");
        db.execute(EVENTS_TABLE, []).expect("table");
        let event = |at_us, kind, name: &str| Event {
            at_us,
            kind,
            name: name.into(),
            text: format!("{name} at {at_us}"),
        };
        let first = vec![
            event(2, Kind::Problem, "can"),
            event(1, Kind::Mark, "pit"),
            event(3, Kind::Loop, "loop"),
        ];
        insert(&db, 1, &first).expect("record");
        insert(&db, 2, &[event(4, Kind::Cleared, "can")]).expect("record");
        assert_eq!(list(&db, 1).expect("list"), first);
        assert_eq!(list(&db, 2).expect("list").len(), 1);
        assert!(list(&db, 3).expect("list").is_empty());
    }
}
