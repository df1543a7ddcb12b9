//! Forwards the local store to TDengine: per table, rows after a persisted cursor, in batches
//! of up to 5,000, as typed SQL. The cursor moves only after TDengine accepted a batch, so an
//! outage or a reboot loses nothing; a batch re-sent after a crash overwrites the same
//! timestamps (TDengine keeps one row per timestamp and sub-table), so nothing is duplicated.

use crate::config::TdengineConfig;
use crate::sql::Mapping;
use aer::tables::TABLES;
use aer_host::counters::{Counters, worth_logging};
use anyhow::{Context, Result};
use rusqlite::Connection;
use rusqlite::types::Value as Sql;
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
pub fn schema_statements(config: &TdengineConfig) -> Vec<String> {
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

/// Reads the next batch of `table` after the cursor: (last id, rows without `id`).
pub fn next_batch(
    db: &Connection,
    table: usize,
    limit: usize,
) -> rusqlite::Result<(i64, Vec<Vec<Sql>>)> {
    let Some(local) = TABLES.get(table) else {
        return Ok((0, Vec::new()));
    };
    let cursor: i64 = db
        .query_row(
            "SELECT last_id FROM forward_cursor WHERE table_name = ?1",
            [local.name],
            |row| row.get(0),
        )
        .or_else(|error| match error {
            rusqlite::Error::QueryReturnedNoRows => Ok(0),
            other => Err(other),
        })?;
    let mut statement = db.prepare_cached(&format!(
        "SELECT * FROM \"{}\" WHERE id > ?1 ORDER BY id LIMIT ?2",
        local.name
    ))?;
    let width = local.columns.len() + 1;
    let mut last = cursor;
    let rows = statement
        .query_map(rusqlite::params![cursor, limit as i64], |row| {
            let id: i64 = row.get(0)?;
            let values = (1..width)
                .map(|i| row.get::<_, Sql>(i))
                .collect::<rusqlite::Result<Vec<_>>>()?;
            Ok((id, values))
        })?
        .collect::<rusqlite::Result<Vec<_>>>()?;
    let rows = rows
        .into_iter()
        .map(|(id, values)| {
            last = id;
            values
        })
        .collect();
    Ok((last, rows))
}

/// Moves `table`'s cursor to `last_id`.
pub fn advance(db: &Connection, table: usize, last_id: i64) -> rusqlite::Result<()> {
    let Some(local) = TABLES.get(table) else {
        return Ok(());
    };
    db.execute(
        "INSERT INTO forward_cursor (table_name, last_id) VALUES (?1, ?2) \
         ON CONFLICT(table_name) DO UPDATE SET last_id = excluded.last_id",
        rusqlite::params![local.name, last_id],
    )?;
    Ok(())
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

/// Runs the forwarder until `cancel`: `config.workers` workers share the tables.
pub async fn run(
    config: TdengineConfig,
    store: PathBuf,
    counters: Arc<Counters>,
    cancel: CancellationToken,
) {
    let workers = config.workers.clamp(1, TABLES.len());
    let mut handles = Vec::new();
    for worker in 0..workers {
        let tables: Vec<usize> = (0..TABLES.len())
            .filter(|t| t % workers == worker)
            .collect();
        handles.push(tokio::spawn(worker_loop(
            config.clone(),
            store.clone(),
            tables,
            counters.clone(),
            cancel.clone(),
        )));
    }
    for handle in handles {
        let _ = handle.await;
    }
}

async fn worker_loop(
    config: TdengineConfig,
    store: PathBuf,
    tables: Vec<usize>,
    counters: Arc<Counters>,
    cancel: CancellationToken,
) {
    let mut backoff = BACKOFF_START;
    let mut taos: Option<Taos> = None;
    let db = match Connection::open(&store) {
        Ok(db) => db,
        Err(error) => {
            warn!(%error, "forwarder cannot open the local store");
            return;
        }
    };
    let _ = db.busy_timeout(Duration::from_secs(5));
    let mappings: Vec<(usize, Mapping)> = tables
        .iter()
        .filter_map(|t| Some((*t, Mapping::new(TABLES.get(*t)?, &config.database))))
        .collect();
    while !cancel.is_cancelled() {
        let connection = match &taos {
            Some(connection) => connection,
            None => match connect(&config).await {
                Ok(connection) => {
                    info!(dsn = %config.dsn, "forwarding the local store to TDengine");
                    backoff = BACKOFF_START;
                    taos.insert(connection)
                }
                Err(error) => {
                    let count = Counters::bump(&counters.forward_errors);
                    if worth_logging(count) {
                        warn!(
                            error = format!("{error:#}"),
                            retry_s = backoff.as_secs(),
                            "TDengine unreachable; rows stay in the local store"
                        );
                    }
                    pause(backoff, &cancel).await;
                    backoff = (backoff * 2).min(BACKOFF_MAX);
                    continue;
                }
            },
        };
        let mut moved = 0usize;
        let mut failed = false;
        for (table, mapping) in &mappings {
            let (last, rows) = match next_batch(&db, *table, config.batch_rows.clamp(1, 5_000)) {
                Ok(batch) => batch,
                Err(error) => {
                    warn!(%error, "reading the local store failed");
                    continue;
                }
            };
            if rows.is_empty() {
                continue;
            }
            let mut ok = true;
            for statement in mapping.inserts(&rows) {
                if let Err(error) = connection.exec(&statement).await {
                    let count = Counters::bump(&counters.forward_errors);
                    if worth_logging(count) {
                        warn!(%error, count, "TDengine write failed; retrying with backoff");
                    }
                    ok = false;
                    break;
                }
            }
            if !ok {
                failed = true;
                break;
            }
            if let Err(error) = advance(&db, *table, last) {
                warn!(%error, "forwarder cursor not saved; the batch will be sent again (overwrites, no duplicates)");
            }
            counters
                .forwarded
                .fetch_add(rows.len() as u64, Ordering::Relaxed);
            moved += rows.len();
        }
        if failed {
            taos = None;
            pause(backoff, &cancel).await;
            backoff = (backoff * 2).min(BACKOFF_MAX);
        } else if moved == 0 {
            pause(IDLE, &cancel).await;
        }
    }
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
