//! The writer thread: takes the queue's rows in batches and commits each batch in one
//! transaction.

use super::queue::{BATCH_ROWS, Queue, RowSender};
use super::row::Row;
use aer::tables::TABLES;
use aer_host::counters::Counters;
use rusqlite::Connection;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::thread::JoinHandle;
use std::time::Duration;
use tracing::error;

/// The writer thread and its queue.
pub struct StoreWriter {
    sender: Option<RowSender>,
    thread: Option<JoinHandle<()>>,
}

impl StoreWriter {
    /// Starts the writer on `db`.
    pub fn start(db: Connection, counters: Arc<Counters>) -> Self {
        let (queue, sender) = Queue::new();
        let thread = std::thread::Builder::new()
            .name("store-writer".into())
            .spawn(move || write_loop(db, &queue, &counters))
            .ok();
        Self {
            sender: Some(sender),
            thread,
        }
    }

    /// A handle producers send rows with.
    pub fn sender(&self) -> Option<RowSender> {
        self.sender.clone()
    }

    /// Writes every queued row and stops the writer, once every other sender is dropped.
    pub fn finish(mut self) {
        self.sender.take();
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

fn write_loop(mut db: Connection, queue: &Queue, counters: &Counters) {
    let mut batch: Vec<Row> = Vec::with_capacity(BATCH_ROWS);
    loop {
        let Some(open) = queue.take(&mut batch) else {
            return;
        };
        while !batch.is_empty() {
            match commit(&mut db, &batch) {
                Ok(()) => {
                    counters
                        .stored
                        .fetch_add(batch.len() as u64, Ordering::Relaxed);
                    batch.clear();
                }
                Err(error) => {
                    // Disk full or I/O error: keep the batch and retry, so nothing is lost
                    // while the cause is fixed; producers block once the queue fills.
                    error!(%error, rows = batch.len(), "local store write failed; retrying in 1 s");
                    std::thread::sleep(Duration::from_secs(1));
                }
            }
        }
        if !open {
            return;
        }
    }
}

fn commit(db: &mut Connection, batch: &[Row]) -> rusqlite::Result<()> {
    let transaction = db.transaction()?;
    {
        // Each table's statement is prepared once per batch, not looked up per row.
        let mut statements: Vec<Option<rusqlite::CachedStatement<'_>>> =
            TABLES.iter().map(|_| None).collect();
        for row in batch {
            let table = row.table();
            let Some(slot) = statements.get_mut(table.index) else {
                continue;
            };
            let statement = match slot {
                Some(statement) => statement,
                None => slot.insert(transaction.prepare_cached(table.sqlite.insert)?),
            };
            row.bind(statement)?;
            statement.raw_execute()?;
        }
    }
    transaction.commit()
}
