//! Each session's calibration record: every change a pit master made to the CCM's calibration
//! through the XCP gateway (when, from where, which parameter, old and new value, accepted or
//! refused and why, and the checksum the CCM runs on after it), and the values the gateway
//! found when each master connected. With it, a run's data says which calibration produced
//! it, and two runs' calibrations compare. `aer-raspi session calibration` prints it; the
//! exports carry it.

pub use aer_host::calibration::number;
use rusqlite::{Connection, params};
use std::fmt;

/// One row per entry, in the session that was open when the store took it.
pub(crate) const CALIBRATION_TABLE: &str = "CREATE TABLE IF NOT EXISTS \"session_calibration\" (\"session_id\" INTEGER NOT NULL, \"at_us\" INTEGER NOT NULL, \"master\" TEXT NOT NULL, \"kind\" TEXT NOT NULL, \"parameter\" TEXT NOT NULL, \"element\" INTEGER, \"old\" REAL, \"new\" REAL, \"accepted\" INTEGER NOT NULL, \"reason\" TEXT NOT NULL, \"checksum\" INTEGER)";

/// What an entry records.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Kind {
    /// The value as the gateway read it when a master connected (old and new alike).
    Found,
    /// A value written (DOWNLOAD).
    Write,
    /// A value the reference page (the schema's defaults) restored (COPY_CAL_PAGE).
    Revert,
    /// The page the control step runs on (SET_CAL_PAGE): 0 working, 1 reference.
    Page,
    /// The working page saved to flash, for the next start (SET_REQUEST).
    Save,
}

impl Kind {
    /// The name the store and the exports use.
    pub const fn name(self) -> &'static str {
        match self {
            Self::Found => "found",
            Self::Write => "write",
            Self::Revert => "revert",
            Self::Page => "page",
            Self::Save => "save",
        }
    }

    fn from_name(name: &str) -> Option<Self> {
        [
            Self::Found,
            Self::Write,
            Self::Revert,
            Self::Page,
            Self::Save,
        ]
        .into_iter()
        .find(|kind| kind.name() == name)
    }
}

/// The parameter name of a [`Kind::Page`] entry.
pub const ECU_PAGE: &str = "ecu_page";

/// One change (or attempt, or finding) of the CCM's calibration.
#[derive(Debug, Clone, PartialEq)]
pub struct Entry {
    /// When the CCM answered (us since the epoch).
    pub at_us: i64,
    /// The master's address (`10.9.0.2:51234`).
    pub master: String,
    pub kind: Kind,
    /// The parameter's name in the schema ([`ECU_PAGE`] for a page switch, empty for a save;
    /// the address in hex for a write outside the calibration page).
    pub parameter: String,
    /// The element of a curve or list (`None` for a scalar).
    pub element: Option<u32>,
    /// The value before (`None` when the gateway did not know it).
    pub old: Option<f64>,
    /// The value after, or the one refused.
    pub new: Option<f64>,
    pub accepted: bool,
    /// Why the CCM refused it (empty when accepted).
    pub reason: String,
    /// CRC-32 of the page the CCM runs on afterwards, as `CCM_CalChecksum` reports it
    /// (`None` when the gateway did not know the whole page).
    pub checksum: Option<u32>,
}

impl Entry {
    /// The parameter with its element: `tc_slip_target`, `pedal_map[3]`.
    pub fn target(&self) -> String {
        match self.element {
            Some(index) => format!("{}[{index}]", self.parameter),
            None => self.parameter.clone(),
        }
    }
}

impl fmt::Display for Entry {
    /// One line: `write tc_gain 0.1 -> 0.14 accepted (10.9.0.2:51234)`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let value = |v: Option<f64>| v.map_or_else(|| "?".to_owned(), number);
        write!(f, "{} {}", self.kind.name(), self.target())?;
        if self.kind != Kind::Save {
            write!(f, " {} -> {}", value(self.old), value(self.new))?;
        }
        if self.accepted {
            write!(f, " accepted")?;
        } else {
            write!(f, " refused: {}", self.reason)?;
        }
        write!(f, " ({})", self.master)
    }
}

