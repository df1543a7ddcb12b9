//! The console's output: a bounded byte queue of whole lines.
//!
//! Writers (any task, any priority, through the firmware's lock) append a line or drop it
//! whole and count the drop; the USB interrupt drains bytes as the host reads them. Nothing
//! waits: a host that is not reading (no terminal open, cable out) costs dropped lines, never
//! time in the control path.
//!
//! A line is formatted straight into the queue and kept only once it is whole, so its length
//! is bounded by the free space alone: a long report line (a bus that heard many ids, a pin
//! with a long source) prints like a short one, and only a queue the host has not drained
//! drops lines.

use core::fmt::{self, Write};

/// A bounded queue of log lines, `N` bytes.
#[derive(Debug)]
pub struct LogBuffer<const N: usize> {
    bytes: [u8; N],
    /// Index of the oldest byte.
    head: usize,
    /// Bytes queued.
    len: usize,
    /// Lines dropped because they did not fit (since start-up).
    dropped: u32,
}

impl<const N: usize> Default for LogBuffer<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> LogBuffer<N> {
    /// An empty buffer.
    pub const fn new() -> Self {
        Self {
            bytes: [0; N],
            head: 0,
            len: 0,
            dropped: 0,
        }
    }

    /// Lines dropped because the buffer was full.
    pub const fn dropped(&self) -> u32 {
        self.dropped
    }

    /// Bytes waiting for the host.
    pub const fn len(&self) -> usize {
        self.len
    }

    /// True when nothing waits.
    pub const fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Appends `args` and a line end, or nothing if the whole line does not fit in the free
    /// space (counted). Returns whether it was queued.
    pub fn line(&mut self, args: fmt::Arguments<'_>) -> bool {
        let mut pending = Pending {
            log: self,
            written: 0,
        };
        let fits = pending.write_fmt(args).is_ok() && pending.write_str("\r\n").is_ok();
        let written = pending.written;
        if !fits {
            self.dropped = self.dropped.wrapping_add(1);
            return false;
        }
        self.len += written;
        true
    }

    /// Moves up to `out.len()` queued bytes into `out`, oldest first, without removing them;
    /// returns how many. Call [`consume`](Self::consume) with what the host accepted.
    pub fn peek(&self, out: &mut [u8]) -> usize {
        let count = out.len().min(self.len);
        for (offset, slot) in out.iter_mut().take(count).enumerate() {
            *slot = self
                .bytes
                .get((self.head + offset) % N)
                .copied()
                .unwrap_or(0);
        }
        count
    }

    /// Removes the `count` oldest bytes (what the host accepted).
    pub fn consume(&mut self, count: usize) {
        let count = count.min(self.len);
        if N > 0 {
            self.head = (self.head + count) % N;
        }
        self.len -= count;
    }
}

/// A line being formatted into the free space behind the queued bytes; the queue takes it
/// only once it is whole ([`LogBuffer::line`]).
struct Pending<'a, const N: usize> {
    log: &'a mut LogBuffer<N>,
    /// Bytes of the line written so far.
    written: usize,
}

impl<const N: usize> Write for Pending<'_, N> {
    fn write_str(&mut self, text: &str) -> fmt::Result {
        let used = self.log.len + self.written;
        if text.len() > N - used {
            return Err(fmt::Error);
        }
        for (offset, &byte) in text.as_bytes().iter().enumerate() {
            let at = (self.log.head + used + offset) % N;
            if let Some(slot) = self.log.bytes.get_mut(at) {
                *slot = byte;
            }
        }
        self.written += text.len();
        Ok(())
    }
}

/// Typed input from the host: bytes gathered into lines of at most `N` bytes.
#[derive(Debug)]
pub struct LineReader<const N: usize> {
    bytes: [u8; N],
    len: usize,
    /// The line being gathered is longer than `N`: the rest of it is discarded.
    overlong: bool,
    /// Lines discarded for being too long, or not UTF-8.
    discarded: u32,
}

impl<const N: usize> Default for LineReader<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> LineReader<N> {
    /// Nothing typed yet.
    pub const fn new() -> Self {
        Self {
            bytes: [0; N],
            len: 0,
            overlong: false,
            discarded: 0,
        }
    }

    /// Lines discarded (too long, or not text).
    pub const fn discarded(&self) -> u32 {
        self.discarded
    }

