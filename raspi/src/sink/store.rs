//! The store as a sink: every record becomes a row for the store's writer ([`crate::store`]).

use super::Sink;
use crate::store::{RowSender, row};
use aer_host::decode::Record;
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
        // Never waits: a full queue drops the row and counts it.
        let _ = self.rows.send(row::row(record, &self.car_id, buses));
    }
}
