//! The raw log's format: every frame of every bus, as received, before anything decodes it,
//! in segment files of checksummed, zstd-compressed blocks. About 14 bytes a frame before
//! compression (candump text: 40), about 3 after it at the car's traffic, and it converts to
//! candump `-l` text without loss ([`Frame::to_candump`]).
//!
//! A segment is the 8-byte header `AERRAW` + version (u16 LE), then blocks:
//!
//! ```text
//! block:   sync "AERB" | stored length u32 LE | CRC-32 of the stored bytes u32 LE | stored
//! stored:  codec u8 (0 plain, 1 zstd) | the payload in that codec
//! payload: first timestamp (us since the epoch) u64 LE, then records:
//!   0x01 bus:   index u8, name length u8, name (UTF-8)
//!   0x02 frame: time since the previous record (zigzag LEB128, us), bus u8,
//!               flags u8 (bit 0: extended id), id (LEB128), length u8 (0-8), data
//!   0x03 time:  time since the previous record (zigzag LEB128, us), where blocks were
//!               joined ([`Joiner`]); the buses' names follow if they changed
//! ```
//!
//! Every block names the buses it uses, so each one decodes on its own. A block cut short by a
//! crash or damaged on disk fails its length or checksum and is skipped: the reader finds the
//! next block by its sync word, so one bad block loses only itself, and says so. The header's
//! version is 2; a segment of another version is refused.

use crate::formats::candump::LoggedFrame;
use crate::formats::frame_record::{self, Cursor, Why};
use std::sync::Arc;
use thiserror::Error;

/// The first bytes of every segment.
pub const MAGIC: [u8; 8] = *b"AERRAW\x02\x00";
/// The bytes every block starts with.
pub const SYNC: [u8; 4] = *b"AERB";
/// The most a block may store; anything longer is damage.
pub const MAX_BLOCK: usize = 1 << 20;
/// The largest payload a block may decompress to; anything longer is damage.
pub const MAX_PAYLOAD: usize = 4 << 20;
/// The zstd level blocks are compressed at: level 3 keeps the raw log at about a fifth of its
/// plain size for well under a millisecond per second of the car's traffic on a Pi 5; higher
/// levels gain a few percent for several times the CPU.
const ZSTD_LEVEL: i32 = 3;
const CODEC_PLAIN: u8 = 0;
const CODEC_ZSTD: u8 = 1;
/// Block header: sync, length, checksum.
const BLOCK_HEADER: usize = 12;

const TAG_BUS: u8 = 0x01;
const TAG_FRAME: u8 = 0x02;
const TAG_TIME: u8 = 0x03;

/// What is wrong with a segment or a block.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum RawError {
    #[error("not a raw log segment (no AERRAW header)")]
    NotRawLog,
    #[error("raw log version {0}: this build reads version 2")]
    Version(u16),
    #[error("block at byte {offset} is cut short (a crash while writing)")]
    Truncated { offset: usize },
    #[error("block at byte {offset} is damaged: {why}")]
    Damaged { offset: usize, why: &'static str },
    #[error("{skipped} bytes before byte {offset} are not a block")]
    Garbage { offset: usize, skipped: usize },
}

/// One frame as the raw log holds it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Frame {
    /// The interface the frame came from (`can0`).
    pub interface: Arc<str>,
    /// The frame; its `bus` is the index the writer used for `interface`.
    pub frame: LoggedFrame,
}

impl Frame {
    /// The `candump -l` line for the frame: the same timestamp, interface, id and data.
    pub fn to_candump(&self) -> String {
        self.frame.to_line(&self.interface)
    }
}

/// Builds a block's payload. Start one with [`BlockEncoder::new`], add the buses' names and
/// frames, then [`BlockEncoder::finish`] it into the bytes to append to a segment.
#[derive(Debug)]
pub struct BlockEncoder {
    payload: Vec<u8>,
    first_us: u64,
    last_us: u64,
    frames: u64,
    /// The buses the payload names, and where its frames start (after their names).
    buses: Vec<Arc<str>>,
    frames_at: usize,
}

