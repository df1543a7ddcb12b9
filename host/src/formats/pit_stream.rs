//! The pit stream: what the Pi's ingest takes in (every CAN frame as received, and every
//! telemetry packet the kernel's ISO-TP reassembled), in batches of a short window,
//! zstd-compressed, one MQTT message per batch. The pit decodes it with the same ingest and
//! generated decoders as the Pi ([`crate::decode::Ingest`]), so it sees what the Pi sees at a
//! few bytes a frame instead of a JSON document per message: the stream fits a long-range
//! radio. Each batch is numbered, so a receiver knows what it missed.
//!
//! ```text
//! message: "AERP" | version u8 (1) | batch number u32 LE | first timestamp u64 LE (us since
//!          the epoch) | payload length u32 LE | the payload, zstd-compressed
//! payload: bus count u8, then per bus: name length u8, name (UTF-8, the index is the order)
//!          then records:
//!   0x02 frame:  the frame record the raw log carries too ([`crate::formats::frame_record`]): time
//!                since the previous record (zigzag LEB128, us), bus u8, flags u8 (bit 0:
//!                extended id), id (LEB128), length u8 (0-8), data
//!   0x04 packet: time since the previous record (zigzag LEB128, us), bus u8,
//!                length (LEB128), the packet
//! ```

use crate::formats::candump::LoggedFrame;
use crate::formats::frame_record::{self, Cursor};
use crate::formats::varint::put_varint;
use std::sync::Arc;
use thiserror::Error;

/// What the stream's topic root adds to the topic root: `aer` -> `aer-pit`. The stream is
/// binary, so it stays out of `aer/#`, which Grafana, Node-RED and `mosquitto_sub -v` read as
/// JSON text.
pub const ROOT_SUFFIX: &str = "-pit";

/// The pits' topics' root for the car whose topics are below `car_prefix` (`aer/car1` ->
/// `aer-pit/car1`): the stream, the history, the lap marks.
pub fn pit_root(car_prefix: &str) -> String {
    match car_prefix.rsplit_once('/') {
        Some((root, car)) => format!("{root}{ROOT_SUFFIX}/{car}"),
        None => format!("{car_prefix}{ROOT_SUFFIX}"),
    }
}

/// The stream's topic for the car whose topics are below `car_prefix` (`aer/car1` ->
/// `aer-pit/car1/stream`).
pub fn topic(car_prefix: &str) -> String {
    format!("{}/stream", pit_root(car_prefix))
}
/// Uncompressed payload at which a batch goes out before its window ends. With one more
/// record (at most a [`MAX_PACKET`] packet) and even incompressible, the message stays under
/// the broker's 20 KiB limit.
pub const MAX_BATCH_PAYLOAD: usize = 12 * 1024;
#[cfg(test)]
mod tests {
    #[test]
    fn the_stream_sits_beside_the_cars_json_topics() {
        assert_eq!(super::topic("aer/car1"), "aer-pit/car1/stream");
        assert_eq!(super::topic("team/aer/car7"), "team/aer-pit/car7/stream");
        assert_eq!(super::topic("car1"), "car1-pit/stream");
    }
}

/// The first bytes of every batch.
pub const MAGIC: [u8; 4] = *b"AERP";
/// The format this build writes and reads.
pub const VERSION: u8 = 1;
/// Bytes before the compressed payload.
pub const HEADER_LEN: usize = 4 + 1 + 4 + 8 + 4;
/// The largest payload a batch may decompress to: a second of a saturated 1 Mbit/s bus is
/// about 8,000 frames of at most 20 bytes; anything longer is not a batch of ours.
pub const MAX_PAYLOAD: usize = 1 << 20;
/// The largest packet a record may carry (the ISO-TP maximum).
pub const MAX_PACKET: usize = 4095;
/// The zstd level: small batches gain little from more.
const ZSTD_LEVEL: i32 = 3;

const TAG_FRAME: u8 = 0x02;
const TAG_PACKET: u8 = 0x04;

/// Why a message is not a batch this build can read.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum StreamError {
    #[error("not a pit stream batch (no AERP header)")]
    NotABatch,
    #[error("pit stream version {0} is newer than this build reads")]
    Version(u8),
    #[error("the batch's payload does not decompress: {0}")]
    Compression(String),
    #[error("the batch says {said} payload bytes, it holds {held}")]
    Length { said: usize, held: usize },
    #[error("the batch is damaged at payload byte {offset}: {why}")]
    Damaged { offset: usize, why: &'static str },
}

/// One thing ingest took in.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Item {
    /// A CAN frame as received.
    Frame(LoggedFrame),
    /// A telemetry packet the kernel reassembled.
    Packet {
        ts_us: u64,
        bus: u8,
        packet: Vec<u8>,
    },
}

impl Item {
    /// When it arrived (us since the epoch).
    pub fn ts_us(&self) -> u64 {
        match self {
            Self::Frame(frame) => frame.ts_us,
            Self::Packet { ts_us, .. } => *ts_us,
        }
    }
}

/// A batch as read back.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Batch {
    /// Its number: one more than the previous batch of the same stream.
    pub number: u32,
    /// The buses' names by index.
    pub buses: Vec<Arc<str>>,
    /// Its frames and packets in arrival order.
    pub items: Vec<Item>,
}

/// Builds one batch.
#[derive(Debug)]
pub struct BatchEncoder {
    number: u32,
    first_us: u64,
    last_us: u64,
    payload: Vec<u8>,
    items: usize,
}

