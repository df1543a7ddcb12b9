//! The Pi's ingest service as a library: the binary (`aer-raspi`), the end-to-end tests and the
//! benchmarks use the same pipeline.
//!
//! Data flow: [`source`] (SocketCAN, a candump log via [`candump`], or [`synthetic`]) ->
//! [`pipeline`] -> [`ingest`] (ISO-TP + generated decoders) -> [`publish`] (typed MQTT topics
//! on the embedded [`broker`]) and [`store`] (SQLite) -> [`forward`] (TDengine via [`sql`]).
//! [`metrics`] counts everything on the way.

pub mod broker;
pub mod candump;
pub mod config;
pub mod forward;
pub mod ingest;
pub mod metrics;
pub mod pipeline;
pub mod publish;
pub mod source;
pub mod sql;
pub mod store;
pub mod synthetic;