/// Adds `entries` to session `session`, all or none.
pub fn record(db: &Connection, session: i64, entries: &[Entry]) -> rusqlite::Result<()> {
    // All or none: the writer retries a failed batch whole, which must not store any twice.
    let transaction = db.unchecked_transaction()?;
    insert(&transaction, session, entries)?;
    transaction.commit()
}

/// Adds `entries` to session `session` inside the caller's transaction.
pub(crate) fn insert(db: &Connection, session: i64, entries: &[Entry]) -> rusqlite::Result<()> {
    let mut insert = db.prepare_cached(
        "INSERT INTO session_calibration (session_id, at_us, master, kind, parameter, element, \
         old, new, accepted, reason, checksum) VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11)",
    )?;
    for e in entries {
        insert.execute(params![
            session,
            e.at_us,
            e.master,
            e.kind.name(),
            e.parameter,
            e.element,
            e.old.filter(|v| v.is_finite()),
            e.new.filter(|v| v.is_finite()),
            e.accepted,
            e.reason,
            e.checksum,
        ])?;
    }
    Ok(())
}

/// The entries between `from_us` and `to_us` (inclusive, either open) of session `session`
/// (or of every session), in the order they were recorded.
pub fn list(
    db: &Connection,
    session: Option<i64>,
    from_us: Option<i64>,
    to_us: Option<i64>,
) -> rusqlite::Result<Vec<Entry>> {
    let mut query = db.prepare(
        "SELECT at_us, master, kind, parameter, element, old, new, accepted, reason, checksum \
         FROM session_calibration WHERE (?1 IS NULL OR session_id = ?1) AND at_us >= ?2 \
         AND at_us <= ?3 ORDER BY rowid",
    )?;
    let rows = query.query_map(
        params![
            session,
            from_us.unwrap_or(i64::MIN),
            to_us.unwrap_or(i64::MAX)
        ],
        |r| {
            let kind: String = r.get(2)?;
            Ok(Entry {
                at_us: r.get(0)?,
                master: r.get(1)?,
                // A kind this build does not know (a newer build's store) reads as a write:
                // the values stay visible.
                kind: Kind::from_name(&kind).unwrap_or(Kind::Write),
                parameter: r.get(3)?,
                element: r.get(4)?,
                old: r.get(5)?,
                new: r.get(6)?,
                accepted: r.get(7)?,
                reason: r.get(8)?,
                checksum: r.get(9)?,
            })
        },
    )?;
    rows.collect()
}

/// The calibration as a session's record knows it at its end: per parameter and element, the
/// last value found or accepted, and the page the CCM ran on ([`ECU_PAGE`]); refusals change
/// nothing, a save is not a value. Sorted by parameter, then element.
pub fn values_at_end(entries: &[Entry]) -> Vec<(String, Option<u32>, f64)> {
    let mut values: std::collections::BTreeMap<(String, Option<u32>), f64> = Default::default();
    for e in entries.iter().filter(|e| e.accepted) {
        if let (Kind::Found | Kind::Write | Kind::Revert | Kind::Page, Some(new)) = (e.kind, e.new)
        {
            values.insert((e.parameter.clone(), e.element), new);
        }
    }
    values
        .into_iter()
        .map(|((parameter, element), value)| (parameter, element, value))
        .collect()
}

