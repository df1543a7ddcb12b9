//! Sending a batch so that one bad row cannot stall the rest: a statement TDengine refuses
//! while it is up is split in halves until the rows it refuses are found; those are set
//! aside and everything else goes in. A database that is down is an outage, not a bad row:
//! the whole batch waits for it.

use super::cursor::Batch;
use super::sql::Mapping;
use std::future::Future;
use std::ops::Range;

/// Where rows go: TDengine, or a fake that refuses as it does (tests).
pub trait Destination: Send {
    /// Runs one statement; `Err` carries the database's (or the transport's) reason.
    fn exec(&mut self, sql: &str) -> impl Future<Output = Result<(), String>> + Send;
    /// Whether the database answers at all, to tell a refused statement from an outage.
    fn alive(&mut self) -> impl Future<Output = bool> + Send;
}

/// How a batch went.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Sent {
    /// Rows that went in.
    pub rows: usize,
    /// Rows refused on their own, with the reason: (id, error).
    pub set_aside: Vec<(i64, String)>,
}

/// Sends `batch` through `mapping`. `Err` (with the reason) if the database stopped
/// answering: the caller keeps the batch and tries again later. Rows in a statement that
/// failed part-way may be sent twice; TDengine keeps one row per timestamp and sub-table, so
/// that overwrites, it does not duplicate.
pub async fn send(
    destination: &mut impl Destination,
    mapping: &Mapping,
    batch: &Batch,
) -> Result<Sent, String> {
    let mut sent = Sent::default();
    let mut pending: Vec<Range<usize>> = Vec::new();
    pending.push(0..batch.rows.len());
    while let Some(range) = pending.pop() {
        let Some(rows) = batch.rows.get(range.clone()) else {
            continue;
        };
        if rows.is_empty() {
            continue;
        }
        let mut refused = None;
        for statement in mapping.inserts(rows) {
            if let Err(error) = destination.exec(&statement).await {
                refused = Some(error);
                break;
            }
        }
        let Some(error) = refused else {
            sent.rows += rows.len();
            continue;
        };
        if !destination.alive().await {
            return Err(error);
        }
        if range.len() == 1 {
            if let Some(id) = batch.ids.get(range.start) {
                sent.set_aside.push((*id, error));
            }
            continue;
        }
        // The second half waits under the first: rows still go in in order.
        let middle = range.start + range.len() / 2;
        pending.push(middle..range.end);
        pending.push(range.start..middle);
    }
    Ok(sent)
}
