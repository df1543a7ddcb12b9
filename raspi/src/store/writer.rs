//! The writer thread: takes the queue's rows in batches and commits each batch in one
//! transaction. A failing store (disk full, read-only, I/O error) is retried with backoff and
//! reported; while it fails the queue fills and new rows are dropped and counted, but nothing
//! upstream waits. Between batches it applies the retention budget.

use super::calibration::{self, Entry};
use super::clock::{StepWatch, describe_step};
use super::compact::Compaction;
use super::events::{self, Event};
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

/// Calibration entries and events that may wait for the writer (a tuner makes a few a minute,
/// the status a few a second at worst).
const NOTES: usize = 1024;

/// The writer thread, and the sender it keeps until it finishes.
pub struct StoreWriter {
    sender: Option<RowSender>,
    notes: NoteSender,
    thread: Option<JoinHandle<()>>,
}

/// What the writer records in the open session besides rows.
#[derive(Debug, Clone, PartialEq)]
pub enum Note {
    /// A calibration record entry (the XCP gateway's).
    Calibration(Entry),
    /// An event (a mark, a problem, a count that grew, a loop point).
    Event(Event),
}

impl Note {
    /// The counter of notes of this kind the store could not record.
    fn unrecorded<'a>(&self, counters: &'a Counters) -> &'a std::sync::atomic::AtomicU64 {
        match self {
            Self::Calibration(_) => &counters.calibration_unrecorded,
            Self::Event(_) => &counters.events_unrecorded,
        }
    }
}

impl From<Entry> for Note {
    fn from(entry: Entry) -> Self {
        Self::Calibration(entry)
    }
}

impl From<Event> for Note {
    fn from(event: Event) -> Self {
        Self::Event(event)
    }
}

/// Hands calibration entries and events to the writer, which records them in the open
/// session. Never waits: a note the writer cannot take is counted (`calibration_unrecorded`
/// or `events_unrecorded`).
#[derive(Clone)]
pub struct NoteSender {
    notes: std::sync::mpsc::SyncSender<Note>,
    counters: Arc<Counters>,
}

impl NoteSender {
    /// A sender to `notes`, which counts in `counters` what it could not hand over.
    pub fn new(notes: std::sync::mpsc::SyncSender<Note>, counters: Arc<Counters>) -> Self {
        Self { notes, counters }
    }

    /// Hands `note` over; false (and counted) if the writer is behind or gone.
    pub fn send(&self, note: impl Into<Note>) -> bool {
        let note = note.into();
        let counter = note.unrecorded(&self.counters);
        let sent = self.notes.try_send(note).is_ok();
        if !sent {
            let count = Counters::bump(counter);
            if worth_logging(count) {
                warn!(
                    count,
                    "a calibration entry or event could not be recorded (the store is behind or stopped)"
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
        let (notes, notes_in) = std::sync::mpsc::sync_channel(NOTES);
        let notes = NoteSender::new(notes, counters.clone());
        let writer = Writer {
            db,
            queue,
            notes: notes_in,
            notes_pending: Vec::new(),
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
            notes,
            thread,
        }
    }

    /// A handle producers send rows with.
    pub fn sender(&self) -> Option<RowSender> {
        self.sender.clone()
    }

    /// A handle the XCP gateway hands its calibration entries to, and the status its events.
    pub fn note_sender(&self) -> NoteSender {
        self.notes.clone()
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
    /// Calibration entries and events, and those a failing store still owes.
    notes: std::sync::mpsc::Receiver<Note>,
    notes_pending: Vec<Note>,
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
                self.record_notes();
                return;
            };
            if !batch.is_empty() {
                self.write(&mut batch, open);
            }
            self.record_notes();
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
                self.record_notes();
                return;
            }
        }
    }

