//! What every host-side consumer of the car's data shares, the Pi service and the dashboard
//! alike, with nothing of either: no broker, no database, no UI.
//!
//! - [`formats`]: the byte formats: candump text, the raw log's segments, the pit stream's
//!   batches and the frame record they share;
//! - [`decode`]: frames in, decoded records out (ISO-TP reassembly, fingerprint check, the
//!   generated decoders), and [`decode::decode_log`] for whole logs;
//! - [`reports`]: what the service reports: its counters, its status and metrics payloads and
//!   their typed topics, each bus's measured traffic;
//! - [`link`]: the clients off the Pi: TLS with the team's certificates, the pit's history
//!   requests, the XCP master through the Pi's gateway;
//! - [`run`]: the channels derived from the telemetry (speed, power, distance, energy) and
//!   the laps;
//! - [`calibration`]: the calibration record's entries as the Pi and the pit show them;
//! - [`config`]: reading configuration files and the broker settings both tiers use;
//! - [`clock`]: timestamps as the topics carry them;
//! - [`logging`]: log output fit for a terminal and for the journal.

pub mod calibration;
pub mod clock;
pub mod config;
pub mod decode;
pub mod formats;
pub mod link;
pub mod logging;
pub mod reports;
pub mod run;
