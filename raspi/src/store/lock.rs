//! One writer per store: the service holds an exclusive lock on `<store>.lock` (and on its raw
//! log folder's `.lock`) from before it opens a session until it stops, so a second `run`,
//! `demo` or `replay` on the same store refuses before touching anything instead of closing
//! the running session and splitting the run in two. The lock is the kernel's (`flock`): it
//! goes with the process, so a crash or `kill -9` never leaves a stale one behind. The file
//! says who holds it, for the refusal's message.

use std::fs::{File, OpenOptions, TryLockError};
use std::io::{Read, Seek, Write};
use std::path::{Path, PathBuf};

/// Why the store could not be taken.
#[derive(Debug, thiserror::Error)]
pub enum LockError {
    /// Another process holds it.
    #[error(
        "{what} is in use by another aer-raspi ({holder}): one service records into a store at a time. \
Stop that one first (Ctrl-C, or `sudo systemctl stop aer-raspi` for the installed service), \
or give this one its own store (AER_STORE_PATH=... AER_RAW_LOG_DIR=...); to change the running \
session use `aer-raspi session new` or `session set`"
    )]
    Held { what: String, holder: String },
    /// The lock file cannot be created or locked (missing folder, no permission).
    #[error("cannot lock {path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

/// An exclusive hold on a store or raw log folder, released when dropped (or when the process
/// ends, however it ends).
#[derive(Debug)]
pub struct Held {
    _file: File,
    path: PathBuf,
}

impl Held {
    /// The lock file.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

/// The lock file of the store at `store`: `<store>.lock` beside it.
pub fn store_lock_path(store: &Path) -> PathBuf {
    let mut name = store.as_os_str().to_owned();
    name.push(".lock");
    PathBuf::from(name)
}

/// The lock file of a raw log folder.
pub fn raw_log_lock_path(dir: &Path) -> PathBuf {
    dir.join(".lock")
}

/// Takes `lock_path` exclusively for `what` (as the refusal names it), recording `holder`
/// (this process: its id and job) in it; refuses at once if another process holds it.
pub fn take(lock_path: &Path, what: &str, holder: &str) -> Result<Held, LockError> {
    let io = |source| LockError::Io {
        path: lock_path.to_owned(),
        source,
    };
    let mut file = OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .open(lock_path)
        .map_err(io)?;
    match file.try_lock() {
        Ok(()) => {}
        Err(TryLockError::WouldBlock) => {
            let mut text = String::new();
            // Who holds it is a courtesy: an unreadable note still refuses.
            let _ = file.read_to_string(&mut text);
            let holder = text.trim();
            return Err(LockError::Held {
                what: what.to_owned(),
                holder: if holder.is_empty() {
                    "a process that did not say which".to_owned()
                } else {
                    holder.to_owned()
                },
            });
        }
        Err(TryLockError::Error(source)) => return Err(io(source)),
    }
    // Who holds it is a courtesy too: on a full disk the lock holds without its note, and the
    // service runs (its drops counted) rather than refusing to start.
    let noted = file
        .set_len(0)
        .and_then(|()| file.rewind())
        .and_then(|()| writeln!(file, "{holder}"))
        .and_then(|()| file.flush());
    if let Err(error) = noted {
        tracing::warn!(%error, path = %lock_path.display(), "the lock holds, but its note of who holds it could not be written");
    }
    Ok(Held {
        _file: file,
        path: lock_path.to_owned(),
    })
}

/// Who holds `lock_path` now, as its note says, if that process still runs (Linux: its
/// `/proc` entry). Looks without locking, so a service starting this instant is never refused
/// for it.
pub fn holder(lock_path: &Path) -> Option<String> {
    let note = std::fs::read_to_string(lock_path).ok()?;
    let pid: u32 = note
        .strip_prefix("pid ")?
        .split(|c: char| !c.is_ascii_digit())
        .next()?
        .parse()
        .ok()?;
    Path::new(&format!("/proc/{pid}"))
        .exists()
        .then(|| note.trim().to_owned())
}

/// This process as a lock's note names it: `pid 1234, aer-raspi demo, since 2026-11-28T10:00:00Z`.
pub fn this_process(job: &str, now_us: i64) -> String {
    let since = super::utc(now_us);
    let since = since
        .split_once('.')
        .map_or(since.clone(), |(s, _)| format!("{s}Z"));
    format!("pid {}, aer-raspi {job}, since {since}", std::process::id())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_second_take_is_refused_naming_the_holder_and_free_once_released() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = store_lock_path(&dir.path().join("store.sqlite"));
        let first = take(&path, "the store", "pid 999999999, aer-raspi demo").expect("first");
        match take(&path, "the store", "pid 2, aer-raspi run") {
            Err(LockError::Held { holder, what }) => {
                assert_eq!(holder, "pid 999999999, aer-raspi demo");
                assert_eq!(what, "the store");
            }
            other => panic!("a second writer was not refused: {other:?}"),
        }
        assert_eq!(holder(&path), None, "no process 999999999: not held");
        drop(first);
        let mine = take(&path, "the store", &this_process("run", 0)).expect("free");
        assert!(holder(&path).is_some_and(|h| h.contains(&std::process::id().to_string())));
        drop(mine);
        let again = take(&path, "the store", "pid 3, aer-raspi run").expect("released");
        assert_eq!(
            std::fs::read_to_string(again.path()).expect("note"),
            "pid 3, aer-raspi run\n"
        );
    }

    #[test]
    fn a_lock_in_a_missing_folder_is_an_error_naming_the_file() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("missing").join("store.sqlite.lock");
        let error = take(&path, "the store", "me").expect_err("no folder");
        assert!(error.to_string().contains("missing"), "{error}");
    }
}