impl BlockEncoder {
    /// A block whose timestamps count from `first_us`; `buses` names each bus index used.
    pub fn new(first_us: u64, buses: &[Arc<str>]) -> Self {
        let mut payload = Vec::with_capacity(32 * 1024);
        payload.extend_from_slice(&first_us.to_le_bytes());
        for (index, name) in buses.iter().enumerate() {
            let (Ok(index), Ok(len)) = (u8::try_from(index), u8::try_from(name.len())) else {
                continue;
            };
            payload.extend_from_slice(&[TAG_BUS, index, len]);
            payload.extend_from_slice(name.as_bytes());
        }
        Self {
            frames_at: payload.len(),
            payload,
            first_us,
            last_us: first_us,
            frames: 0,
            buses: buses.to_vec(),
        }
    }

    /// Appends a frame.
    pub fn push(&mut self, frame: &LoggedFrame) {
        self.payload.push(TAG_FRAME);
        frame_record::put(&mut self.payload, &mut self.last_us, frame);
        self.frames += 1;
    }

    /// Frames in the block so far.
    pub fn frames(&self) -> u64 {
        self.frames
    }

    /// Bytes of payload so far.
    pub fn len(&self) -> usize {
        self.payload.len()
    }

    /// True before the first frame.
    pub fn is_empty(&self) -> bool {
        self.frames == 0
    }

    /// The block as it goes to disk ([`seal`]).
    pub fn finish(self) -> Vec<u8> {
        seal(&self.payload)
    }
}

/// Blocks joined into one payload, so that many small blocks are compressed as one:
/// compression needs a few kilobytes of context to pay, and ingest hands over a block per
/// batch it reads. Each joined block's frames keep their timestamps (the first frame's time
/// since the previous block's last, or a time record) and its buses their names (named again
/// only when they changed).
#[derive(Debug, Default)]
pub struct Joiner {
    payload: Vec<u8>,
    last_us: u64,
    frames: u64,
    buses: Vec<Arc<str>>,
}

impl Joiner {
    /// Appends `block`'s frames.
    pub fn push(&mut self, block: &BlockEncoder) {
        let first_frame = block.payload.get(block.frames_at..block.frames_at + 2);
        if self.payload.is_empty() {
            self.payload.extend_from_slice(&block.payload);
        } else if block.buses == self.buses && first_frame == Some(&[TAG_FRAME, 0]) {
            // The block's first frame is at its start time: its time since the previous
            // frame takes the place of that zero, as if one encoder had written both.
            self.payload.push(TAG_FRAME);
            let mut last_us = self.last_us;
            frame_record::put_time(&mut self.payload, &mut last_us, block.first_us);
            self.payload
                .extend_from_slice(block.payload.get(block.frames_at + 2..).unwrap_or_default());
        } else {
            self.payload.push(TAG_TIME);
            let mut last_us = self.last_us;
            frame_record::put_time(&mut self.payload, &mut last_us, block.first_us);
            let from = if block.buses == self.buses {
                block.frames_at
            } else {
                8
            };
            self.payload
                .extend_from_slice(block.payload.get(from..).unwrap_or_default());
        }
        if block.buses != self.buses {
            self.buses.clone_from(&block.buses);
        }
        self.last_us = block.last_us;
        self.frames += block.frames;
    }

    /// Bytes of payload so far.
    pub fn len(&self) -> usize {
        self.payload.len()
    }

    /// True before the first block.
    pub fn is_empty(&self) -> bool {
        self.payload.is_empty()
    }

    /// Frames joined so far.
    pub fn frames(&self) -> u64 {
        self.frames
    }

    /// The joined blocks as one block on disk ([`seal`]).
    pub fn finish(self) -> Vec<u8> {
        seal(&self.payload)
    }
}

