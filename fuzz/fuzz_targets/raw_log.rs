//! The raw log reader over arbitrary segment bytes: frames or typed problems, never a panic,
//! and every frame it yields converts to a candump line.
#![no_main]

use aer_host::rawlog::{MAGIC, SegmentReader};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let mut segment = MAGIC.to_vec();
    segment.extend_from_slice(data);
    if let Ok(reader) = SegmentReader::new(&segment) {
        for frame in reader.flatten() {
            let _ = frame.to_candump();
        }
    }
    // Bytes that may not even have the header.
    if let Ok(reader) = SegmentReader::new(data) {
        reader.for_each(drop);
    }
});
