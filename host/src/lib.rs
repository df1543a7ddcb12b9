//! What every host-side consumer of the car's data shares, the Pi service and the dashboard
//! alike, with nothing of either: no broker, no database, no UI.
//!
//! - [`candump`]: candump log lines, the interchange format of recorded sessions;
//! - [`raw_format`]: the raw log's segment format, written before decoding, read by replays;
//! - [`decode`]: frames in, decoded records out (ISO-TP reassembly, fingerprint check, the
//!   generated decoders), and [`decode::decode_log`] for whole logs;
//! - [`counters`]: the service's counters, one set for counting and publishing;
//! - [`status`]: the service's status and metrics payloads and their typed topics;
//! - [`traffic`]: each bus's measured load and each message's measured rate;
//! - [`config`]: reading configuration files and the broker settings both tiers use;
//! - [`pit_stream`]: the compact stream for the pit: ingest's input in compressed batches;
//! - [`pit_history`]: what a pit that missed batches asks for, and how the Pi answers;
//! - [`tls`]: TLS for MQTT clients off the Pi, trusting the team's certificates only;
//! - [`clock`]: timestamps as the topics carry them;
//! - [`logging`]: log output fit for a terminal and for the journal.

pub mod calibration;
pub mod candump;
pub mod clock;
pub mod config;
pub mod counters;
pub mod decode;
pub mod frame_record;
pub mod logging;
pub mod pit_history;
pub mod pit_stream;
pub mod raw_format;
pub mod status;
pub mod tls;
pub mod traffic;
pub mod varint;
pub mod xcp_master;