/// A payload as a block on disk: sync word, length, checksum, the payload compressed with
/// zstd (stored plain in the unlikely case zstd fails or cannot make it smaller).
pub fn seal(payload: &[u8]) -> Vec<u8> {
    let compressed = zstd::bulk::compress(payload, ZSTD_LEVEL)
        .ok()
        .filter(|c| c.len() < payload.len());
    let (codec, stored) = match &compressed {
        Some(compressed) => (CODEC_ZSTD, compressed.as_slice()),
        None => (CODEC_PLAIN, payload),
    };
    let mut body = Vec::with_capacity(1 + stored.len());
    body.push(codec);
    body.extend_from_slice(stored);
    let mut block = Vec::with_capacity(BLOCK_HEADER + body.len());
    block.extend_from_slice(&SYNC);
    block.extend_from_slice(&(body.len() as u32).to_le_bytes());
    block.extend_from_slice(&crc32fast::hash(&body).to_le_bytes());
    block.extend_from_slice(&body);
    block
}

/// Reads the frames of a segment in order. Problems (a damaged or cut-short block, bytes that
/// are not a block) come out in place of the frames they cost, and reading goes on at the next
/// good block.
pub struct SegmentReader<'a> {
    data: &'a [u8],
    pos: usize,
    block: Option<BlockReader>,
}

impl<'a> SegmentReader<'a> {
    /// A reader over a whole segment's bytes; fails unless they start with the header.
    pub fn new(data: &'a [u8]) -> Result<Self, RawError> {
        let header = data.get(..MAGIC.len()).ok_or(RawError::NotRawLog)?;
        if header.get(..6) != MAGIC.get(..6) {
            return Err(RawError::NotRawLog);
        }
        let version = header
            .get(6..8)
            .map_or(0, |v| u16::from_le_bytes([v[0], v[1]]));
        if version != 2 {
            return Err(RawError::Version(version));
        }
        Ok(Self {
            data,
            pos: MAGIC.len(),
            block: None,
        })
    }

    /// True when `data` starts like a segment (so a log file can be told from candump text).
    pub fn is_segment(data: &[u8]) -> bool {
        data.get(..6) == MAGIC.get(..6)
    }

    /// The next block, or the problem found in its place.
    fn next_block(&mut self) -> Option<Result<BlockReader, RawError>> {
        let rest = self.data.get(self.pos..)?;
        if rest.is_empty() {
            return None;
        }
        if rest.get(..SYNC.len()) != Some(&SYNC[..]) {
            return Some(Err(self.resync(self.pos)));
        }
        let offset = self.pos;
        let Some(header) = rest.get(..BLOCK_HEADER) else {
            self.pos = self.data.len();
            return Some(Err(RawError::Truncated { offset }));
        };
        let word = |at: usize| {
            let mut bytes = [0u8; 4];
            if let Some(field) = header.get(at..at + 4) {
                bytes.copy_from_slice(field);
            }
            u32::from_le_bytes(bytes)
        };
        let (len, crc) = (word(4) as usize, word(8));
        if len > MAX_BLOCK {
            self.resync(offset + 1);
            return Some(Err(RawError::Damaged {
                offset,
                why: "declared length too large",
            }));
        }
        let Some(payload) = rest.get(BLOCK_HEADER..BLOCK_HEADER + len) else {
            // Cut short, unless another block follows: then the length itself is damaged.
            self.resync(offset + 1);
            return Some(Err(if self.pos < self.data.len() {
                RawError::Damaged {
                    offset,
                    why: "declared length past the next block",
                }
            } else {
                RawError::Truncated { offset }
            }));
        };
        if crc32fast::hash(payload) != crc {
            self.resync(offset + 1);
            return Some(Err(RawError::Damaged {
                offset,
                why: "checksum mismatch",
            }));
        }
        self.pos = offset + BLOCK_HEADER + len;
        Some(
            self.decode(payload, offset)
                .and_then(|p| BlockReader::new(p, offset)),
        )
    }

    /// A block's stored bytes as its payload.
    fn decode(&self, stored: &[u8], offset: usize) -> Result<Vec<u8>, RawError> {
        let damaged = |why| RawError::Damaged { offset, why };
        match stored.split_first() {
            Some((&CODEC_PLAIN, payload)) => Ok(payload.to_vec()),
            Some((&CODEC_ZSTD, compressed)) => zstd::bulk::decompress(compressed, MAX_PAYLOAD)
                .map_err(|_| damaged("does not decompress")),
            Some(_) => Err(damaged("unknown codec")),
            None => Err(damaged("empty block")),
        }
    }

