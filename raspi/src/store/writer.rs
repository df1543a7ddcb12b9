//! The writer thread: takes the queue's rows in batches and commits each batch in one
//! transaction. A failing store (disk full, read-only, I/O error) is retried with backoff and
//! reported; while it fails the queue fills and new rows are dropped and counted, but nothing
//! upstream waits. Between batches it applies the retention budget.

use super::calibration::{self, Entry};
use super::clock::{StepWatch, describe_step};
use super::compact::Compaction;
use super::queue::{BATCH_ROWS, BATCH_WAIT, QUEUE_ROWS, Queue, RowSender, WhenFull};
use super::retention::Retention;
use super::row::Row;
use super::session;
use super::session::record_clock_step;
use super::session_messages::Tally;
use crate::health::Health;
use aer::tables::TABLES;
use aer_host::reports::counters::{Counters, worth_logging};
use rusqlite::Connection;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};
use tracing::{error, info, warn};

/// Backoff after a failed commit: 1 s doubling to 30 s.
const RETRY_START: Duration = Duration::from_secs(1);
const RETRY_MAX: Duration = Duration::from_secs(30);
/// How long a stopping writer keeps retrying a failing store before it gives up on the rows
/// it holds (counted as dropped; the raw log has their frames).
const STOP_GRACE: Duration = Duration::from_secs(3);

/// Calibration entries that may wait for the writer (a tuner makes a few a minute).
const CALIBRATION_ENTRIES: usize = 1024;

/// The writer thread, and the sender it keeps until it finishes.
pub struct StoreWriter {
    sender: Option<RowSender>,
    calibration: CalibrationSender,
    thread: Option<JoinHandle<()>>,
}

/// Hands calibration entries to the writer, which records them in the open session. Never
/// waits: an entry the writer cannot take is counted (`calibration_unrecorded`).
#[derive(Clone)]
pub struct CalibrationSender {
    entries: std::sync::mpsc::SyncSender<Entry>,
    counters: Arc<Counters>,
}

impl CalibrationSender {
    /// A sender to `entries`, which counts in `counters` what it could not hand over.
    pub fn new(entries: std::sync::mpsc::SyncSender<Entry>, counters: Arc<Counters>) -> Self {
        Self { entries, counters }
    }

    /// Hands `entry` over; false (and counted) if the writer is behind or gone.
    pub fn send(&self, entry: Entry) -> bool {
        let sent = self.entries.try_send(entry).is_ok();
        if !sent {
            let count = Counters::bump(&self.counters.calibration_unrecorded);
            if worth_logging(count) {
                warn!(
                    count,
                    "a calibration entry could not be recorded (the store is behind or stopped)"
                );
            }
        }
        sent
    }
}

/// What the writer does besides writing.
#[derive(Default)]
pub struct WriterOptions {
    /// Keeps the store within its budget.
    pub retention: Option<Retention>,
    /// Compacts closed sessions into compressed blocks.
    pub compaction: Option<Compaction>,
    /// Where the writer reports failures.
    pub health: Arc<Health>,
    /// Rows that may wait (default `QUEUE_ROWS`).
    pub queue_rows: Option<usize>,
    /// What senders do when that many wait.
    pub when_full: WhenFull,
}

impl StoreWriter {
    /// Starts the writer on `db`.
    pub fn start(db: Connection, counters: Arc<Counters>) -> Self {
        Self::with_options(db, counters, WriterOptions::default())
    }

