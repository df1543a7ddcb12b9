//! BLF, the Vector tools' binary log (CANalyzer, CANoe): a 144-byte file header, then log
//! containers of up to 128 KiB of objects each, zlib-compressed. Each frame is a CAN message
//! object (type 1) timed in nanoseconds from the header's start time.
//!
//! The start time is a Windows SYSTEMTIME, to the millisecond, in UTC (the Pi's clock; the
//! Vector tools write local time, which on the car is UTC). It is the earliest frame's
//! millisecond, so each frame's offset is exact.

use super::{FrameWriter, Summary};
use aer_host::formats::raw_format::Frame;
use chrono::{Datelike, Timelike};
use embedded_can::Id;
use flate2::{Compression, write::ZlibEncoder};
use std::io::{self, Seek, SeekFrom, Write};

const FILE_HEADER_BYTES: usize = 144;
/// Object header (signature, sizes, type) and its version-1 part (flags, timestamp).
const OBJECT_HEADER_BYTES: usize = 16;
const OBJECT_HEADER_V1_BYTES: usize = 16;
const CAN_MESSAGE_BYTES: usize = OBJECT_HEADER_BYTES + OBJECT_HEADER_V1_BYTES + 16;
const CONTAINER_HEADER_BYTES: usize = OBJECT_HEADER_BYTES + 16;
/// A container's objects before compression, as the Vector tools write them.
const CONTAINER_BYTES: usize = 128 * 1024;

const CAN_MESSAGE: u32 = 1;
const LOG_CONTAINER: u32 = 10;
const ZLIB_DEFLATE: u16 = 2;
/// Object timestamps in nanoseconds.
const TIME_ONE_NANS: u32 = 2;
const EXTENDED_ID: u32 = 0x8000_0000;
/// "Unknown application": not one of Vector's own.
const APPLICATION_ID: u8 = 0;
/// The binary log format's version, as current writers give it.
const BIN_LOG_VERSION: [u8; 4] = [2, 6, 8, 1];

/// Writes one BLF file; the header is written again by [`FrameWriter::finish`] with the
/// sizes and counts.
pub struct BlfWriter<W: Write + Seek> {
    out: W,
    start_us: u64,
    last_us: u64,
    objects: Vec<u8>,
    count: u32,
    file_bytes: u64,
    uncompressed_bytes: u64,
}

impl<W: Write + Seek> BlfWriter<W> {
    pub fn new(mut out: W, summary: &Summary) -> io::Result<Self> {
        let start_us = summary.first_us - summary.first_us % 1_000;
        out.write_all(&[0; FILE_HEADER_BYTES])?;
        Ok(Self {
            out,
            start_us,
            last_us: summary.last_us,
            objects: Vec::with_capacity(CONTAINER_BYTES),
            count: 0,
            file_bytes: FILE_HEADER_BYTES as u64,
            uncompressed_bytes: FILE_HEADER_BYTES as u64,
        })
    }

    /// Writes the objects gathered so far as one compressed container.
    fn flush_container(&mut self) -> io::Result<()> {
        if self.objects.is_empty() {
            return Ok(());
        }
        let mut encoder = ZlibEncoder::new(Vec::new(), Compression::default());
        encoder.write_all(&self.objects)?;
        let compressed = encoder.finish()?;
        let size = CONTAINER_HEADER_BYTES + compressed.len();
        let mut header = object_header(OBJECT_HEADER_BYTES, size, LOG_CONTAINER);
        header.extend_from_slice(&ZLIB_DEFLATE.to_le_bytes());
        header.extend_from_slice(&[0; 6]);
        header.extend_from_slice(&u32_of(self.objects.len())?.to_le_bytes());
        header.extend_from_slice(&[0; 4]);
        self.out.write_all(&header)?;
        self.out.write_all(&compressed)?;
        // The format pads a container by its size modulo 4 (not to a multiple of 4).
        let padding = size % 4;
        self.out.write_all(&[0; 3][..padding])?;
        self.file_bytes += (size + padding) as u64;
        self.uncompressed_bytes += (CONTAINER_HEADER_BYTES + self.objects.len()) as u64;
        self.objects.clear();
        Ok(())
    }