    /// Moves to the next sync word at or after `from`; returns what was skipped.
    fn resync(&mut self, from: usize) -> RawError {
        let start = self.pos;
        let found = self
            .data
            .get(from..)
            .and_then(|rest| rest.windows(SYNC.len()).position(|w| w == SYNC));
        self.pos = found.map_or(self.data.len(), |at| from + at);
        RawError::Garbage {
            offset: self.pos,
            skipped: self.pos - start,
        }
    }
}

impl Iterator for SegmentReader<'_> {
    type Item = Result<Frame, RawError>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            if let Some(block) = &mut self.block {
                match block.next() {
                    Some(Ok(frame)) => return Some(Ok(frame)),
                    Some(Err(error)) => {
                        // The rest of a block that passed its checksum but does not parse is
                        // not trusted.
                        self.block = None;
                        return Some(Err(error));
                    }
                    None => self.block = None,
                }
            }
            match self.next_block()? {
                Ok(block) => self.block = Some(block),
                Err(error) => return Some(Err(error)),
            }
        }
    }
}

/// The records of one block.
struct BlockReader {
    payload: Vec<u8>,
    offset: usize,
    pos: usize,
    last_us: u64,
    buses: Vec<Option<Arc<str>>>,
}

impl BlockReader {
    fn new(payload: Vec<u8>, offset: usize) -> Result<Self, RawError> {
        let first = payload.get(..8).ok_or(RawError::Damaged {
            offset,
            why: "block shorter than its timestamp",
        })?;
        let mut bytes = [0u8; 8];
        bytes.copy_from_slice(first);
        Ok(Self {
            payload,
            offset,
            pos: 8,
            last_us: u64::from_le_bytes(bytes),
            buses: Vec::new(),
        })
    }

    fn damaged(&self, why: &'static str) -> RawError {
        RawError::Damaged {
            offset: self.offset,
            why,
        }
    }

