//! The durable local store (SQLite, bundled): the generated tables, written in batches by one
//! thread, plus the forwarder's cursor table. Nothing is dropped on the way in: a full queue
//! slows the producer down instead.
//!
//! [`schema`] opens and migrates the file, [`row`] turns records into rows, [`queue`] holds
//! them for the [`writer`] thread; [`StoreSink`] is what ingest hands records to.

pub mod queue;
pub mod row;
pub mod schema;
pub mod writer;

pub use queue::RowSender;
pub use row::{Row, RowData};
pub use schema::{CURSOR_TABLE, StoreError, open};
pub use writer::StoreWriter;

use super::Sink;
use aer_host::ingest::Record;
use std::sync::Arc;

/// The store as a sink: every record becomes a row for the writer.
pub struct StoreSink {
    rows: RowSender,
    car_id: Arc<str>,
}

impl StoreSink {
    /// Rows for car `car_id`, sent to `rows`.
    pub fn new(rows: RowSender, car_id: &str) -> Self {
        Self {
            rows,
            car_id: car_id.into(),
        }
    }
}

impl Sink for StoreSink {
    fn accept(&mut self, record: &Record, buses: &[Arc<str>]) {
        // Blocks while the writer is behind: the store never drops.
        self.rows.send(row::row(record, &self.car_id, buses));
    }
}
