//! The durable local store (SQLite, bundled): the generated tables, written in batches by one
//! thread, plus the forwarder's cursor table. Nothing is dropped on the way in: a full queue
//! slows the producer down instead.

use crate::ingest::Record;
use crate::metrics::Counters;
use aer::can::AnyMessage;
use aer::can::MESSAGES;
use aer::local_store::{LocalTable, TABLES};
use aer::runtime::{SignalMeta, SignalVisitor, Value};
use aer::telemetry::{Telemetry, TelemetryHeader};
use rusqlite::{Connection, Statement};
use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;
use thiserror::Error;
use tracing::{error, info};

/// Rows per transaction at most, and the longest a row waits for its batch.
const BATCH_ROWS: usize = 2_000;
const BATCH_WAIT: Duration = Duration::from_millis(100);
/// Rows that may wait for the writer before producers block.
const QUEUE_ROWS: usize = 65_536;

/// Why the store cannot be used.
#[derive(Debug, Error)]
pub enum StoreError {
    /// The file cannot be created or opened (missing folder, no permission, read-only disk).
    #[error("cannot open the local store at {path}: {source}")]
    Open {
        path: PathBuf,
        #[source]
        source: rusqlite::Error,
    },
    /// Creating or migrating the tables failed.
    #[error("cannot prepare the local store's tables at {path}: {source}")]
    Schema {
        path: PathBuf,
        #[source]
        source: rusqlite::Error,
    },
}

/// The forwarder's persisted position per table.
pub const CURSOR_TABLE: &str = "CREATE TABLE IF NOT EXISTS \"forward_cursor\" (\"table_name\" TEXT PRIMARY KEY, \"last_id\" INTEGER NOT NULL)";

/// Opens (creating if needed) the store at `path` and brings its tables up to this schema:
/// missing tables are created, missing columns added. Fails at once if the path is not
/// writable, so a bad path is reported at start-up, not at the first packet.
pub fn open(path: &Path) -> Result<Connection, StoreError> {
    let open_error = |source| StoreError::Open {
        path: path.to_owned(),
        source,
    };
    let db = Connection::open(path).map_err(open_error)?;
    let schema_error = |source| StoreError::Schema {
        path: path.to_owned(),
        source,
    };
    // WAL: the forwarder reads while the writer appends; NORMAL sync is durable across
    // application crashes and loses at most the last transaction on power loss.
    db.pragma_update(None, "journal_mode", "WAL")
        .map_err(schema_error)?;
    db.pragma_update(None, "synchronous", "NORMAL")
        .map_err(schema_error)?;
    for table in TABLES {
        for statement in table.create {
            db.execute(statement, []).map_err(schema_error)?;
        }
        migrate(&db, table).map_err(schema_error)?;
    }
    db.execute(CURSOR_TABLE, []).map_err(schema_error)?;
    Ok(db)
}

/// Adds the columns a store created by an older build lacks.
fn migrate(db: &Connection, table: &LocalTable) -> rusqlite::Result<()> {
    let mut statement = db.prepare("SELECT name FROM pragma_table_info(?1)")?;
    let existing: Vec<String> = statement
        .query_map([table.name], |row| row.get(0))?
        .collect::<rusqlite::Result<_>>()?;
    let existing: Vec<&str> = existing.iter().map(String::as_str).collect();
    for column in table.missing_columns(&existing) {
        info!(
            table = table.name,
            column = column.name,
            "adding a column the store lacks"
        );
        db.execute(&table.add_column_sql(column), [])?;
    }
    Ok(())
}

/// One record on its way into the store: the decoded values themselves. The writer binds
/// them straight into its insert, so the pipeline allocates nothing per row.
#[derive(Debug, Clone, PartialEq)]
pub struct Row {
    pub car_id: Arc<str>,
    /// Receive time (us since the epoch).
    pub ts_us: u64,
    pub data: RowData,
}

/// What a row holds.
#[derive(Debug, Clone, PartialEq)]
pub enum RowData {
    Telemetry {
        header: TelemetryHeader,
        telemetry: Telemetry,
    },
    Can {
        /// The bus's interface name.
        bus: Arc<str>,
        message: AnyMessage,
    },
}

/// The row a record becomes; `bus_names` maps bus numbers to interface names.
pub fn row(record: &Record, car_id: &Arc<str>, bus_names: &[Arc<str>]) -> Row {
    match record {
        Record::Telemetry {
            ts_us,
            header,
            telemetry,
            ..
        } => Row {
            car_id: car_id.clone(),
            ts_us: *ts_us,
            data: RowData::Telemetry {
                header: *header,
                telemetry: **telemetry,
            },
        },
        Record::Can {
            ts_us,
            bus,
            message,
        } => Row {
            car_id: car_id.clone(),
            ts_us: *ts_us,
            data: RowData::Can {
                bus: bus_names
                    .get(usize::from(*bus))
                    .cloned()
                    .unwrap_or_else(|| format!("bus{bus}").into()),
                message: *message,
            },
        },
    }
}

