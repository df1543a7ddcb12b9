//! The pit stream's batch reader (what the dashboard decodes off the radio), two ways:
//! - over arbitrary bytes, with and without the batch header: a batch or a typed error,
//!   never a panic;
//! - over a batch the Pi's encoder built from the input's frames: it comes back exactly.
#![no_main]

use aer_host::candump::LoggedFrame;
use aer_host::pit_stream::{BatchEncoder, Item, MAGIC, VERSION, decode};
use embedded_can::{ExtendedId, Id, StandardId};
use libfuzzer_sys::fuzz_target;
use std::sync::Arc;

/// Bytes of input per frame: delta time (2), bus (1), flags (1), id (4), length (1), data (8).
const FRAME_INPUT: usize = 17;

fuzz_target!(|data: &[u8]| {
    let _ = decode(data);
    let mut message = MAGIC.to_vec();
    message.push(VERSION);
    message.extend_from_slice(data);
    let _ = decode(&message);
    round_trip(data);
});

fn round_trip(data: &[u8]) {
    let buses: Vec<Arc<str>> = vec!["can0".into(), "can1".into()];
    let mut ts_us = 1_700_000_000_000_000u64;
    let frames: Vec<LoggedFrame> = data
        .chunks_exact(FRAME_INPUT)
        .map(|chunk| frame_from(chunk, &mut ts_us))
        .collect();
    let mut encoder = BatchEncoder::new(7, ts_us, &buses);
    for frame in &frames {
        encoder.frame(frame);
    }
    let batch = decode(&encoder.finish()).expect("an undamaged batch decodes");
    assert_eq!(batch.number, 7);
    assert_eq!(batch.buses, buses);
    let written: Vec<Item> = frames.into_iter().map(Item::Frame).collect();
    assert_eq!(batch.items, written);
}

fn frame_from(chunk: &[u8], ts_us: &mut u64) -> LoggedFrame {
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
        bus: chunk[2] % 2,
        id,
        len,
        data: payload,
    }
}
