//! Forwards the local store to TDengine: per table, rows after a persisted cursor, in batches
//! of up to 5,000, as typed SQL. The cursor moves only after TDengine took a batch, so an
//! outage or a reboot loses nothing; a batch re-sent after a crash overwrites the same
//! timestamps (TDengine keeps one row per timestamp and sub-table), so nothing is duplicated.
//! Rows TDengine refuses while it is up are found by splitting the batch ([`batch`]), set
//! aside in the store with the reason, and counted; they never stall the rows after them.
//! The DSN's credentials never reach the log (`redact`).

pub mod batch;
pub mod cursor;
pub mod sql;

pub use batch::{Destination, Sent};
use cursor::set_aside;
pub use cursor::{Batch, advance, next_batch};

use self::sql::Mapping;
use crate::config::TdengineConfig;
use crate::health::Health;
use aer::tables::TABLES;
use aer_host::reports::counters::{Counters, worth_logging};
use anyhow::{Context, Result};
use rusqlite::Connection;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;
use taos::{AsyncFetchable, AsyncQueryable, AsyncTBuilder, Taos, TaosBuilder};
use tokio_util::sync::CancellationToken;
use tracing::{info, warn};

/// Backoff after a failure: 1 s doubling to 30 s.
const BACKOFF_START: Duration = Duration::from_secs(1);
const BACKOFF_MAX: Duration = Duration::from_secs(30);
/// Pause when every table is caught up.
const IDLE: Duration = Duration::from_millis(200);

/// The SQL that prepares a database for this schema: the database (microsecond timestamps,
/// the configured options) and every super table, qualified with the database name (a
/// WebSocket connection has no current database).
pub(crate) fn schema_statements(config: &TdengineConfig) -> Vec<String> {
    let database = &config.database;
    let mut statements = vec![format!(
        "CREATE DATABASE IF NOT EXISTS `{database}` PRECISION 'us' {}",
        config.database_options
    )];
    statements.extend(
        TABLES
            .iter()
            .map(|t| qualified(t.tdengine.create, t.name, database)),
    );
    statements
}

/// `sql` with its first mention of `table` qualified by `database`.
fn qualified(sql: &str, table: &str, database: &str) -> String {
    sql.replacen(&format!("`{table}`"), &format!("`{database}`.`{table}`"), 1)
}

/// Connects and prepares the database; adds columns a live database lacks.
async fn connect(config: &TdengineConfig) -> Result<Taos> {
    let builder = TaosBuilder::from_dsn(&config.dsn).context("TDengine DSN")?;
    let taos = builder.build().await.context("connecting to TDengine")?;
    let database = &config.database;
    for statement in schema_statements(config) {
        taos.exec(&statement)
            .await
            .with_context(|| format!("running {statement}"))?;
    }
    for table in TABLES {
        let described = taos
            .query(format!("DESCRIBE `{database}`.`{}`", table.name))
            .await?
            .to_records()
            .await?;
        let existing: Vec<String> = described
            .iter()
            .filter_map(|row| row.first().and_then(|v| v.to_string().ok()))
            .collect();
        let existing: Vec<&str> = existing.iter().map(String::as_str).collect();
        for column in table.missing_columns(&existing) {
            info!(
                table = table.name,
                column = column.name,
                "adding a column TDengine lacks"
            );
            let sql = qualified(&table.tdengine_add_column(column), table.name, database);
            taos.exec(&sql)
                .await
                .with_context(|| format!("running {sql}"))?;
        }
    }
    Ok(taos)
}

/// TDengine through its WebSocket client.
struct Tdengine(Taos);

impl Destination for Tdengine {
    async fn exec(&mut self, sql: &str) -> Result<(), String> {
        self.0
            .exec(sql)
            .await
            .map(|_| ())
            .map_err(|e| e.to_string())
    }

    async fn alive(&mut self) -> bool {
        self.0.query("SELECT SERVER_VERSION()").await.is_ok()
    }
}

