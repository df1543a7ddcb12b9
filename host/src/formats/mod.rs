//! The byte formats the car's data travels and rests in: candump text, the raw log's
//! segments, the pit stream's batches, the frame record the last two share, and their compact
//! integers.

pub mod candump;
pub mod frame_record;
pub mod pit_stream;
pub mod raw_format;
pub mod varint;
