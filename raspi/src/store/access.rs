//! How the command line opens the store: a command never makes a new store by accident, a
//! reader needs no write permission anywhere (the pit user, with the service stopped or
//! running), and a store that is only unreadable is called unreadable, not damaged.
//!
//! SQLite reads a WAL-mode file through its `-shm` index, which it creates if missing; in a
//! folder the reader cannot write (the service's 0750 data folder, to group `aer`) that fails
//! once the service has stopped and removed the index. With no `-wal` file beside the store,
//! nothing is being written and nothing waits to be checkpointed, so the file alone is the
//! whole store: it is then read as immutable, which needs no index. A service that starts
//! during such a read makes a `-wal` file; [`ReadOnly::still_consistent`] tells the caller to
//! read again.

use super::StoreError;
use rusqlite::{Connection, ErrorCode, OpenFlags};
use std::path::{Path, PathBuf};

/// How a read-only store was opened.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReadMode {
    /// Through SQLite's WAL index, as any reader alongside the service.
    Shared,
    /// The file alone (no `-wal`: nothing is writing), without the index a read-only folder
    /// cannot hold.
    Immutable,
}

/// A store opened for reading.
pub struct ReadOnly {
    pub db: Connection,
    pub mode: ReadMode,
    path: PathBuf,
}

impl ReadOnly {
    /// False when a writer appeared while the store was read as immutable (the service
    /// started): what was read may mix old and new pages, so read again.
    pub fn still_consistent(&self) -> bool {
        self.mode == ReadMode::Shared || !companion(&self.path, "-wal").exists()
    }
}

/// `path` with `suffix` added to its file name (`-wal`, `-shm`).
fn companion(path: &Path, suffix: &str) -> PathBuf {
    let mut name = path.as_os_str().to_owned();
    name.push(suffix);
    PathBuf::from(name)
}

/// Opens the existing store at `path` for reading only.
pub fn open_read_only(path: &Path) -> Result<ReadOnly, StoreError> {
    exists(path)?;
    // Reading the file's first page answers whether this user may read it at all.
    if let Err(source) = std::fs::File::open(path).and_then(|mut file| {
        use std::io::Read;
        let mut first = [0u8; 16];
        file.read(&mut first).map(|_| ())
    }) {
        return Err(StoreError::Unreadable {
            path: path.to_owned(),
            source,
        });
    }
    let shared = Connection::open_with_flags(
        path,
        OpenFlags::SQLITE_OPEN_READ_ONLY | OpenFlags::SQLITE_OPEN_NO_MUTEX,
    )
    .and_then(|db| readable(&db).map(|()| db));
    match shared {
        Ok(db) => Ok(ReadOnly {
            db,
            mode: ReadMode::Shared,
            path: path.to_owned(),
        }),
        Err(error) if needs_index(&error) && !companion(path, "-wal").exists() => {
            let db = Connection::open_with_flags(
                immutable_uri(path),
                OpenFlags::SQLITE_OPEN_READ_ONLY
                    | OpenFlags::SQLITE_OPEN_URI
                    | OpenFlags::SQLITE_OPEN_NO_MUTEX,
            )
            .and_then(|db| readable(&db).map(|()| db))
            .map_err(|source| classify(path, source))?;
            Ok(ReadOnly {
                db,
                mode: ReadMode::Immutable,
                path: path.to_owned(),
            })
        }
        Err(error) => Err(classify(path, error)),
    }
}

/// Opens the existing store at `path` for a command that changes it (as the service's user);
/// a missing store is created only when `create` says so.
pub fn open_for_change(path: &Path, create: bool) -> Result<Connection, StoreError> {
    if !create {
        exists(path)?;
    }
    super::open(path)
}

fn exists(path: &Path) -> Result<(), StoreError> {
    match std::fs::metadata(path) {
        Ok(_) => Ok(()),
        Err(error) if error.kind() == std::io::ErrorKind::NotFound => Err(StoreError::Missing {
            path: path.to_owned(),
        }),
        Err(source) => Err(StoreError::Unreadable {
            path: path.to_owned(),
            source,
        }),
    }
}

/// One read of the schema: fails now, not in the middle of an export.
fn readable(db: &Connection) -> rusqlite::Result<()> {
    db.query_row("SELECT count(*) FROM sqlite_master", [], |_| Ok(()))
}

/// The failures of a read-only open that only the WAL index causes: it cannot be created in
/// this folder, or not opened for writing.
fn needs_index(error: &rusqlite::Error) -> bool {
    matches!(
        error.sqlite_error_code(),
        Some(ErrorCode::CannotOpen | ErrorCode::ReadOnly)
    )
}

/// Damaged only when SQLite says the file is not a sound database; anything else is a
/// failure to open (permissions, a lock, a missing folder).
pub(crate) fn classify(path: &Path, source: rusqlite::Error) -> StoreError {
    match source.sqlite_error_code() {
        Some(ErrorCode::DatabaseCorrupt | ErrorCode::NotADatabase) => StoreError::Damaged {
            path: path.to_owned(),
            why: source.to_string(),
        },
        _ => StoreError::Open {
            path: path.to_owned(),
            source,
        },
    }
}

/// An SQLite URI for `path` with `immutable=1` (the characters a URI gives meaning to,
/// escaped).
fn immutable_uri(path: &Path) -> String {
    let mut uri = String::from("file:");
    for byte in path.as_os_str().as_encoded_bytes() {
        match byte {
            b'%' | b'?' | b'#' => uri.push_str(&format!("%{byte:02X}")),
            _ => uri.push(char::from(*byte)),
        }
    }
    uri.push_str("?immutable=1");
    uri
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uris_escape_what_sqlite_reads_as_syntax() {
        assert_eq!(
            immutable_uri(Path::new("/var/lib/aer/store.sqlite")),
            "file:/var/lib/aer/store.sqlite?immutable=1"
        );
        assert_eq!(
            immutable_uri(Path::new("/tmp/a?b#c%d.sqlite")),
            "file:/tmp/a%3Fb%23c%25d.sqlite?immutable=1"
        );
    }

    #[test]
    fn a_missing_store_is_missing_and_never_created() {
        let dir = tempfile::tempdir().expect("dir");
        let path = dir.path().join("none.sqlite");
        assert!(matches!(
            open_read_only(&path),
            Err(StoreError::Missing { .. })
        ));
        assert!(matches!(
            open_for_change(&path, false),
            Err(StoreError::Missing { .. })
        ));
        assert!(!path.exists());
        assert!(open_for_change(&path, true).is_ok());
        assert!(path.exists());
    }

    #[test]
    fn a_file_that_is_not_a_database_is_damaged_but_a_locked_one_is_not() {
        let dir = tempfile::tempdir().expect("dir");
        let path = dir.path().join("junk.sqlite");
        std::fs::write(&path, vec![0x55u8; 8192]).expect("write");
        assert!(matches!(
            open_read_only(&path),
            Err(StoreError::Damaged { .. })
        ));
        let busy = rusqlite::Error::SqliteFailure(
            rusqlite::ffi::Error::new(rusqlite::ffi::SQLITE_BUSY),
            None,
        );
        assert!(matches!(classify(&path, busy), StoreError::Open { .. }));
    }
}
