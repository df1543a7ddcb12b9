//! Disk space the store gives back: retention and compaction free pages inside the file, and
//! only an incremental vacuum returns them to the file system (the store is created with
//! `auto_vacuum = INCREMENTAL`).

use rusqlite::Connection;

/// Gives the store's free pages back to the file system. `PRAGMA incremental_vacuum` frees
/// one page per step of its statement: it must be stepped to the end, which
/// `execute_batch` does not do.
pub fn release_free_pages(db: &Connection) -> rusqlite::Result<()> {
    let mut statement = db.prepare("PRAGMA incremental_vacuum")?;
    let mut rows = statement.query([])?;
    while rows.next()?.is_some() {}
    Ok(())
}