    /// Runs `read` on a cursor at the current position; damage names this block.
    fn read<T>(
        &mut self,
        read: impl FnOnce(&mut Cursor<'_>, &mut u64) -> Result<T, Why>,
    ) -> Result<T, RawError> {
        let mut cursor = Cursor::new(&self.payload, self.pos);
        let result = read(&mut cursor, &mut self.last_us);
        self.pos = cursor.at;
        result.map_err(|why| self.damaged(why))
    }

    fn time(&mut self) -> Result<(), RawError> {
        self.read(|cursor, last_us| cursor.time(last_us).map(|_| ()))
    }

    fn bus(&mut self) -> Result<(), RawError> {
        let (index, name) = self.read(|cursor, _| {
            let index = usize::from(cursor.byte()?);
            let len = usize::from(cursor.byte()?);
            let name = std::str::from_utf8(cursor.bytes(len)?).map_err(|_| "bus name not UTF-8")?;
            Ok((index, Arc::<str>::from(name)))
        })?;
        if self.buses.len() <= index {
            self.buses.resize(index + 1, None);
        }
        if let Some(slot) = self.buses.get_mut(index) {
            *slot = Some(name);
        }
        Ok(())
    }

    fn frame(&mut self) -> Result<Frame, RawError> {
        let frame = self.read(|cursor, last_us| cursor.frame(last_us))?;
        let interface = self
            .buses
            .get(usize::from(frame.bus))
            .cloned()
            .flatten()
            .ok_or(self.damaged("frame of an unnamed bus"))?;
        Ok(Frame { interface, frame })
    }
}

impl Iterator for BlockReader {
    type Item = Result<Frame, RawError>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            let tag = *self.payload.get(self.pos)?;
            self.pos += 1;
            match tag {
                TAG_BUS => {
                    if let Err(error) = self.bus() {
                        return Some(Err(error));
                    }
                }
                TAG_FRAME => return Some(self.frame()),
                TAG_TIME => {
                    if let Err(error) = self.time() {
                        return Some(Err(error));
                    }
                }
                _ => return Some(Err(self.damaged("unknown record"))),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use embedded_can::{ExtendedId, Id, StandardId};

    fn frame(ts_us: u64, bus: u8, id: Id, data: &[u8]) -> LoggedFrame {
        LoggedFrame::new(ts_us, bus, id, data).unwrap()
    }

    fn segment(blocks: &[Vec<u8>]) -> Vec<u8> {
        let mut out = MAGIC.to_vec();
        for block in blocks {
            out.extend_from_slice(block);
        }
        out
    }

    fn sample_block(first: u64) -> (Vec<u8>, Vec<LoggedFrame>) {
        let (encoder, frames) = sample_encoder(first);
        (encoder.finish(), frames)
    }

    fn sample_encoder(first: u64) -> (BlockEncoder, Vec<LoggedFrame>) {
        let buses: Vec<Arc<str>> = vec!["can0".into(), "can1".into()];
        let frames = vec![
            frame(
                first,
                0,
                Id::Standard(StandardId::new(0x666).unwrap()),
                &[0x10, 0x48],
            ),
            frame(
                first + 250,
                1,
                Id::Extended(ExtendedId::new(0x18FF_01F4).unwrap()),
                &[],
            ),
            // Out of order by a little: deltas are signed.
            frame(
                first + 100,
                0,
                Id::Standard(StandardId::new(0x7FF).unwrap()),
                &[1; 8],
            ),
        ];
        let mut encoder = BlockEncoder::new(first, &buses);
        for f in &frames {
            encoder.push(f);
        }
        (encoder, frames)
    }

    #[test]
    fn frames_come_back_exactly_and_convert_to_candump() {
        let (block, frames) = sample_block(1_700_000_000_000_123);
        let data = segment(&[block]);
        let read: Vec<Frame> = SegmentReader::new(&data)
            .unwrap()
            .map(Result::unwrap)
            .collect();
        assert_eq!(read.iter().map(|f| f.frame).collect::<Vec<_>>(), frames);
        assert_eq!(
            read[0].to_candump(),
            "(1700000000.000123) can0 666#1048",
            "the line candump -l writes"
        );
        assert_eq!(&*read[1].interface, "can1");
        // Header 8, block header 12, codec 1 (too small to compress: plain), first
        // timestamp 8, two bus names 14, then the three frames: 6-11 bytes each beside their
        // 10 data bytes (candump text: 105 bytes).
        assert_eq!(data.len(), 8 + 12 + 1 + 8 + 14 + 26 + 10);
    }

    #[test]
    fn joined_payloads_compress_and_keep_every_timestamp_and_bus() {
        let mut joined = Joiner::default();
        let mut expected = Vec::new();
        let mut plain = 0;
        for block in 0..100u64 {
            let (encoder, frames) = sample_encoder(1_700_000_000_000_000 + block * 10_000);
            plain += encoder.len();
            joined.push(&encoder);
            expected.extend(frames);
        }
        // The buses named again when they change.
        let renamed: Vec<Arc<str>> = vec!["vcan0".into()];
        let mut encoder = BlockEncoder::new(5, &renamed);
        let frame = frame(5, 0, Id::Standard(StandardId::ZERO), &[7]);
        encoder.push(&frame);
        joined.push(&encoder);
        expected.push(frame);
        assert_eq!(joined.frames(), 301);
        let block = joined.finish();
        assert!(
            block.len() * 8 < plain,
            "{plain} bytes of blocks compressed to {}",
            block.len()
        );
        let read: Vec<LoggedFrame> = SegmentReader::new(&segment(&[block]))
            .unwrap()
            .map(|r| r.unwrap().frame)
            .collect();
        assert_eq!(read, expected);
    }

    #[test]
    fn a_block_that_does_not_decompress_is_damage() {
        let mut data = segment(&[]);
        let body = [CODEC_ZSTD, 1, 2, 3, 4];
        data.extend_from_slice(&SYNC);
        data.extend_from_slice(&(body.len() as u32).to_le_bytes());
        data.extend_from_slice(&crc32fast::hash(&body).to_le_bytes());
        data.extend_from_slice(&body);
        let (next, _) = sample_block(9_000);
        data.extend_from_slice(&next);
        let results: Vec<_> = SegmentReader::new(&data).unwrap().collect();
        assert!(matches!(
            results.first(),
            Some(Err(RawError::Damaged {
                why: "does not decompress",
                ..
            }))
        ));
        assert_eq!(results.iter().filter(|r| r.is_ok()).count(), 3);
    }

    #[test]
    fn a_cut_short_tail_loses_only_the_last_block() {
        let (first, frames) = sample_block(1_000);
        let (second, _) = sample_block(2_000);
        let mut data = segment(&[first, second]);
        data.truncate(data.len() - 5);
        let results: Vec<_> = SegmentReader::new(&data).unwrap().collect();
        let good: Vec<LoggedFrame> = results
            .iter()
            .filter_map(|r| r.as_ref().ok().map(|f| f.frame))
            .collect();
        assert_eq!(good, frames);
        assert!(matches!(
            results.last(),
            Some(Err(RawError::Truncated { .. }))
        ));
    }

    #[test]
    fn a_damaged_block_is_skipped_and_reading_goes_on() {
        let (first, _) = sample_block(1_000);
        let (second, frames) = sample_block(2_000);
        let damaged_at = MAGIC.len() + 20;
        let mut data = segment(&[first, second]);
        data[damaged_at] ^= 0xFF;
        let results: Vec<_> = SegmentReader::new(&data).unwrap().collect();
        assert!(matches!(
            results.first(),
            Some(Err(RawError::Damaged { .. }))
        ));
        let good: Vec<LoggedFrame> = results
            .iter()
            .filter_map(|r| r.as_ref().ok().map(|f| f.frame))
            .collect();
        assert_eq!(good, frames, "the second block still reads");
    }

    #[test]
    fn other_files_are_refused() {
        assert_eq!(
            SegmentReader::new(b"(1.000000) can0 123#").err(),
            Some(RawError::NotRawLog)
        );
        assert!(!SegmentReader::is_segment(b"(1.0) can0 1#"));
        let mut newer = MAGIC.to_vec();
        newer[6] = 9;
        assert_eq!(SegmentReader::new(&newer).err(), Some(RawError::Version(9)));
    }
}

#[cfg(test)]
mod properties {
    use super::*;
    use embedded_can::{ExtendedId, Id, StandardId};
    use proptest::prelude::*;

