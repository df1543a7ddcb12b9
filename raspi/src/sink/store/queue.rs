//! The bounded queue between the pipeline and the store's writer thread.

use super::row::Row;
use std::sync::{Arc, Condvar, Mutex};
use std::time::Duration;

/// Rows per transaction at most, and the longest a row waits for its batch.
pub const BATCH_ROWS: usize = 2_000;
pub const BATCH_WAIT: Duration = Duration::from_millis(100);
/// Rows that may wait for the writer before producers block.
const QUEUE_ROWS: usize = 65_536;

/// Rows waiting for the writer. Producers wake the writer only when a batch is full, so a busy
/// pipeline costs one wake-up per batch, not one per row; otherwise the writer takes what is
/// there every [`BATCH_WAIT`].
pub struct Queue {
    state: Mutex<Pending>,
    /// Signals the writer: a full batch, or the last sender gone.
    filled: Condvar,
    /// Signals blocked producers: the writer took the queue.
    emptied: Condvar,
}

struct Pending {
    rows: Vec<Row>,
    senders: usize,
}

/// Sends rows to the writer; blocks while the queue is full, so nothing is dropped.
/// The writer stops once every sender is gone and the queue is written.
pub struct RowSender(Arc<Queue>);

impl RowSender {
    /// Queues `row`.
    pub fn send(&self, row: Row) {
        let Ok(mut pending) = self.0.state.lock() else {
            return;
        };
        while pending.rows.len() >= QUEUE_ROWS {
            match self.0.emptied.wait(pending) {
                Ok(guard) => pending = guard,
                Err(_) => return,
            }
        }
        pending.rows.push(row);
        if pending.rows.len() == BATCH_ROWS {
            self.0.filled.notify_one();
        }
    }
}

impl Clone for RowSender {
    fn clone(&self) -> Self {
        if let Ok(mut pending) = self.0.state.lock() {
            pending.senders += 1;
        }
        Self(self.0.clone())
    }
}

impl Drop for RowSender {
    fn drop(&mut self) {
        if let Ok(mut pending) = self.0.state.lock() {
            pending.senders -= 1;
            if pending.senders == 0 {
                self.0.filled.notify_one();
            }
        }
    }
}

impl Queue {
    /// An empty queue and its first sender.
    pub fn new() -> (Arc<Self>, RowSender) {
        let queue = Arc::new(Self {
            state: Mutex::new(Pending {
                rows: Vec::with_capacity(BATCH_ROWS),
                senders: 1,
            }),
            filled: Condvar::new(),
            emptied: Condvar::new(),
        });
        (queue.clone(), RowSender(queue))
    }

    /// Waits until a batch is full, every sender is gone, or [`BATCH_WAIT`] passed, then moves
    /// the waiting rows into `batch` (which must be empty). Returns whether any sender is
    /// left, or `None` if a producer panicked holding the lock.
    pub fn take(&self, batch: &mut Vec<Row>) -> Option<bool> {
        let mut pending = self.state.lock().ok()?;
        if pending.rows.len() < BATCH_ROWS && pending.senders > 0 {
            pending = self.filled.wait_timeout(pending, BATCH_WAIT).ok()?.0;
        }
        std::mem::swap(batch, &mut pending.rows);
        self.emptied.notify_all();
        Some(pending.senders > 0)
    }
}