    /// Feeds one byte; returns a complete line (without its end, trimmed) when `byte` ends
    /// one. Carriage return and line feed both end a line; an empty line is skipped; backspace
    /// (BS or DEL, what terminals send) takes back the last byte typed.
    pub fn push(&mut self, byte: u8) -> Option<&str> {
        if byte == 0x08 || byte == 0x7F {
            if !self.overlong {
                self.len = self.len.saturating_sub(1);
            }
            return None;
        }
        if byte == b'\r' || byte == b'\n' {
            let len = core::mem::take(&mut self.len);
            if core::mem::take(&mut self.overlong) {
                self.discarded = self.discarded.wrapping_add(1);
                return None;
            }
            let line = self.bytes.get(..len)?;
            return match core::str::from_utf8(line) {
                Ok(text) if !text.trim().is_empty() => Some(text.trim()),
                Ok(_) => None,
                Err(_) => {
                    self.discarded = self.discarded.wrapping_add(1);
                    None
                }
            };
        }
        match self.bytes.get_mut(self.len) {
            Some(slot) if !self.overlong => {
                *slot = byte;
                self.len += 1;
            }
            _ => self.overlong = true,
        }
        None
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::format;

    #[test]
    fn backspace_takes_back_the_last_byte_typed() {
        let mut reader = LineReader::<16>::new();
        let mut typed = None;
        for &byte in b"repq\x7f\x08port\r" {
            typed = reader.push(byte).map(std::string::String::from).or(typed);
        }
        assert_eq!(typed.as_deref(), Some("report"));
        let mut reader = LineReader::<16>::new();
        let mut typed = None;
        for &byte in b"\x7f\x7fhelp\n" {
            typed = reader.push(byte).map(std::string::String::from).or(typed);
        }
        assert_eq!(
            typed.as_deref(),
            Some("help"),
            "nothing to take back is nothing"
        );
    }

    fn drain<const N: usize>(log: &mut LogBuffer<N>) -> std::string::String {
        let mut out = [0u8; 64];
        let mut text = std::string::String::new();
        loop {
            let count = log.peek(&mut out);
            if count == 0 {
                return text;
            }
            text.push_str(core::str::from_utf8(&out[..count]).unwrap());
            log.consume(count);
        }
    }

    #[test]
    fn lines_that_do_not_fit_are_dropped_whole_and_counted() {
        let mut log = LogBuffer::<16>::new();
        assert!(log.line(format_args!("state {}", 1)));
        assert!(!log.line(format_args!("a longer line")));
        assert_eq!(log.dropped(), 1);
        assert_eq!(drain(&mut log), "state 1\r\n");
        assert!(log.line(format_args!("a longer line")), "room again");
        assert_eq!(drain(&mut log), "a longer line\r\n");
    }

    #[test]
    fn a_line_is_limited_by_the_free_space_alone() {
        let mut log = LogBuffer::<1_024>::new();
        let long = "x".repeat(700);
        assert!(log.line(format_args!("{long}")));
        assert!(
            !log.line(format_args!("{long}")),
            "no room for a second one"
        );
        assert_eq!(log.dropped(), 1);
        assert_eq!(log.len(), 702, "the dropped line left nothing behind");
        assert_eq!(drain(&mut log), format!("{long}\r\n"));
        assert!(
            log.line(format_args!("{long}")),
            "room again, across the wrap"
        );
        assert_eq!(drain(&mut log), format!("{long}\r\n"));
    }

    #[test]
    fn a_partial_read_keeps_the_rest_in_order_across_the_wrap() {
        let mut log = LogBuffer::<12>::new();
        for round in 0..20 {
            assert!(log.line(format_args!("{round:03}")));
            let mut two = [0u8; 2];
            assert_eq!(log.peek(&mut two), 2);
            log.consume(2);
            let rest = drain(&mut log);
            assert_eq!(
                format!("{}{rest}", core::str::from_utf8(&two).unwrap()),
                format!("{round:03}\r\n")
            );
        }
    }

    #[test]
    fn typed_lines_end_on_cr_or_lf_and_overlong_ones_are_discarded() {
        let mut reader = LineReader::<8>::new();
        let mut lines = std::vec::Vec::new();
        for &byte in b"help\r\n\nout led on\rcal rest\n" {
            if let Some(line) = reader.push(byte) {
                lines.push(std::string::String::from(line));
            }
        }
        assert_eq!(lines, ["help", "cal rest"]);
        assert_eq!(reader.discarded(), 1);
    }
}
