//! What the Pi service reports about itself and the dashboard reads: the counters, the status
//! and metrics payloads and their topics, each bus's measured traffic, what
//! the schema declares and never arrived.

pub mod arrivals;
pub mod counters;
pub mod status;
pub mod traffic;
