//! The durable local store (SQLite, bundled): the generated tables, written in batches by one
//! thread, plus the forwarder's cursor and set-aside tables. Live telemetry never waits for
//! it: a store that is behind or failing drops rows (counted, reported) while the raw log
//! keeps their frames.
//!
//! [`lock`] keeps it to one service at a time, [`schema`] opens, checks and migrates the file, [`access`] opens it for the command line, [`row`] turns records into rows, [`queue`]
//! holds them for the [`writer`] thread, [`retention`] keeps the file within its budget,
//! [`session`] records who drove which run and which rows it made, [`clock`] how far its times
//! can be trusted, [`session_messages`] each
//! session's CAN messages (frames, rate, integrity and lateness counts), [`calibration`] each
//! session's calibration changes, [`events`] what happened during it (marks, problems, drops), [`compact`] packs closed
//! sessions into compressed blocks and reads them back, [`space`] gives freed pages back to the
//! file system. Ingest feeds it through
//! [`crate::sink::store::StoreSink`].

pub mod access;
pub mod calibration;
pub mod clock;
pub mod compact;
pub mod events;
pub mod lock;
pub mod queue;
pub mod retention;
pub mod row;
pub mod schema;
pub mod session;
pub mod session_messages;
pub mod space;
pub mod writer;

pub use compact::Compaction;
pub use queue::{RowSender, WhenFull};
pub use retention::{Budget, Retention};
pub use row::{Row, RowData};
pub use schema::{StoreError, open, open_or_recover};
pub use writer::{NoteSender, StoreWriter, WriterOptions};

/// A time as RFC 3339 in UTC with microseconds (`2026-11-26T10:00:00.000000Z`), as every
/// command prints one; the number itself when it is out of range.
pub fn utc(us: i64) -> String {
    chrono::DateTime::from_timestamp_micros(us).map_or_else(
        || us.to_string(),
        |t| t.format("%Y-%m-%dT%H:%M:%S%.6fZ").to_string(),
    )
}