/// The values session `from` ended with, as `Found` entries of session `to` at `at_us`: a
/// session started while the CCM runs (`session new`) begins with the calibration the one
/// before ended with, since the CCM's page does not change at a session's boundary. Returns
/// how many were carried over.
pub fn carry_over(db: &Connection, from: i64, to: i64, at_us: i64) -> rusqlite::Result<usize> {
    let before = list(db, Some(from), None, None)?;
    let checksum = before.iter().rev().find_map(|e| e.checksum);
    let carried: Vec<Entry> = values_at_end(&before)
        .into_iter()
        .map(|(parameter, element, value)| Entry {
            at_us,
            master: format!("carried over from session {from}"),
            kind: Kind::Found,
            parameter,
            element,
            old: Some(value),
            new: Some(value),
            accepted: true,
            reason: String::new(),
            checksum,
        })
        .collect();
    record(db, to, &carried)?;
    Ok(carried.len())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_next_session_begins_with_the_values_the_one_before_ended_with() {
        let db = Connection::open_in_memory().expect("memory");
        db.execute(CALIBRATION_TABLE, []).expect("table");
        let entries = [
            entry(Kind::Found, "traction_kp", 500.0, true),
            entry(Kind::Write, "traction_kp", 650.0, true),
            entry(Kind::Write, "launch_kp", 1e6, false),
        ];
        record(&db, 1, &entries).expect("record");
        assert_eq!(carry_over(&db, 1, 2, 2_000).expect("carry"), 1);
        let carried = list(&db, Some(2), None, None).expect("list");
        assert_eq!(values_at_end(&carried), values_at_end(&entries));
        assert!(
            carried
                .iter()
                .all(|e| e.kind == Kind::Found && e.at_us == 2_000)
        );
        assert_eq!(carry_over(&db, 3, 4, 3_000).expect("nothing"), 0);
    }

    fn entry(kind: Kind, parameter: &str, new: f64, accepted: bool) -> Entry {
        Entry {
            at_us: 1_000,
            master: "10.9.0.2:5000".into(),
            kind,
            parameter: parameter.into(),
            element: None,
            old: Some(0.1),
            new: Some(new),
            accepted,
            reason: if accepted {
                String::new()
            } else {
                "only at standstill".into()
            },
            checksum: Some(0xDEAD_BEEF),
        }
    }

    #[test]
    fn entries_round_trip_through_the_store_in_their_session_and_window() {
        let db = Connection::open_in_memory().expect("db");
        db.execute(super::super::session::SESSIONS_TABLE, [])
            .expect("sessions");
        db.execute(CALIBRATION_TABLE, []).expect("table");
        let mut written = vec![
            entry(Kind::Found, "tc_gain", 0.1, true),
            entry(Kind::Write, "tc_gain", 0.14, true),
            entry(Kind::Write, "launch_rpm", 0.3, false),
        ];
        written[2].at_us = 5_000;
        written[1].element = Some(3);
        record(&db, 7, &written).expect("recorded");
        record(&db, 8, &written[..1]).expect("another session");
        assert_eq!(list(&db, Some(7), None, None).expect("listed"), written);
        assert_eq!(
            list(&db, Some(7), None, Some(4_999)).expect("listed").len(),
            2
        );
        assert_eq!(list(&db, Some(8), Some(1_001), None).expect("listed"), []);
        assert_eq!(list(&db, None, None, None).expect("listed").len(), 4);
    }

    #[test]
    fn the_values_at_the_end_take_the_last_accepted_value_of_each_parameter() {
        let entries = [
            entry(Kind::Found, "tc_gain", 0.1, true),
            entry(Kind::Write, "tc_gain", 0.14, true),
            entry(Kind::Write, "tc_gain", 0.5, false),
            entry(Kind::Found, "launch_rpm", 3.0, true),
            entry(Kind::Save, "", 0.0, true),
            entry(Kind::Found, ECU_PAGE, 0.0, true),
            entry(Kind::Page, ECU_PAGE, 1.0, true),
        ];
        assert_eq!(
            values_at_end(&entries),
            [
                (ECU_PAGE.to_owned(), None, 1.0),
                ("launch_rpm".to_owned(), None, 3.0),
                ("tc_gain".to_owned(), None, 0.14)
            ]
        );
    }

    #[test]
    fn an_entry_reads_as_one_line() {
        let refused = entry(Kind::Write, "tc_gain", 0.5, false);
        assert_eq!(
            refused.to_string(),
            "write tc_gain 0.1 -> 0.5 refused: only at standstill (10.9.0.2:5000)"
        );
    }
}
