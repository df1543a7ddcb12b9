//! Frames made from fuzz input, shared by the targets that encode frames (raw log, pit stream).

use aer_host::formats::candump::LoggedFrame;
use embedded_can::{ExtendedId, Id, StandardId};

/// Bytes of input per frame: delta time (2), bus (1), flags (1), id (4), length (1), data (8).
pub const FRAME_INPUT: usize = 17;

/// A frame from `chunk` ([`FRAME_INPUT`] bytes) after `ts_us` (which it advances), on one of
/// `buses` buses.
pub fn frame_from(chunk: &[u8], ts_us: &mut u64, buses: u8) -> LoggedFrame {
    *ts_us += u64::from(u16::from_le_bytes([chunk[0], chunk[1]]));
    let raw_id = u32::from_le_bytes([chunk[4], chunk[5], chunk[6], chunk[7]]);
    let id = if chunk[3] & 1 != 0 {
        Id::Extended(ExtendedId::new(raw_id & 0x1FFF_FFFF).expect("29 bits"))
    } else {
        Id::Standard(StandardId::new((raw_id & 0x7FF) as u16).expect("11 bits"))
    };
    let len = chunk[8] % 9;
    let mut payload = [0u8; 8];
    payload[..usize::from(len)].copy_from_slice(&chunk[9..9 + usize::from(len)]);
    LoggedFrame {
        ts_us: *ts_us,
        bus: chunk[2] % buses,
        id,
        len,
        data: payload,
    }
}
