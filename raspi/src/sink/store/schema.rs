//! Opening the store: the generated tables, migrated to this schema, and the forwarder's
//! cursor table.

use aer::tables::{TABLES, Table};
use rusqlite::Connection;
use std::path::{Path, PathBuf};
use thiserror::Error;
use tracing::info;

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
}

/// The forwarder's persisted position per table.
pub const CURSOR_TABLE: &str = "CREATE TABLE IF NOT EXISTS \"forward_cursor\" (\"table_name\" TEXT PRIMARY KEY, \"last_id\" INTEGER NOT NULL)";

/// Opens (creating if needed) the store at `path` and brings its tables up to this schema:
/// missing tables are created, missing columns added. Fails at once if the path is not
/// writable, so a bad path is reported at start-up, not at the first packet.
pub fn open(path: &Path) -> Result<Connection, StoreError> {
    let open_error = |source| StoreError::Open {
        path: path.to_owned(),
        source,
    };
    let db = Connection::open(path).map_err(open_error)?;
    let schema_error = |source| StoreError::Schema {
        path: path.to_owned(),
        source,
    };
    // WAL: the forwarder reads while the writer appends; NORMAL sync is durable across
    // application crashes and loses at most the last transaction on power loss.
    db.pragma_update(None, "journal_mode", "WAL")
        .map_err(schema_error)?;
    db.pragma_update(None, "synchronous", "NORMAL")
        .map_err(schema_error)?;
    for table in TABLES {
        for statement in table.sqlite.create {
            db.execute(statement, []).map_err(schema_error)?;
        }
        migrate(&db, table).map_err(schema_error)?;
    }
    db.execute(CURSOR_TABLE, []).map_err(schema_error)?;
    Ok(db)
}

/// Adds the columns a store created by an older build lacks.
fn migrate(db: &Connection, table: &Table) -> rusqlite::Result<()> {
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