/// Runs the forwarder until `cancel`: `config.workers` workers share the tables.
pub async fn run(
    config: TdengineConfig,
    store: PathBuf,
    counters: Arc<Counters>,
    health: Arc<Health>,
    cancel: CancellationToken,
) {
    let workers = config.workers.clamp(1, TABLES.len());
    let mut handles = Vec::new();
    for worker in 0..workers {
        let tables: Vec<usize> = (0..TABLES.len())
            .filter(|t| t % workers == worker)
            .collect();
        let config = config.clone();
        let (store, counters, health, cancel) = (
            store.clone(),
            counters.clone(),
            health.clone(),
            cancel.clone(),
        );
        handles.push(tokio::spawn(async move {
            let connect = || async {
                connect(&config)
                    .await
                    .map(Tdengine)
                    .map_err(|e| format!("{e:#}"))
            };
            let worker = Worker {
                config: &config,
                tables,
                counters: &counters,
                health: &health,
            };
            worker.run(&store, connect, &cancel).await;
        }));
    }
    for handle in handles {
        let _ = handle.await;
    }
}

/// One worker: its tables, and where it reports.
pub struct Worker<'a> {
    pub config: &'a TdengineConfig,
    /// Indices into `TABLES`.
    pub tables: Vec<usize>,
    pub counters: &'a Counters,
    pub health: &'a Health,
}

impl Worker<'_> {
    /// Forwards until `cancel`, connecting with `connect` (again after each outage).
    pub async fn run<D, F, Fut>(
        &self,
        store: &std::path::Path,
        connect: F,
        cancel: &CancellationToken,
    ) where
        D: Destination,
        F: Fn() -> Fut,
        Fut: std::future::Future<Output = Result<D, String>>,
    {
        // Held as `&mut` across awaits (a shared `&Connection` is not `Send`).
        let mut db = match Connection::open(store) {
            Ok(db) => db,
            Err(error) => {
                warn!(%error, "forwarder cannot open the local store");
                return;
            }
        };
        let _ = db.busy_timeout(Duration::from_secs(5));
        let mut backoff = BACKOFF_START;
        let mut destination: Option<D> = None;
        while !cancel.is_cancelled() {
            let connection = match &mut destination {
                Some(connection) => connection,
                None => match connect().await {
                    Ok(connection) => {
                        info!(dsn = %redact(&self.config.dsn), "forwarding the local store to TDengine");
                        backoff = BACKOFF_START;
                        destination.insert(connection)
                    }
                    Err(error) => {
                        self.outage(&error, backoff);
                        pause(backoff, cancel).await;
                        backoff = (backoff * 2).min(BACKOFF_MAX);
                        continue;
                    }
                },
            };
            match self.pass(&mut db, connection).await {
                Ok(0) => pause(IDLE, cancel).await,
                Ok(_) => {
                    if self.health.forward.recovered() {
                        info!("forwarding to TDengine again");
                    }
                }
                Err(error) => {
                    self.outage(&error, backoff);
                    destination = None;
                    pause(backoff, cancel).await;
                    backoff = (backoff * 2).min(BACKOFF_MAX);
                }
            }
        }
    }

    /// One batch of each table; returns the rows moved, or the outage that stopped it.
    async fn pass(
        &self,
        db: &mut Connection,
        destination: &mut impl Destination,
    ) -> Result<usize, String> {
        let mut moved = 0;
        for &table in &self.tables {
            let Some(local) = TABLES.get(table) else {
                continue;
            };
            let batch = match next_batch(db, table, self.config.batch_rows.clamp(1, 5_000)) {
                Ok(batch) => batch,
                Err(error) => {
                    warn!(%error, "reading the local store failed");
                    continue;
                }
            };
            for damaged in &batch.damaged {
                let count = Counters::bump(&self.counters.damaged_blocks);
                warn!(error = %damaged, count, "a compacted block does not decode: its rows are not forwarded");
            }
            let Some(last) = batch.last_id() else {
                continue;
            };
            if batch.ids.is_empty() {
                // Only damaged blocks: move past them.
                if let Err(error) = advance(db, table, last) {
                    warn!(%error, "forwarder cursor not saved");
                }
                continue;
            }
            let mapping = Mapping::new(local, &self.config.database);
            let sent = batch::send(destination, &mapping, &batch).await?;
            if !sent.set_aside.is_empty() {
                self.set_aside(db, table, &sent.set_aside);
            }
            if let Err(error) = advance(db, table, last) {
                warn!(%error, "forwarder cursor not saved; the batch will be sent again (overwrites, no duplicates)");
            }
            self.counters
                .forwarded
                .fetch_add(sent.rows as u64, Ordering::Relaxed);
            moved += batch.ids.len();
        }
        Ok(moved)
    }

    fn set_aside(&self, db: &Connection, table: usize, rows: &[(i64, String)]) {
        let count = self
            .counters
            .forward_set_aside
            .fetch_add(rows.len() as u64, Ordering::Relaxed)
            + rows.len() as u64;
        let first = rows.first().map(|(_, e)| e.as_str()).unwrap_or_default();
        self.health.forward_refused.failed(&format!(
            "TDengine refused {count} row(s), set aside in the store (forward_set_aside): {first}"
        ));
        warn!(
            rows = rows.len(),
            count,
            error = first,
            "TDengine refused rows; set aside in the store (forward_set_aside) and moving on"
        );
        if let Err(error) = set_aside(db, table, rows) {
            warn!(%error, "could not record the refused rows; they stay in the store");
        }
    }

    fn outage(&self, error: &str, backoff: Duration) {
        let count = Counters::bump(&self.counters.forward_errors);
        let error = redact(error);
        self.health
            .forward
            .failed(&format!("TDengine unreachable: {error}"));
        if worth_logging(count) {
            warn!(
                error,
                retry_s = backoff.as_secs(),
                count,
                "TDengine unreachable; rows stay in the local store"
            );
        }
    }
}

