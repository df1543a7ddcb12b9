//! The bounded queue between ingest and the store's writer thread. Live, sending never waits:
//! telemetry must not stall because the disk is slow, full or failing, so a row the queue has
//! no room for is dropped and counted (the raw log still holds its frame). Replaying a log,
//! nothing is live: sending waits for room while the store works.

use super::row::Row;
use aer_host::reports::counters::{Counters, worth_logging};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::Duration;
use tracing::warn;

/// Rows per transaction at most, and the longest a row waits for its transaction: one commit
/// a second writes each table's last page once a second instead of ten times (the main
/// cause of the store's write amplification).
pub(crate) const BATCH_ROWS: usize = 20_000;
pub(crate) const BATCH_WAIT: Duration = Duration::from_secs(1);
/// Rows that may wait for the writer (two minutes of the car's traffic) before new ones are
/// dropped.
pub(crate) const QUEUE_ROWS: usize = 65_536;

/// What a sender does when the queue is full.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum WhenFull {
    /// Drop the row and count it (live sources).
    #[default]
    Drop,
    /// Wait for room while the store works; drop once it fails (replays).
    Wait,
}

/// Rows waiting for the writer. Producers wake the writer only when a batch is full, so a busy
/// pipeline costs one wake-up per batch, not one per row; otherwise the writer takes what is
/// there every `BATCH_WAIT`.
pub struct Queue {
    state: Mutex<Pending>,
    /// Signals the writer: a full batch, or the last sender gone.
    filled: Condvar,
    /// Signals waiting senders: the writer took rows.
    emptied: Condvar,
    capacity: usize,
    when_full: WhenFull,
    /// The writer's last commit failed.
    failing: AtomicBool,
}

struct Pending {
    rows: Vec<Row>,
    senders: usize,
}

/// Sends rows to the writer without waiting; the writer stops once every sender is gone and
/// the queue is written.
pub struct RowSender {
    queue: Arc<Queue>,
    counters: Arc<Counters>,
}

impl RowSender {
    /// Queues `row`, or drops and counts it when the queue is full. Returns whether it was
    /// queued.
    pub fn send(&self, row: Row) -> bool {
        let Ok(mut pending) = self.queue.state.lock() else {
            return false;
        };
        while self.queue.when_full == WhenFull::Wait
            && pending.rows.len() >= self.queue.capacity
            && !self.queue.failing.load(Ordering::Relaxed)
        {
            // Woken when the writer takes rows; the timeout re-checks whether it failed.
            match self
                .queue
                .emptied
                .wait_timeout(pending, Duration::from_millis(100))
            {
                Ok((guard, _)) => pending = guard,
                Err(_) => return false,
            }
        }
        if pending.rows.len() >= self.queue.capacity {
            drop(pending);
            let count = Counters::bump(&self.counters.store_dropped);
            if worth_logging(count) {
                warn!(
                    count,
                    "local store behind or failing: row dropped (its frames stay in the raw log)"
                );
            }
            return false;
        }
        pending.rows.push(row);
        if pending.rows.len() == BATCH_ROWS {
            self.queue.filled.notify_one();
        }
        true
    }
}

impl Clone for RowSender {
    fn clone(&self) -> Self {
        if let Ok(mut pending) = self.queue.state.lock() {
            pending.senders += 1;
        }
        Self {
            queue: self.queue.clone(),
            counters: self.counters.clone(),
        }
    }
}

impl Drop for RowSender {
    fn drop(&mut self) {
        if let Ok(mut pending) = self.queue.state.lock() {
            pending.senders -= 1;
            if pending.senders == 0 {
                self.queue.filled.notify_one();
            }
        }
    }
}

impl Queue {
    /// An empty queue holding at most `capacity` rows, and its first sender.
    pub fn new(
        capacity: usize,
        when_full: WhenFull,
        counters: Arc<Counters>,
    ) -> (Arc<Self>, RowSender) {
        let queue = Arc::new(Self {
            state: Mutex::new(Pending {
                rows: Vec::with_capacity(BATCH_ROWS),
                senders: 1,
            }),
            filled: Condvar::new(),
            emptied: Condvar::new(),
            capacity,
            when_full,
            failing: AtomicBool::new(false),
        });
        (queue.clone(), RowSender { queue, counters })
    }

    /// Waits until a batch is full, every sender is gone, or `wait` passed, then moves up to
    /// `BATCH_ROWS` waiting rows into `batch` (which must be empty). Returns whether any
    /// sender is left, or `None` if a producer panicked holding the lock.
    pub fn take(&self, batch: &mut Vec<Row>, wait: Duration) -> Option<bool> {
        let mut pending = self.state.lock().ok()?;
        if pending.rows.len() < BATCH_ROWS && pending.senders > 0 {
            pending = self.filled.wait_timeout(pending, wait).ok()?.0;
        }
        let take = pending.rows.len().min(BATCH_ROWS);
        batch.extend(pending.rows.drain(..take));
        self.emptied.notify_all();
        Some(pending.senders > 0 || !pending.rows.is_empty())
    }

    /// The writer's commits fail (`true`) or work again: waiting senders stop waiting.
    pub(crate) fn set_failing(&self, failing: bool) {
        self.failing.store(failing, Ordering::Relaxed);
        if failing {
            self.emptied.notify_all();
        }
    }

    /// True once every sender is gone (the service is stopping).
    pub(crate) fn is_closed(&self) -> bool {
        self.state
            .lock()
            .map_or(true, |pending| pending.senders == 0)
    }

    /// Waits up to `timeout`, returning early once every sender is gone.
    pub(crate) fn wait_closed(&self, timeout: Duration) {
        let Ok(pending) = self.state.lock() else {
            return;
        };
        let _ = self
            .filled
            .wait_timeout_while(pending, timeout, |pending| pending.senders > 0);
    }

    /// Rows waiting.
    pub fn len(&self) -> usize {
        self.state.lock().map_or(0, |pending| pending.rows.len())
    }

    /// True when no row waits.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}