impl Row {
    /// Index of the row's table in `aer::local_store::TABLES` (telemetry first, then one per
    /// DBC message in schema order).
    fn table(&self) -> Option<usize> {
        match &self.data {
            RowData::Telemetry { .. } => Some(0),
            RowData::Can { message, .. } => {
                let meta = message.meta();
                // Compared by id: a `const` reference need not have one address.
                MESSAGES
                    .iter()
                    .position(|m| m.id == meta.id && m.extended == meta.extended)
                    .map(|index| index + 1)
            }
        }
    }

    /// Binds every column of the row into `statement` (its table's insert).
    fn bind(&self, statement: &mut Statement<'_>) -> rusqlite::Result<()> {
        let ts = i64::try_from(self.ts_us).unwrap_or(i64::MAX);
        statement.raw_bind_parameter(1, &*self.car_id)?;
        match &self.data {
            RowData::Telemetry { header, telemetry } => {
                statement.raw_bind_parameter(2, aer::telemetry::TELEMETRY_FINGERPRINT)?;
                statement.raw_bind_parameter(3, ts)?;
                statement.raw_bind_parameter(4, header.sequence)?;
                statement.raw_bind_parameter(5, header.timestamp_us)?;
                let mut binder = Binder::new(statement, 6, &[]);
                telemetry.visit(&mut binder);
                binder.result
            }
            RowData::Can { bus, message } => {
                // Multiplexed signals that are absent must read NULL, not the previous row's.
                statement.clear_bindings();
                statement.raw_bind_parameter(1, &*self.car_id)?;
                statement.raw_bind_parameter(2, &**bus)?;
                statement.raw_bind_parameter(3, aer::can::SCHEMA_FINGERPRINT)?;
                statement.raw_bind_parameter(4, ts)?;
                let mut binder = Binder::new(statement, 5, message.meta().signals);
                message.visit(&mut binder);
                binder.result
            }
        }
    }
}

/// Binds visited values: in visiting order, or (with `signals`) at their signal's column.
struct Binder<'s, 'c> {
    statement: &'s mut Statement<'c>,
    first: usize,
    next: usize,
    signals: &'static [SignalMeta],
    result: rusqlite::Result<()>,
}

impl<'s, 'c> Binder<'s, 'c> {
    fn new(statement: &'s mut Statement<'c>, first: usize, signals: &'static [SignalMeta]) -> Self {
        Self {
            statement,
            first,
            next: first,
            signals,
            result: Ok(()),
        }
    }
}

impl SignalVisitor for Binder<'_, '_> {
    fn signal(&mut self, signal: &'static SignalMeta, value: Value, _: Option<&'static str>) {
        if self.result.is_err() {
            return;
        }
        let index = if self.signals.is_empty() {
            self.next
        } else {
            match self.signals.iter().position(|s| s.name == signal.name) {
                Some(position) => self.first + position,
                None => return,
            }
        };
        self.next += 1;
        self.result = match value {
            Value::Int(i) => match i64::try_from(i) {
                Ok(i) => self.statement.raw_bind_parameter(index, i),
                Err(_) => self.statement.raw_bind_parameter(index, i as f64),
            },
            Value::Float(f) if f.is_finite() => self.statement.raw_bind_parameter(index, f),
            Value::Float(_) => self
                .statement
                .raw_bind_parameter(index, rusqlite::types::Null),
        };
    }
}

/// The writer thread and its queue.
pub struct StoreWriter {
    sender: Option<RowSender>,
    thread: Option<JoinHandle<()>>,
}

/// Rows waiting for the writer. Producers wake the writer only when a batch is full, so a busy
/// pipeline costs one wake-up per batch, not one per row; otherwise the writer takes what is
/// there every [`BATCH_WAIT`].
struct Queue {
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

impl StoreWriter {
    /// Starts the writer on `db`.
    pub fn start(db: Connection, counters: Arc<Counters>) -> Self {
        let queue = Arc::new(Queue {
            state: Mutex::new(Pending {
                rows: Vec::with_capacity(BATCH_ROWS),
                senders: 1,
            }),
            filled: Condvar::new(),
            emptied: Condvar::new(),
        });
        let sender = RowSender(queue.clone());
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
        let open = {
            let Ok(mut pending) = queue.state.lock() else {
                return;
            };
            if pending.rows.len() < BATCH_ROWS && pending.senders > 0 {
                match queue.filled.wait_timeout(pending, BATCH_WAIT) {
                    Ok((guard, _)) => pending = guard,
                    Err(_) => return,
                }
            }
            std::mem::swap(&mut batch, &mut pending.rows);
            queue.emptied.notify_all();
            pending.senders > 0
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
            let Some(index) = row.table() else {
                continue;
            };
            let (Some(table), Some(slot)) = (TABLES.get(index), statements.get_mut(index)) else {
                continue;
            };
            let statement = match slot {
                Some(statement) => statement,
                None => slot.insert(transaction.prepare_cached(table.insert)?),
            };
            row.bind(statement)?;
            statement.raw_execute()?;
        }
    }
    transaction.commit()
}