/// `dsn` (or a message quoting it) without credentials: the password in `user:password@`
/// and any `token=` or `password=` parameter become `***`.
pub(crate) fn redact(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(at) = rest.find("://") {
        let (head, tail) = rest.split_at(at + 3);
        out.push_str(head);
        let authority_end = tail
            .find(|c: char| c == '/' || c == '?' || c.is_whitespace())
            .unwrap_or(tail.len());
        let (authority, after) = tail.split_at(authority_end);
        match authority.rsplit_once('@') {
            Some((userinfo, host)) => {
                let user = userinfo.split_once(':').map_or(userinfo, |(user, _)| user);
                out.push_str(user);
                if userinfo.contains(':') {
                    out.push_str(":***");
                }
                out.push('@');
                out.push_str(host);
            }
            None => out.push_str(authority),
        }
        rest = after;
    }
    out.push_str(rest);
    for key in ["token=", "password=", "pass="] {
        while let Some(at) = out.find(key) {
            let value_start = at + key.len();
            if out.get(value_start..).is_some_and(|v| v.starts_with("***")) {
                break;
            }
            let value_end = out[value_start..]
                .find(|c: char| c == '&' || c.is_whitespace())
                .map_or(out.len(), |end| value_start + end);
            out.replace_range(value_start..value_end, "***");
        }
    }
    out
}

/// Waits `duration`, or less if cancelled.
async fn pause(duration: Duration, cancel: &CancellationToken) {
    tokio::select! {
        () = tokio::time::sleep(duration) => {}
        () = cancel.cancelled() => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn credentials_never_reach_the_log() {
        assert_eq!(
            redact("taos+ws://root:s3cret@pit:6041"),
            "taos+ws://root:***@pit:6041"
        );
        assert_eq!(
            redact(
                "connecting to taos+wss://user:p@ss:w0rd@cloud.example/db?token=abc123&x=1 failed"
            ),
            "connecting to taos+wss://user:***@cloud.example/db?token=***&x=1 failed"
        );
        assert_eq!(
            redact("taos+ws://localhost:6041"),
            "taos+ws://localhost:6041"
        );
        assert_eq!(redact("no url here"), "no url here");
    }

    #[test]
    fn every_schema_statement_names_the_database() {
        let config = TdengineConfig {
            database: "pit".into(),
            ..TdengineConfig::default()
        };
        let statements = schema_statements(&config);
        assert!(
            statements[0].starts_with("CREATE DATABASE IF NOT EXISTS `pit` PRECISION 'us' "),
            "{}",
            statements[0]
        );
        // Sized for a Raspberry Pi by default.
        for option in ["VGROUPS 1", "BUFFER 16"] {
            assert!(statements[0].contains(option), "{}", statements[0]);
        }
        assert_eq!(statements.len(), 1 + TABLES.len());
        for (statement, table) in statements[1..].iter().zip(TABLES) {
            assert!(
                statement.starts_with(&format!(
                    "CREATE STABLE IF NOT EXISTS `pit`.`{}` (",
                    table.name
                )),
                "{statement}"
            );
        }
        let column = &TABLES[0].columns[1];
        assert_eq!(
            qualified(&TABLES[0].tdengine_add_column(column), "telemetry", "pit"),
            format!(
                "ALTER STABLE `pit`.`telemetry` ADD COLUMN `{}` {}",
                column.name,
                column.ty.tdengine()
            )
        );
    }
}
