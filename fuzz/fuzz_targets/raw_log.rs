//! The raw log reader, two ways:
//! - over arbitrary bytes (with and without the segment header): frames or typed problems,
//!   never a panic, and every frame it yields converts to a candump line;
//! - over a segment the writer's encoder built from the input's frames, then damaged at one
//!   byte: undamaged, the reader gives back exactly the frames written; damaged, it still gives
//!   back every frame of every block the damage did not touch, in order.
#![no_main]

use aer_host::formats::candump::LoggedFrame;
use aer_host::formats::raw_format::{BlockEncoder, MAGIC, SegmentReader};
use frames::{FRAME_INPUT, frame_from};
use libfuzzer_sys::fuzz_target;
use std::sync::Arc;

#[path = "frames.rs"]
mod frames;

fuzz_target!(|data: &[u8]| {
    let mut segment = MAGIC.to_vec();
    segment.extend_from_slice(data);
    if let Ok(reader) = SegmentReader::new(&segment) {
        for frame in reader.flatten() {
            let _ = frame.to_candump();
        }
    }
    if let Ok(reader) = SegmentReader::new(data) {
        reader.for_each(drop);
    }
    round_trip(data);
});

fn round_trip(data: &[u8]) {
    let Some((&damage, data)) = data.split_first() else {
        return;
    };
    let buses: Vec<Arc<str>> = vec!["can0".into(), "can1".into(), "isotp".into()];
    let mut blocks: Vec<(std::ops::Range<usize>, Vec<LoggedFrame>)> = Vec::new();
    let mut segment = MAGIC.to_vec();
    let mut ts_us = 1_700_000_000_000_000u64;
    let mut encoder: Option<(BlockEncoder, Vec<LoggedFrame>)> = None;
    for chunk in data.chunks_exact(FRAME_INPUT) {
        let frame = frame_from(chunk, &mut ts_us, 3);
        let (block, frames) =
            encoder.get_or_insert_with(|| (BlockEncoder::new(frame.ts_us, &buses), Vec::new()));
        block.push(&frame);
        frames.push(frame);
        // The flags byte's top bit ends the block, so inputs choose the block layout.
        if chunk[3] & 0x80 != 0 {
            close(&mut encoder, &mut segment, &mut blocks);
        }
    }
    close(&mut encoder, &mut segment, &mut blocks);

    let written: Vec<LoggedFrame> = blocks.iter().flat_map(|(_, f)| f.clone()).collect();
    let read: Vec<LoggedFrame> = SegmentReader::new(&segment)
        .expect("header")
        .map(|frame| frame.expect("an undamaged segment reads without problems").frame)
        .collect();
    assert_eq!(read, written);

    if segment.len() <= MAGIC.len() {
        return;
    }
    // Damage one byte after the header (at a place and with a value the input chooses).
    let at = MAGIC.len() + (usize::from(damage) * 7919) % (segment.len() - MAGIC.len());
    segment[at] ^= damage | 1;
    let survivors: Vec<LoggedFrame> = blocks
        .iter()
        .filter(|(range, _)| !range.contains(&at))
        .flat_map(|(_, f)| f.clone())
        .collect();
    let read: Vec<LoggedFrame> = SegmentReader::new(&segment)
        .expect("header")
        .flatten()
        .map(|frame| frame.frame)
        .collect();
    let mut rest = read.iter();
    for frame in &survivors {
        assert!(
            rest.any(|r| r == frame),
            "a frame of an undamaged block was lost: {frame:?}"
        );
    }
}

fn close(
    encoder: &mut Option<(BlockEncoder, Vec<LoggedFrame>)>,
    segment: &mut Vec<u8>,
    blocks: &mut Vec<(std::ops::Range<usize>, Vec<LoggedFrame>)>,
) {
    if let Some((block, frames)) = encoder.take() {
        let start = segment.len();
        segment.extend_from_slice(&block.finish());
        blocks.push((start..segment.len(), frames));
    }
}
