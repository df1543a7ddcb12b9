//! The pit stream's batch reader (what the dashboard decodes off the radio), two ways:
//! - over arbitrary bytes, with and without the batch header: a batch or a typed error,
//!   never a panic;
//! - over a batch the Pi's encoder built from the input's frames: it comes back exactly.
#![no_main]

use aer_host::formats::candump::LoggedFrame;
use aer_host::formats::pit_stream::{BatchEncoder, Item, MAGIC, VERSION, decode};
use frames::{FRAME_INPUT, frame_from};
use libfuzzer_sys::fuzz_target;
use std::sync::Arc;

#[path = "frames.rs"]
mod frames;

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
        .map(|chunk| frame_from(chunk, &mut ts_us, 2))
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
