//! The checks `cargo xtask m7-check` runs twice, on the host and on an emulated Cortex-M7, and
//! compares line by line: any difference means the firmware's instruction set computes
//! something else than the host tests saw (float handling, integer widths, layout).
//!
//! Each check writes one or more transcript lines; bulk results are folded into an FNV-1a
//! digest of their `Debug` text and bytes, so the transcript stays short while covering every
//! decoded value.
#![no_std]

pub mod bench_day;
mod bench_sim;
mod bringup;
mod ccm;
mod codec;
mod cost;
mod digest;
mod isotp;
mod pcc;

pub use cost::{COSTS, Cost};
pub use digest::Digest;

/// Writes the whole transcript.
pub fn run(out: &mut impl core::fmt::Write) -> core::fmt::Result {
    codec::can_messages(out)?;
    codec::telemetry(out)?;
    isotp::transfers(out)?;
    pcc::scenarios(out)?;
    ccm::session(out)?;
    bringup::checks(out)?;
    bench_day::transcripts(out)?;
    writeln!(out, "done")
}
