//! The frame record the raw log and the pit stream share (`aer_host::formats::frame_record`), two ways:
//! - over arbitrary bytes: frames or a reason, never a panic, never a read past the end;
//! - over records written from the input's frames: each comes back exactly, in order.
#![no_main]

use aer_host::formats::frame_record::{self, Cursor};
use frames::{FRAME_INPUT, frame_from};
use libfuzzer_sys::fuzz_target;

#[path = "frames.rs"]
mod frames;

fuzz_target!(|data: &[u8]| {
    let mut cursor = Cursor::new(data, 0);
    let mut last_us = 0;
    while !cursor.is_done() {
        if cursor.frame(&mut last_us).is_err() {
            break;
        }
        assert!(cursor.at <= data.len());
    }

    let mut ts_us = 1_700_000_000_000_000u64;
    let frames: Vec<_> = data
        .chunks_exact(FRAME_INPUT)
        .map(|chunk| frame_from(chunk, &mut ts_us, 4))
        .collect();
    let mut out = Vec::new();
    let mut last_us = 1_700_000_000_000_000u64;
    for frame in &frames {
        frame_record::put(&mut out, &mut last_us, frame);
    }
    let mut cursor = Cursor::new(&out, 0);
    let mut last_us = 1_700_000_000_000_000u64;
    for frame in &frames {
        assert_eq!(cursor.frame(&mut last_us), Ok(*frame));
    }
    assert!(cursor.is_done());
});