    fn any_frame() -> impl Strategy<Value = LoggedFrame> {
        (
            any::<u64>(),
            0u8..3,
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
        /// Any frames, split into blocks anywhere, sealed one by one or joined into one
        /// block, read back exactly and in order.
        #[test]
        fn frames_survive_any_blocking(
            frames in proptest::collection::vec(any_frame(), 0..200),
            cuts in proptest::collection::vec(any::<usize>(), 0..5),
            joined in any::<bool>(),
        ) {
            let buses: Vec<Arc<str>> = vec!["can0".into(), "can1".into(), "vcan9".into()];
            let mut cuts: Vec<usize> = cuts.into_iter().map(|c| c % (frames.len() + 1)).collect();
            cuts.sort_unstable();
            let mut data = MAGIC.to_vec();
            let mut all = Joiner::default();
            let mut start = 0;
            for end in cuts.into_iter().chain([frames.len()]) {
                let Some(chunk) = frames.get(start..end) else { continue };
                if let Some(first) = chunk.first() {
                    let mut block = BlockEncoder::new(first.ts_us, &buses);
                    for f in chunk {
                        block.push(f);
                    }
                    if joined {
                        all.push(&block);
                    } else {
                        data.extend_from_slice(&block.finish());
                    }
                }
                start = end;
            }
            if !all.is_empty() {
                data.extend_from_slice(&all.finish());
            }
            let read: Vec<LoggedFrame> = SegmentReader::new(&data)
                .expect("header")
                .map(|r| r.map(|f| f.frame))
                .collect::<Result<_, _>>()
                .expect("no damage");
            prop_assert_eq!(read, frames);
        }

        /// Any bytes after the header give frames or typed problems, never a panic, and end.
        #[test]
        fn damage_is_reported_not_fatal(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
            let mut data = MAGIC.to_vec();
            data.extend_from_slice(&bytes);
            let reader = SegmentReader::new(&data).expect("header");
            prop_assert!(reader.count() <= data.len());
        }
    }
}