impl BatchEncoder {
    /// Batch `number`, its timestamps counting from `first_us`, naming `buses` by index.
    pub fn new(number: u32, first_us: u64, buses: &[Arc<str>]) -> Self {
        let mut payload = Vec::with_capacity(8 * 1024);
        let named: Vec<&Arc<str>> = buses.iter().take(usize::from(u8::MAX)).collect();
        payload.push(named.len() as u8);
        for name in named {
            let bytes = name.as_bytes();
            let len = bytes.len().min(usize::from(u8::MAX));
            payload.push(len as u8);
            payload.extend_from_slice(bytes.get(..len).unwrap_or_default());
        }
        Self {
            number,
            first_us,
            last_us: first_us,
            payload,
            items: 0,
        }
    }

    /// Appends a frame.
    pub fn frame(&mut self, frame: &LoggedFrame) {
        self.payload.push(TAG_FRAME);
        frame_record::put(&mut self.payload, &mut self.last_us, frame);
        self.items += 1;
    }

    /// Appends a packet (longer than [`MAX_PACKET`]: cut there, as no receiver would take it).
    pub fn packet(&mut self, ts_us: u64, bus: u8, packet: &[u8]) {
        let packet = packet
            .get(..packet.len().min(MAX_PACKET))
            .unwrap_or_default();
        self.payload.push(TAG_PACKET);
        frame_record::put_time(&mut self.payload, &mut self.last_us, ts_us);
        self.payload.push(bus);
        put_varint(&mut self.payload, packet.len() as u64);
        self.payload.extend_from_slice(packet);
        self.items += 1;
    }

    /// Frames and packets so far.
    pub fn items(&self) -> usize {
        self.items
    }

    /// The first timestamp.
    pub fn first_us(&self) -> u64 {
        self.first_us
    }

    /// The newest record's timestamp (the first, before any).
    pub fn last_us(&self) -> u64 {
        self.last_us
    }

    /// Its number.
    pub fn number(&self) -> u32 {
        self.number
    }

    /// Uncompressed payload bytes so far.
    pub fn payload_len(&self) -> usize {
        self.payload.len()
    }

    /// The message to publish.
    pub fn finish(self) -> Vec<u8> {
        let compressed = zstd::bulk::compress(&self.payload, ZSTD_LEVEL).unwrap_or_default();
        let mut message = Vec::with_capacity(HEADER_LEN + compressed.len());
        message.extend_from_slice(&MAGIC);
        message.push(VERSION);
        message.extend_from_slice(&self.number.to_le_bytes());
        message.extend_from_slice(&self.first_us.to_le_bytes());
        message.extend_from_slice(&(self.payload.len() as u32).to_le_bytes());
        message.extend_from_slice(&compressed);
        message
    }
}

/// The payload's buses and records.
fn records(
    cursor: &mut Cursor<'_>,
    first_us: u64,
) -> Result<(Vec<Arc<str>>, Vec<Item>), frame_record::Why> {
    let count = cursor.byte()?;
    let mut buses = Vec::with_capacity(usize::from(count));
    for _ in 0..count {
        let len = cursor.byte()?;
        let name = std::str::from_utf8(cursor.bytes(usize::from(len))?)
            .map_err(|_| "bus name not UTF-8")?;
        buses.push(Arc::from(name));
    }
    let mut items = Vec::new();
    let mut last_us = first_us;
    while !cursor.is_done() {
        match cursor.byte()? {
            TAG_FRAME => items.push(Item::Frame(cursor.frame(&mut last_us)?)),
            TAG_PACKET => {
                let ts_us = cursor.time(&mut last_us)?;
                let bus = cursor.byte()?;
                let len = usize::try_from(cursor.varint()?).unwrap_or(usize::MAX);
                if len > MAX_PACKET {
                    return Err("packet longer than ISO-TP allows");
                }
                let packet = cursor.bytes(len)?.to_vec();
                items.push(Item::Packet { ts_us, bus, packet });
            }
            _ => return Err("unknown record"),
        }
    }
    Ok((buses, items))
}

fn header_field<const N: usize>(message: &[u8], at: usize) -> Result<[u8; N], StreamError> {
    message
        .get(at..at + N)
        .and_then(|bytes| bytes.try_into().ok())
        .ok_or(StreamError::NotABatch)
}

/// A batch's number and first timestamp, read from its header alone.
pub fn peek(message: &[u8]) -> Result<(u32, u64), StreamError> {
    if message.get(..4) != Some(&MAGIC[..]) {
        return Err(StreamError::NotABatch);
    }
    Ok((
        u32::from_le_bytes(header_field(message, 5)?),
        u64::from_le_bytes(header_field(message, 9)?),
    ))
}

/// Reads one batch.
pub fn decode(message: &[u8]) -> Result<Batch, StreamError> {
    if message.get(..4) != Some(&MAGIC[..]) {
        return Err(StreamError::NotABatch);
    }
    let version = *message.get(4).ok_or(StreamError::NotABatch)?;
    if version != VERSION {
        return Err(StreamError::Version(version));
    }
    let number = u32::from_le_bytes(header_field(message, 5)?);
    let first_us = u64::from_le_bytes(header_field(message, 9)?);
    let said = u32::from_le_bytes(header_field(message, 17)?) as usize;
    if said > MAX_PAYLOAD {
        return Err(StreamError::Length { said, held: 0 });
    }
    let compressed = message.get(HEADER_LEN..).unwrap_or_default();
    let payload = zstd::bulk::decompress(compressed, said.max(1))
        .map_err(|error| StreamError::Compression(error.to_string()))?;
    if payload.len() != said {
        return Err(StreamError::Length {
            said,
            held: payload.len(),
        });
    }
    let mut cursor = Cursor::new(&payload, 0);
    let (buses, items) = records(&mut cursor, first_us).map_err(|why| StreamError::Damaged {
        offset: cursor.at,
        why,
    })?;
    Ok(Batch {
        number,
        buses,
        items,
    })
}