    fn header(&self) -> io::Result<Vec<u8>> {
        let mut header = Vec::with_capacity(FILE_HEADER_BYTES);
        header.extend_from_slice(b"LOGG");
        header.extend_from_slice(&u32_of(FILE_HEADER_BYTES)?.to_le_bytes());
        header.extend_from_slice(&[APPLICATION_ID, 0, 0, 0]);
        header.extend_from_slice(&BIN_LOG_VERSION);
        header.extend_from_slice(&self.file_bytes.to_le_bytes());
        header.extend_from_slice(&self.uncompressed_bytes.to_le_bytes());
        header.extend_from_slice(&self.count.to_le_bytes());
        header.extend_from_slice(&0u32.to_le_bytes());
        for time in [self.start_us, self.last_us] {
            for field in system_time(time) {
                header.extend_from_slice(&field.to_le_bytes());
            }
        }
        header.resize(FILE_HEADER_BYTES, 0);
        Ok(header)
    }
}

impl<W: Write + Seek> FrameWriter for BlfWriter<W> {
    fn frame(&mut self, frame: &Frame, channel: u16) -> io::Result<()> {
        if self.objects.len() + CAN_MESSAGE_BYTES > CONTAINER_BYTES {
            self.flush_container()?;
        }
        let nanos = frame
            .frame
            .ts_us
            .saturating_sub(self.start_us)
            .saturating_mul(1_000);
        let id = match frame.frame.id {
            Id::Standard(id) => u32::from(id.as_raw()),
            Id::Extended(id) => id.as_raw() | EXTENDED_ID,
        };
        let object = &mut self.objects;
        object.extend_from_slice(&object_header(
            OBJECT_HEADER_BYTES + OBJECT_HEADER_V1_BYTES,
            CAN_MESSAGE_BYTES,
            CAN_MESSAGE,
        ));
        object.extend_from_slice(&TIME_ONE_NANS.to_le_bytes());
        object.extend_from_slice(&[0; 4]); // client index, object version
        object.extend_from_slice(&nanos.to_le_bytes());
        object.extend_from_slice(&channel.to_le_bytes());
        object.push(0); // flags: received
        object.push(frame.frame.len);
        object.extend_from_slice(&id.to_le_bytes());
        object.extend_from_slice(&frame.frame.data);
        self.count = self.count.saturating_add(1);
        Ok(())
    }

    fn finish(mut self: Box<Self>) -> io::Result<()> {
        self.flush_container()?;
        let header = self.header()?;
        self.out.seek(SeekFrom::Start(0))?;
        self.out.write_all(&header)?;
        self.out.flush()
    }
}

/// An object's base header: signature, its header's size, header version 1, the object's
/// size and type.
fn object_header(header_bytes: usize, object_bytes: usize, kind: u32) -> Vec<u8> {
    let mut header = Vec::with_capacity(CAN_MESSAGE_BYTES);
    header.extend_from_slice(b"LOBJ");
    header.extend_from_slice(&(header_bytes as u16).to_le_bytes());
    header.extend_from_slice(&1u16.to_le_bytes());
    header.extend_from_slice(&(object_bytes as u32).to_le_bytes());
    header.extend_from_slice(&kind.to_le_bytes());
    header
}

fn u32_of(n: usize) -> io::Result<u32> {
    u32::try_from(n).map_err(|_| io::Error::other("a BLF container over 4 GiB"))
}

/// A time as a Windows SYSTEMTIME: year, month, day of the week (0 = Sunday), day, hour,
/// minute, second, millisecond.
fn system_time(us: u64) -> [u16; 8] {
    let Some(t) = i64::try_from(us)
        .ok()
        .and_then(chrono::DateTime::from_timestamp_micros)
    else {
        return [0; 8];
    };
    let narrow = |n: u32| u16::try_from(n).unwrap_or(0);
    [
        u16::try_from(t.year()).unwrap_or(0),
        narrow(t.month()),
        narrow(t.weekday().num_days_from_sunday()),
        narrow(t.day()),
        narrow(t.hour()),
        narrow(t.minute()),
        narrow(t.second()),
        narrow(t.timestamp_subsec_millis()),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn system_time_is_the_utc_calendar_to_the_millisecond() {
        // Friday 2026-11-27 14:08:40.123456 UTC.
        assert_eq!(
            system_time(1_795_788_520_123_456),
            [2026, 11, 5, 27, 14, 8, 40, 123]
        );
    }
}
