//! ASC, the Vector tools' text log (CANalyzer, CANoe): a header with the start time, then one
//! line per frame with its time from the start in microseconds, channel, identifier
//! (hexadecimal, `x` for an extended one), direction and data.
//!
//! Times are the Pi's receive times in UTC (the Pi's clock): the start is the earliest frame's
//! second, so every line's offset is exact to the microsecond.

use super::{FrameWriter, Summary};
use aer_host::formats::raw_format::Frame;
use embedded_can::Id;
use std::io::{self, Write};

/// Writes one ASC file.
pub struct AscWriter<W: Write> {
    out: W,
    start_us: u64,
}

impl<W: Write> AscWriter<W> {
    /// Writes the header: the start, the metadata as comments, and which bus each channel is.
    pub fn new(mut out: W, summary: &Summary, metadata: &[(String, String)]) -> io::Result<Self> {
        let start_us = summary.first_us - summary.first_us % 1_000_000;
        let start = vector_date(start_us);
        writeln!(out, "date {start}")?;
        writeln!(out, "base hex  timestamps absolute")?;
        writeln!(out, "internal events logged")?;
        writeln!(
            out,
            "// exported by aer-raspi {}",
            env!("CARGO_PKG_VERSION")
        )?;
        writeln!(out, "// times: when the Pi received each frame, UTC")?;
        writeln!(out, "// channels: {}", summary.channels.describe())?;
        for (key, value) in metadata {
            writeln!(out, "// {key}: {}", one_line(value))?;
        }
        writeln!(out, "Begin Triggerblock {start}")?;
        writeln!(out, "   0.000000 Start of measurement")?;
        Ok(Self { out, start_us })
    }
}

impl<W: Write> FrameWriter for AscWriter<W> {
    fn frame(&mut self, frame: &Frame, channel: u16) -> io::Result<()> {
        let at = frame.frame.ts_us.saturating_sub(self.start_us);
        let id = match frame.frame.id {
            Id::Standard(id) => format!("{:X}", id.as_raw()),
            Id::Extended(id) => format!("{:X}x", id.as_raw()),
        };
        let payload = frame.frame.payload();
        write!(
            self.out,
            "{:>4}.{:06} {channel}  {id:<15} Rx   d {:X}",
            at / 1_000_000,
            at % 1_000_000,
            payload.len()
        )?;
        for byte in payload {
            write!(self.out, " {byte:02X}")?;
        }
        writeln!(self.out)
    }

    fn finish(mut self: Box<Self>) -> io::Result<()> {
        writeln!(self.out, "End TriggerBlock")?;
        self.out.flush()
    }
}

/// A time as the Vector tools write it in a header: `Fri Nov 27 02:08:40.000 am 2026`.
fn vector_date(us: u64) -> String {
    i64::try_from(us)
        .ok()
        .and_then(chrono::DateTime::from_timestamp_micros)
        .unwrap_or_default()
        .format("%a %b %d %I:%M:%S%.3f %P %Y")
        .to_string()
}

/// A metadata value on one comment line.
fn one_line(value: &str) -> String {
    value.replace(['\r', '\n'], " ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_header_date_is_the_vector_form() {
        // 2026-11-27 14:08:40 UTC.
        assert_eq!(
            vector_date(1_795_788_520_000_000),
            "Fri Nov 27 02:08:40.000 pm 2026"
        );
    }
}
