//! The Pi's ingest service as a library: the binary (`aer-raspi`), the end-to-end tests and the
//! benchmarks run the same stages.
//!
//! Data flow, one way: [`source`] (SocketCAN, or a candump log replayed) -> [`ingest`]
//! (decoding, shared with the dashboard in `aer-host`) -> [`sink`]s: typed MQTT topics on the
//! embedded [`broker`], and the SQLite [`store`] -> [`forward`] (TDengine). [`export`] reads
//! the store back out. [`status_topics`] publishes the service's status and metrics;
//! [`service`] assembles it all.

pub mod broker;
mod bus_names;
pub mod column_descriptions;
pub mod commands;
pub mod config;
pub mod disk;
pub mod export;
pub mod forward;
pub mod health;
pub mod ingest;
pub mod marks;
pub mod markup;
pub mod pit;
pub mod rawlog;
pub mod report;
pub mod service;
pub mod sink;
pub mod source;
pub mod status_events;
pub mod status_topics;
pub mod store;
pub mod xcp_gateway;
