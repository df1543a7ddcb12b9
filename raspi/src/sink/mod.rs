//! Where decoded records go: the typed MQTT topics ([`mqtt`]) and the local store
//! ([`store`], feeding [`crate::store`]'s writer). Ingest hands every record to every sink in
//! turn, on its own task.

pub mod mqtt;
pub mod store;

use aer_host::decode::Record;
use std::sync::Arc;

/// A consumer of records.
pub trait Sink: Send {
    /// Takes one record; `buses` names the bus numbers records carry.
    fn accept(&mut self, record: &Record, buses: &[Arc<str>]);

    /// Hands on whatever `accept` held back: ingest calls it before it waits for input, so
    /// nothing lingers while the buses are quiet.
    fn flush(&mut self) {}
}