    /// Starts the writer on `db` with retention and health reporting.
    pub fn with_options(db: Connection, counters: Arc<Counters>, options: WriterOptions) -> Self {
        let (queue, sender) = Queue::new(
            options.queue_rows.unwrap_or(QUEUE_ROWS),
            options.when_full,
            counters.clone(),
        );
        let (calibration, calibration_entries) = std::sync::mpsc::sync_channel(CALIBRATION_ENTRIES);
        let calibration = CalibrationSender::new(calibration, counters.clone());
        let writer = Writer {
            db,
            queue,
            calibration: calibration_entries,
            calibration_pending: Vec::new(),
            counters,
            health: options.health,
            retention: options.retention,
            compaction: options.compaction,
            stop_by: None,
            clock: StepWatch::new(),
        };
        let thread = std::thread::Builder::new()
            .name("store-writer".into())
            .spawn(move || writer.run())
            .ok();
        Self {
            sender: Some(sender),
            calibration,
            thread,
        }
    }

    /// A handle producers send rows with.
    pub fn sender(&self) -> Option<RowSender> {
        self.sender.clone()
    }

    /// A handle the XCP gateway hands its calibration entries to.
    pub fn calibration_sender(&self) -> CalibrationSender {
        self.calibration.clone()
    }

    /// Writes every queued row and stops the writer, once every other sender is dropped. A
    /// store that keeps failing is given a few seconds (`STOP_GRACE`), then its rows are
    /// counted as dropped.
    pub fn finish(mut self) {
        self.sender.take();
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

struct Writer {
    db: Connection,
    queue: Arc<Queue>,
    /// Calibration entries from the XCP gateway, and those a failing store still owes.
    calibration: std::sync::mpsc::Receiver<Entry>,
    calibration_pending: Vec<Entry>,
    counters: Arc<Counters>,
    health: Arc<Health>,
    retention: Option<Retention>,
    compaction: Option<Compaction>,
    /// When the service stops, the time by which a failing store's rows are given up.
    stop_by: Option<Instant>,
    /// Steps of the wall clock, recorded in the open session.
    clock: StepWatch,
}

impl Writer {
    /// Starts the stop grace period, once.
    fn stopping(&mut self) {
        self.stop_by
            .get_or_insert_with(|| Instant::now() + STOP_GRACE);
    }

    fn run(mut self) {
        let mut batch: Vec<Row> = Vec::with_capacity(BATCH_ROWS);
        loop {
            let Some(open) = self.queue.take(&mut batch, BATCH_WAIT) else {
                self.record_calibration();
                return;
            };
            if !batch.is_empty() {
                self.write(&mut batch, open);
            }
            self.record_calibration();
            if let Some((at_us, step_us)) = self.clock.check() {
                warn!(step = %describe_step(at_us, step_us), "the wall clock stepped; the open session records it");
                if let Err(error) = record_clock_step(&self.db, at_us, step_us) {
                    warn!(%error, "recording the clock step failed");
                }
            }
            if let Some(retention) = &mut self.retention {
                retention.maybe_prune(&self.db, &self.counters, &self.health);
            }
            if open {
                self.compact();
            } else {
                self.record_calibration();
                return;
            }
        }
    }

    /// Records the calibration entries that came in, in the open session. A failing store
    /// keeps them for the next try (up to the channel's bound; beyond it the oldest are
    /// counted as unrecorded); with no session open they are counted too.
    fn record_calibration(&mut self) {
        self.calibration_pending.extend(self.calibration.try_iter());
        if self.calibration_pending.is_empty() {
            return;
        }
        let recorded = session::current(&self.db).and_then(|session| match session {
            Some(session) => {
                calibration::record(&self.db, session, &self.calibration_pending).map(|()| true)
            }
            None => Ok(false),
        });
        match recorded {
            Ok(true) => self.calibration_pending.clear(),
            Ok(false) => {
                warn!(
                    entries = self.calibration_pending.len(),
                    "calibration entries with no session open: not recorded"
                );
                self.unrecorded(self.calibration_pending.len());
                self.calibration_pending.clear();
            }
            Err(error) => {
                warn!(%error, "recording calibration entries failed; retrying");
                let over = self
                    .calibration_pending
                    .len()
                    .saturating_sub(CALIBRATION_ENTRIES);
                self.calibration_pending.drain(..over);
                self.unrecorded(over);
            }
        }
    }

    fn unrecorded(&self, entries: usize) {
        self.counters
            .calibration_unrecorded
            .fetch_add(entries as u64, Ordering::Relaxed);
    }

    /// Compacts closed sessions' rows, if due (never while stopping: a stop stays quick, and
    /// the next start goes on).
    fn compact(&mut self) {
        let Some(compaction) = &mut self.compaction else {
            return;
        };
        match compaction.maybe_step(&mut self.db) {
            Ok(rows) => {
                self.counters
                    .compacted_rows
                    .fetch_add(rows, Ordering::Relaxed);
            }
            Err(error) => warn!(%error, "compacting a closed session failed; retrying"),
        }
    }

    /// Commits `batch`, retrying with backoff while the store fails; once the service is
    /// stopping (`open` false) every remaining batch shares one [`STOP_GRACE`], so a full
    /// queue cannot multiply it.
    fn write(&mut self, batch: &mut Vec<Row>, open: bool) {
        let mut backoff = RETRY_START;
        if !open {
            self.stopping();
        }
        loop {
            match commit(&mut self.db, batch) {
                Ok(()) => {
                    self.counters
                        .stored
                        .fetch_add(batch.len() as u64, Ordering::Relaxed);
                    batch.clear();
                    self.queue.set_failing(false);
                    if self.health.store.recovered() {
                        info!("local store writes again");
                    }
                    return;
                }
                Err(error) => {
                    let count = Counters::bump(&self.counters.store_errors);
                    self.health.store.failed(&error.to_string());
                    self.queue.set_failing(true);
                    if worth_logging(count) {
                        error!(%error, rows = batch.len(), retry_s = backoff.as_secs(), count,
                            "local store write failed; new rows are dropped (and counted) while it fails");
                    }
                }
            }
            if self.queue.is_closed() {
                self.stopping();
            }
            let stop_by = self.stop_by;
            if let Some(deadline) = stop_by {
                if Instant::now() >= deadline {
                    self.counters
                        .store_dropped
                        .fetch_add(batch.len() as u64, Ordering::Relaxed);
                    error!(
                        rows = batch.len(),
                        "stopping with the local store failing: rows dropped"
                    );
                    batch.clear();
                    return;
                }
            }
            let pause = stop_by.map_or(backoff, |deadline| {
                backoff.min(deadline.saturating_duration_since(Instant::now()))
            });
            self.queue.wait_closed(pause);
            backoff = (backoff * 2).min(RETRY_MAX);
        }
    }
}

/// Inserts `batch` in one transaction and records the row ids in the open session, if any.
pub fn commit(db: &mut Connection, batch: &[Row]) -> rusqlite::Result<()> {
    let transaction = db.transaction()?;
    // The row ids each table got in this batch, for the open session's record.
    let mut ids: Vec<Option<(i64, i64)>> = vec![None; TABLES.len()];
    let mut tally = Tally::default();
    {
        // Each table's statement is prepared once per batch, not looked up per row.
        let mut statements: Vec<Option<rusqlite::CachedStatement<'_>>> =
            TABLES.iter().map(|_| None).collect();
        for row in batch {
            let table = row.table();
            let (Some(slot), Some(range)) =
                (statements.get_mut(table.index), ids.get_mut(table.index))
            else {
                continue;
            };
            let statement = match slot {
                Some(statement) => statement,
                None => slot.insert(transaction.prepare_cached(table.sqlite.insert)?),
            };
            row.bind(statement)?;
            statement.raw_execute()?;
            tally.add(row);
            let id = transaction.last_insert_rowid();
            *range = Some(range.map_or((id, id), |(first, _)| (first, id)));
        }
    }
    if let Some(session) = session::current(&transaction)? {
        for (table, range) in TABLES.iter().zip(ids) {
            if let Some((first, last)) = range {
                session::record_rows(&transaction, session, table.name, first, last)?;
            }
        }
        tally.record(&transaction, session)?;
    }
    transaction.commit()
}
