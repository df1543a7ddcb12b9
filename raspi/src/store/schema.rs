//! Opening the store: the generated tables, migrated to this schema, and the forwarder's
//! cursor and set-aside tables; a damaged file is moved aside so the service can start.
//!
//! Durability: WAL with `synchronous = FULL`, so a committed transaction survives a power cut
//! (the writer commits once a second). What a power cut loses is what had not been committed:
//! at most the last second's rows plus whatever waited in the writer's queue; a kill of the
//! process loses the same, and nothing already committed.

use super::{calibration, clock, compact, events, session, session_messages};
use aer::tables::{TABLES, Table};
use rusqlite::{Connection, OpenFlags};
use std::path::{Path, PathBuf};
use thiserror::Error;
use tracing::{error, info};

/// Why the store cannot be used.
#[derive(Debug, Error)]
pub enum StoreError {
    /// The file cannot be created or opened (missing folder, no permission, read-only disk).
    #[error("cannot open the local store at {path}: {source}")]
    Open {
        path: PathBuf,
        #[source]
        source: rusqlite::Error,
    },
    /// Creating or migrating the tables failed.
    #[error("cannot prepare the local store's tables at {path}: {source}")]
    Schema {
        path: PathBuf,
        #[source]
        source: rusqlite::Error,
    },
    /// The file is not a database, or fails SQLite's integrity check.
    #[error("the local store at {path} is damaged: {why}")]
    Damaged { path: PathBuf, why: String },
    /// There is no store at the path (a command that reads one never creates it).
    #[error("no store at {path}")]
    Missing { path: PathBuf },
    /// The file exists but this user may not read it.
    #[error(
        "cannot read the store at {path}: {source} (its group, aer, may read it: `sudo adduser $USER aer`, then log in again)"
    )]
    Unreadable {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A damaged file could not be moved aside.
    #[error("cannot move the damaged local store {path} aside: {source}")]
    MoveAside {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

/// The forwarder's persisted position per table.
pub(crate) const CURSOR_TABLE: &str = "CREATE TABLE IF NOT EXISTS \"forward_cursor\" (\"table_name\" TEXT PRIMARY KEY, \"last_id\" INTEGER NOT NULL)";

/// Rows TDengine refused, kept here (not forwarded again) with TDengine's reason.
pub(crate) const SET_ASIDE_TABLE: &str = "CREATE TABLE IF NOT EXISTS \"forward_set_aside\" (\"table_name\" TEXT NOT NULL, \"row_id\" INTEGER NOT NULL, \"error\" TEXT NOT NULL, \"at_us\" INTEGER NOT NULL, PRIMARY KEY (\"table_name\", \"row_id\"))";

/// Opens (creating if needed) the store at `path` and brings its tables up to this schema:
/// missing tables are created, missing columns added. Fails at once if the path is not
/// writable, so a bad path is reported at start-up, not at the first packet; fails with
/// [`StoreError::Damaged`] if the file is not a sound database.
pub fn open(path: &Path) -> Result<Connection, StoreError> {
    let open_error = |source| StoreError::Open {
        path: path.to_owned(),
        source,
    };
    let fresh = !path.exists();
    let db = Connection::open_with_flags(
        path,
        OpenFlags::SQLITE_OPEN_READ_WRITE
            | OpenFlags::SQLITE_OPEN_CREATE
            | OpenFlags::SQLITE_OPEN_NO_MUTEX,
    )
    .map_err(open_error)?;
    check(&db).map_err(|failure| match failure {
        Check::Problem(why) => StoreError::Damaged {
            path: path.to_owned(),
            why,
        },
        Check::Failed(source) => super::access::classify(path, source),
    })?;
    let schema_error = |source| StoreError::Schema {
        path: path.to_owned(),
        source,
    };
    if fresh {
        // Pages freed by retention go back to the file system (set before any table).
        db.pragma_update(None, "auto_vacuum", "INCREMENTAL")
            .map_err(schema_error)?;
    }
    db.pragma_update(None, "journal_mode", "WAL")
        .map_err(schema_error)?;
    db.pragma_update(None, "synchronous", "FULL")
        .map_err(schema_error)?;
    create_tables(&db).map_err(schema_error)?;
    Ok(db)
}

/// Creates the generated tables (adding columns an older store lacks), the forwarder's and
/// the sessions' tables.
pub(crate) fn create_tables(db: &Connection) -> rusqlite::Result<()> {
    for table in TABLES {
        db.execute(table.sqlite.create, [])?;
        add_missing_columns(db, table)?;
    }
    db.execute(CURSOR_TABLE, [])?;
    db.execute(SET_ASIDE_TABLE, [])?;
    db.execute(session::SESSIONS_TABLE, [])?;
    db.execute(clock::SESSION_CLOCK_TABLE, [])?;
    db.execute(session::SESSION_ROWS_TABLE, [])?;
    db.execute(session_messages::SESSION_MESSAGES_TABLE, [])?;
    db.execute(calibration::CALIBRATION_TABLE, [])?;
    db.execute(events::EVENTS_TABLE, [])?;
    db.execute(compact::BLOCKS_TABLE, [])?;
    for table in TABLES {
        ids_after_everything_seen(db, table)?;
    }
    Ok(())
}

/// New rows of `table` get ids after every id it ever had: its rows, its compacted blocks and
/// the forwarder's cursor (a table emptied before its ids were made never to repeat). Writes
/// only when that is not already so, so opening a store someone is writing to stays read-only.
fn ids_after_everything_seen(db: &Connection, table: &Table) -> rusqlite::Result<()> {
    let (seq, seen): (Option<i64>, i64) = db.query_row(
        "SELECT (SELECT seq FROM sqlite_sequence WHERE name = ?1), max( \
           coalesce((SELECT max(last_id) FROM compacted WHERE table_name = ?1), 0), \
           coalesce((SELECT last_id FROM forward_cursor WHERE table_name = ?1), 0))",
        [table.name],
        |row| Ok((row.get(0)?, row.get(1)?)),
    )?;
    match seq {
        Some(seq) if seq >= seen => {}
        Some(_) => {
            db.execute(
                "UPDATE sqlite_sequence SET seq = ?2 WHERE name = ?1",
                rusqlite::params![table.name, seen],
            )?;
        }
        None if seen > 0 => {
            db.execute(
                "INSERT INTO sqlite_sequence (name, seq) VALUES (?1, ?2)",
                rusqlite::params![table.name, seen],
            )?;
        }
        None => {}
    }
    Ok(())
}

/// Opens the store; a damaged one is moved aside (`<file>.damaged-<unix seconds>`, with its
/// WAL) and a fresh store started, so a bad file never keeps the service from running.
/// Returns the connection and, after a recovery, what happened.
pub fn open_or_recover(path: &Path) -> Result<(Connection, Option<String>), StoreError> {
    match open(path) {
        Err(StoreError::Damaged { why, .. }) => {
            let aside = move_aside(path)?;
            let report = format!(
                "the store was damaged ({why}); moved to {} and started afresh",
                aside.display()
            );
            error!("{report}");
            let db = open(path)?;
            info!(path = %path.display(), "fresh local store open");
            Ok((db, Some(report)))
        }
        other => other.map(|db| (db, None)),
    }
}

/// Why the integrity check did not pass.
enum Check {
    /// It ran and found a problem.
    Problem(String),
    /// It could not run: the file is not a database, or is locked or unreadable
    /// ([`super::access::classify`] tells which is damage).
    Failed(rusqlite::Error),
}

/// SQLite's quick integrity check (every page read once; catches torn and garbled files).
fn check(db: &Connection) -> Result<(), Check> {
    let result: Result<String, _> = db.query_row("PRAGMA quick_check", [], |row| row.get(0));
    match result {
        Ok(ok) if ok == "ok" => Ok(()),
        Ok(problem) => Err(Check::Problem(problem)),
        Err(error) => Err(Check::Failed(error)),
    }
}

fn move_aside(path: &Path) -> Result<PathBuf, StoreError> {
    let stamp = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let with_suffix = |suffix: &str| {
        let mut name = path.as_os_str().to_owned();
        name.push(suffix);
        PathBuf::from(name)
    };
    let aside = with_suffix(&format!(".damaged-{stamp}"));
    std::fs::rename(path, &aside).map_err(|source| StoreError::MoveAside {
        path: path.to_owned(),
        source,
    })?;
    for companion in ["-wal", "-shm"] {
        let from = with_suffix(companion);
        if from.exists() {
            let mut to = aside.as_os_str().to_owned();
            to.push(companion);
            let _ = std::fs::rename(&from, PathBuf::from(to));
        }
    }
    Ok(aside)
}

/// Adds the columns a schema change added since the store was created (a new signal in the
/// DBC or the telemetry packet): the rows before it read NULL there.
fn add_missing_columns(db: &Connection, table: &Table) -> rusqlite::Result<()> {
    let mut statement = db.prepare("SELECT name FROM pragma_table_info(?1)")?;
    let existing: Vec<String> = statement
        .query_map([table.name], |row| row.get(0))?
        .collect::<rusqlite::Result<_>>()?;
    let existing: Vec<&str> = existing.iter().map(String::as_str).collect();
    for column in table.missing_columns(&existing) {
        info!(
            table = table.name,
            column = column.name,
            "adding a column the store lacks"
        );
        db.execute(&table.sqlite_add_column(column), [])?;
    }
    Ok(())
}
