//! The frame record the raw log ([`crate::formats::raw_format`]) and the pit stream
//! ([`crate::formats::pit_stream`]) both carry, after their own tag byte, coded here once:
//!
//! ```text
//! time since the previous record (zigzag LEB128, us) | bus u8 | flags u8 (bit 0: extended id)
//! | id (LEB128) | length u8 (0-8) | data
//! ```
//!
//! [`Cursor`] reads it (and the other records of either format) from untrusted bytes: every
//! read is checked, and a record that does not fit says why.

use crate::formats::candump::LoggedFrame;
use crate::formats::varint::{put_varint, read_varint, unzigzag, zigzag};
use embedded_can::{ExtendedId, Id, StandardId};

/// Flags bit 0: the identifier is extended (29 bits).
const FLAG_EXTENDED: u8 = 0x01;

/// Appends `frame` as a frame record (without the tag), its time relative to `last_us`, which
/// becomes the frame's.
pub fn put(out: &mut Vec<u8>, last_us: &mut u64, frame: &LoggedFrame) {
    put_time(out, last_us, frame.ts_us);
    let (flags, id) = match frame.id {
        Id::Standard(id) => (0, u32::from(id.as_raw())),
        Id::Extended(id) => (FLAG_EXTENDED, id.as_raw()),
    };
    out.extend_from_slice(&[frame.bus, flags]);
    put_varint(out, u64::from(id));
    let data = frame.payload();
    // A LoggedFrame holds at most 8 bytes.
    out.push(data.len() as u8);
    out.extend_from_slice(data);
}

/// Appends `ts_us` as the time since `last_us` (zigzag LEB128), which becomes `ts_us`.
pub fn put_time(out: &mut Vec<u8>, last_us: &mut u64, ts_us: u64) {
    let delta = ts_us.wrapping_sub(*last_us) as i64;
    *last_us = ts_us;
    put_varint(out, zigzag(delta));
}

/// A checked reader over a payload; `at` is where the next read starts (for error offsets).
pub struct Cursor<'a> {
    data: &'a [u8],
    /// The next byte's offset.
    pub at: usize,
}

/// Why a record could not be read: what a damaged-data error names.
pub type Why = &'static str;

impl<'a> Cursor<'a> {
    /// A cursor at `at` in `data`.
    pub fn new(data: &'a [u8], at: usize) -> Self {
        Self { data, at }
    }

    /// Whether every byte has been read.
    pub fn is_done(&self) -> bool {
        self.at >= self.data.len()
    }

    /// One byte.
    pub fn byte(&mut self) -> Result<u8, Why> {
        let byte = *self.data.get(self.at).ok_or("record cut short")?;
        self.at += 1;
        Ok(byte)
    }

    /// `len` bytes.
    pub fn bytes(&mut self, len: usize) -> Result<&'a [u8], Why> {
        let data: &'a [u8] = self.data;
        let end = self.at.checked_add(len).ok_or("record cut short")?;
        let bytes = data.get(self.at..end).ok_or("record cut short")?;
        self.at = end;
        Ok(bytes)
    }

    /// A LEB128 value.
    pub fn varint(&mut self) -> Result<u64, Why> {
        let (data, mut at) = (self.data, self.at);
        let value = read_varint(|| {
            let byte = data.get(at).copied();
            at += 1;
            byte
        });
        self.at = at.min(data.len());
        value.ok_or("varint cut short or too long")
    }

    /// A time since `last_us` (zigzag LEB128), which becomes the time read.
    pub fn time(&mut self, last_us: &mut u64) -> Result<u64, Why> {
        let delta = unzigzag(self.varint()?);
        *last_us = last_us.wrapping_add(delta as u64);
        Ok(*last_us)
    }

    /// A frame record (after its tag), its time relative to `last_us`, which becomes the
    /// frame's.
    pub fn frame(&mut self, last_us: &mut u64) -> Result<LoggedFrame, Why> {
        let ts_us = self.time(last_us)?;
        let bus = self.byte()?;
        let flags = self.byte()?;
        let raw_id = u32::try_from(self.varint()?).map_err(|_| "identifier too large")?;
        let id = if flags & FLAG_EXTENDED != 0 {
            ExtendedId::new(raw_id).map(Id::Extended)
        } else {
            u16::try_from(raw_id)
                .ok()
                .and_then(StandardId::new)
                .map(Id::Standard)
        }
        .ok_or("identifier out of range")?;
        let len = usize::from(self.byte()?);
        if len > 8 {
            return Err("frame longer than 8 bytes");
        }
        let data = self.bytes(len)?;
        LoggedFrame::new(ts_us, bus, id, data).ok_or("frame longer than 8 bytes")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn any_frame() -> impl Strategy<Value = LoggedFrame> {
        (
            any::<u64>(),
            any::<u8>(),
            any::<bool>(),
            any::<u32>(),
            proptest::collection::vec(any::<u8>(), 0..=8),
        )
            .prop_map(|(ts, bus, extended, id, data)| {
                let id = if extended {
                    Id::Extended(ExtendedId::new(id & 0x1FFF_FFFF).unwrap_or(ExtendedId::ZERO))
                } else {
                    Id::Standard(StandardId::new((id & 0x7FF) as u16).unwrap_or(StandardId::ZERO))
                };
                LoggedFrame::new(ts, bus, id, &data).unwrap()
            })
    }

    proptest! {
        /// Any frames, one after another, read back exactly, each time relative to the last.
        #[test]
        fn any_frames_read_back(frames in proptest::collection::vec(any_frame(), 0..50), first in any::<u64>()) {
            let mut out = Vec::new();
            let mut last = first;
            for frame in &frames {
                put(&mut out, &mut last, frame);
            }
            let mut cursor = Cursor::new(&out, 0);
            let mut last = first;
            for frame in &frames {
                prop_assert_eq!(cursor.frame(&mut last), Ok(*frame));
            }
            prop_assert!(cursor.is_done());
        }

        /// Any bytes: a frame or a reason, never a panic, never a read past the end.
        #[test]
        fn any_bytes_read_or_say_why(bytes in proptest::collection::vec(any::<u8>(), 0..40)) {
            let mut cursor = Cursor::new(&bytes, 0);
            let mut last = 0;
            let _ = cursor.frame(&mut last);
            prop_assert!(cursor.at <= bytes.len());
        }
    }
}