    /// Records the calibration entries and events that came in, in the open session. A
    /// failing store keeps them for the next try (up to the channel's bound; beyond it the
    /// oldest are counted as unrecorded); with no session open they are counted too.
    fn record_notes(&mut self) {
        self.notes_pending.extend(self.notes.try_iter());
        if self.notes_pending.is_empty() {
            return;
        }
        let recorded = session::current(&self.db).and_then(|session| match session {
            Some(session) => record_notes(&self.db, session, &self.notes_pending).map(|()| true),
            None => Ok(false),
        });
        match recorded {
            Ok(true) => self.notes_pending.clear(),
            Ok(false) => {
                warn!(
                    notes = self.notes_pending.len(),
                    "calibration entries or events with no session open: not recorded"
                );
                let unrecorded = std::mem::take(&mut self.notes_pending);
                self.unrecorded(&unrecorded);
            }
            Err(error) => {
                warn!(%error, "recording calibration entries or events failed; retrying");
                let over = self.notes_pending.len().saturating_sub(NOTES);
                let dropped: Vec<Note> = self.notes_pending.drain(..over).collect();
                self.unrecorded(&dropped);
            }
        }
    }

    fn unrecorded(&self, notes: &[Note]) {
        for note in notes {
            note.unrecorded(&self.counters)
                .fetch_add(1, Ordering::Relaxed);
        }
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
            if let Some(deadline) = stop_by
                && Instant::now() >= deadline
            {
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
            let pause = stop_by.map_or(backoff, |deadline| {
                backoff.min(deadline.saturating_duration_since(Instant::now()))
            });
            self.queue.wait_closed(pause);
            backoff = (backoff * 2).min(RETRY_MAX);
        }
    }
}

/// Records `notes` in session `session`, all or none.
fn record_notes(db: &Connection, session: i64, notes: &[Note]) -> rusqlite::Result<()> {
    let transaction = db.unchecked_transaction()?;
    let entries: Vec<Entry> = notes
        .iter()
        .filter_map(|note| match note {
            Note::Calibration(entry) => Some(entry.clone()),
            Note::Event(_) => None,
        })
        .collect();
    let events: Vec<Event> = notes
        .iter()
        .filter_map(|note| match note {
            Note::Event(event) => Some(event.clone()),
            Note::Calibration(_) => None,
        })
        .collect();
    calibration::insert(&transaction, session, &entries)?;
    events::insert(&transaction, session, &events)?;
    transaction.commit()
}

/// Inserts `batch` in one transaction and records the row ids in the session each row
/// belongs to: the open one, or, for rows received before a `session new` and committed after
/// it, the one it took over from.
pub fn commit(db: &mut Connection, batch: &[Row]) -> rusqlite::Result<()> {
    let transaction = db.transaction()?;
    let filing = session::filing(&transaction)?;
    // Per table, the row ids this batch gave each session (the earlier session's first: rows
    // arrive in order, so a table's rows change session once).
    let mut ids: Vec<Vec<(i64, i64, i64)>> = vec![Vec::new(); TABLES.len()];
    let mut tallies: std::collections::BTreeMap<i64, Tally> = std::collections::BTreeMap::new();
    {
        // Each table's statement is prepared once per batch, not looked up per row.
        let mut statements: Vec<Option<rusqlite::CachedStatement<'_>>> =
            TABLES.iter().map(|_| None).collect();
        for row in batch {
            let table = row.table();
            let (Some(slot), Some(ranges)) =
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
            let id = transaction.last_insert_rowid();
            let Some(filing) = filing else { continue };
            // Once a table's rows reached the open session, later ones stay in it.
            let owner = match ranges.last() {
                Some(&(last_owner, _, _)) if last_owner == filing.id => filing.id,
                _ => filing.session_of(row.ts_us),
            };
            match ranges.last_mut() {
                Some((session, _, last)) if *session == owner => *last = id,
                _ => ranges.push((owner, id, id)),
            }
            tallies.entry(owner).or_default().add(row);
        }
    }
    for (table, ranges) in TABLES.iter().zip(ids) {
        for (session, first, last) in ranges {
            session::record_rows(&transaction, session, table.name, first, last)?;
        }
    }
    for (session, tally) in &tallies {
        tally.record(&transaction, *session)?;
    }
    transaction.commit()
}
