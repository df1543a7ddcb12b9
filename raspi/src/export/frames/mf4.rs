//! MF4: ASAM MDF 4.10 with its bus-logging convention, which CANape and asammdf read as CAN
//! traffic and decode with a DBC. One data group holds every frame as a record: the time
//! (the master channel, seconds from the header's start) and a `CAN_DataFrame` whose parts
//! are the channel (`BusChannel`), identifier (`ID`, bit 31 set for an extended one, and
//! `IDE`), `DLC`, `DataLength` and `DataBytes`.
//!
//! The records are written as they come, into the data block that follows the header; the
//! blocks that describe them are written after it, once the count is known, and the header's
//! links and the data block's length are written again.

use super::{FrameWriter, Summary};
use crate::markup::escape;
use aer_host::formats::raw_format::Frame;
use embedded_can::Id;
use std::io::{self, Seek, SeekFrom, Write};

/// The identification block's size; the header block follows it.
const ID_BYTES: u64 = 64;
const HD_AT: u64 = ID_BYTES;
const HD_LINKS: usize = 6;
/// The data block follows the header block (24 + 6 links + 32 bytes of data).
const DT_AT: u64 = HD_AT + 24 + 8 * HD_LINKS as u64 + 32;
const BLOCK_HEADER_BYTES: u64 = 24;

/// One frame's record: time (f64), channel (u8), identifier (u32), IDE, DLC, data length (u8
/// each), data (8 bytes).
const RECORD_BYTES: u32 = 24;
const TIME_AT: u32 = 0;
const FRAME_AT: u32 = 8;

/// Channel types, synchronisation types and data types of the standard.
const CN_VALUE: u8 = 0;
const CN_MASTER: u8 = 2;
const SYNC_NONE: u8 = 0;
const SYNC_TIME: u8 = 1;
const UNSIGNED_LE: u8 = 0;
const FLOAT_LE: u8 = 4;
const BYTE_ARRAY: u8 = 10;
/// `CAN_DataFrame` is a bus event (cn_flags bit 10); its channel group holds bus events
/// (cg_flags bit 1) and nothing else (bit 2, "plain"), so readers take every record.
const CN_BUS_EVENT: u32 = 1 << 10;
const CG_BUS_EVENT: u16 = (1 << 1) | (1 << 2);
/// Source: a bus (si_type 2), CAN (si_bus_type 2).
const SOURCE_BUS: u8 = 2;
const BUS_CAN: u8 = 2;
/// The header's time is UTC with valid (zero) offsets.
const TIME_OFFSETS_VALID: u8 = 1 << 1;
const EXTENDED_ID: u32 = 0x8000_0000;

/// Writes one MF4 file.
pub struct Mf4Writer<W: Write + Seek> {
    out: W,
    start_us: u64,
    records: u64,
    comment: String,
    channels: String,
}

impl<W: Write + Seek> Mf4Writer<W> {
    /// Writes the identification and header blocks (links to come) and opens the data block.
    pub fn new(mut out: W, summary: &Summary, metadata: &[(String, String)]) -> io::Result<Self> {
        out.write_all(&identification())?;
        let start_ns = summary.first_us.saturating_mul(1_000);
        let mut hd = Vec::with_capacity(32);
        hd.extend_from_slice(&start_ns.to_le_bytes());
        hd.extend_from_slice(&0i16.to_le_bytes()); // time zone offset, minutes
        hd.extend_from_slice(&0i16.to_le_bytes()); // daylight saving offset, minutes
        hd.extend_from_slice(&[TIME_OFFSETS_VALID, 0, 0, 0]);
        hd.extend_from_slice(&0f64.to_le_bytes()); // start angle
        hd.extend_from_slice(&0f64.to_le_bytes()); // start distance
        out.write_all(&block(b"##HD", &[0; HD_LINKS], &hd))?;
        out.write_all(&block(b"##DT", &[], &[]))?;
        Ok(Self {
            out,
            start_us: summary.first_us,
            records: 0,
            comment: header_comment(metadata, &summary.channels.describe()),
            channels: summary.channels.describe(),
        })
    }

    /// Appends a block at the end (8-byte aligned); its address.
    fn append(&mut self, bytes: &[u8]) -> io::Result<u64> {
        let end = self.out.seek(SeekFrom::End(0))?;
        let padding = (8 - end % 8) % 8;
        self.out.write_all(&[0; 8][..padding as usize])?;
        self.out.write_all(bytes)?;
        Ok(end + padding)
    }

    fn text(&mut self, kind: &[u8; 4], text: &str) -> io::Result<u64> {
        let mut data = text.as_bytes().to_vec();
        // Zero-terminated, padded to 8 bytes.
        data.push(0);
        data.resize(data.len().div_ceil(8) * 8, 0);
        self.append(&block(kind, &[], &data))
    }

    /// A channel block; `next`, `composition`, `source` and `unit` are links (0: none).
    fn channel(&mut self, channel: &Channel, next: u64, composition: u64) -> io::Result<u64> {
        let name = self.text(b"##TX", channel.name)?;
        let unit = match channel.unit {
            Some(unit) => self.text(b"##TX", unit)?,
            None => 0,
        };
        let mut data = Vec::with_capacity(72);
        data.extend_from_slice(&[channel.kind, channel.sync, channel.data_type, 0]);
        data.extend_from_slice(&channel.byte_offset.to_le_bytes());
        data.extend_from_slice(&channel.bits.to_le_bytes());
        data.extend_from_slice(&channel.flags.to_le_bytes());
        data.extend_from_slice(&0u32.to_le_bytes()); // invalidation bit
        data.extend_from_slice(&[0, 0, 0, 0]); // precision, reserved, attachments
        data.extend_from_slice(&[0; 48]); // value range and limits
        self.append(&block(
            b"##CN",
            &[next, composition, name, channel.source, 0, 0, unit, 0],
            &data,
        ))
    }
}

impl<W: Write + Seek> FrameWriter for Mf4Writer<W> {
    fn frame(&mut self, frame: &Frame, channel: u16) -> io::Result<()> {
        let at = frame.frame.ts_us.saturating_sub(self.start_us) as f64 / 1e6;
        let (id, extended) = match frame.frame.id {
            Id::Standard(id) => (u32::from(id.as_raw()), 0),
            Id::Extended(id) => (id.as_raw() | EXTENDED_ID, 1),
        };
        let mut record = [0u8; RECORD_BYTES as usize];
        let fields = at
            .to_le_bytes()
            .into_iter()
            .chain([u8::try_from(channel).unwrap_or(u8::MAX)])
            .chain(id.to_le_bytes())
            .chain([extended, frame.frame.len, frame.frame.len])
            .chain(frame.frame.data);
        for (slot, byte) in record.iter_mut().zip(fields) {
            *slot = byte;
        }
        self.out.write_all(&record)?;
        self.records += 1;
        Ok(())
    }

    fn finish(mut self: Box<Self>) -> io::Result<()> {
        let data_end = self.out.stream_position()?;
        let source_name = self.text(b"##TX", "CAN")?;
        let source_path = self.text(b"##TX", &self.channels.clone())?;
        let mut si = vec![SOURCE_BUS, BUS_CAN];
        si.resize(8, 0);
        let source = self.append(&block(b"##SI", &[source_name, source_path, 0], &si))?;
        // The frame's parts, last first, each linking to the next.
        let mut next = 0;
        for part in FRAME_PARTS.iter().rev() {
            next = self.channel(part, next, 0)?;
        }
        let frame = self.channel(
            &Channel {
                source,
                ..DATA_FRAME
            },
            0,
            next,
        )?;
        let time = self.channel(&TIME, frame, 0)?;
        let acquisition = self.text(b"##TX", "CAN")?;
        let mut cg = Vec::with_capacity(32);
        cg.extend_from_slice(&0u64.to_le_bytes()); // record id
        cg.extend_from_slice(&self.records.to_le_bytes());
        cg.extend_from_slice(&CG_BUS_EVENT.to_le_bytes());
        cg.extend_from_slice(&u16::from(b'.').to_le_bytes()); // path separator
        cg.extend_from_slice(&[0; 4]);
        cg.extend_from_slice(&RECORD_BYTES.to_le_bytes());
        cg.extend_from_slice(&0u32.to_le_bytes()); // invalidation bytes
        let group = self.append(&block(b"##CG", &[0, time, acquisition, source, 0, 0], &cg))?;
        let data_group = self.append(&block(b"##DG", &[0, group, DT_AT, 0], &[0; 8]))?;
        let history_comment = self.text(
            b"##MD",
            &format!(
                "<FHcomment><TX>exported from the raw log</TX><tool_id>aer-raspi</tool_id>\
                 <tool_vendor>Anteater Electric Racing</tool_vendor><tool_version>{}</tool_version>\
                 </FHcomment>",
                env!("CARGO_PKG_VERSION")
            ),
        )?;
        let start_ns = self.start_us.saturating_mul(1_000);
        let mut fh = start_ns.to_le_bytes().to_vec();
        fh.extend_from_slice(&[0, 0, 0, 0, TIME_OFFSETS_VALID, 0, 0, 0]);
        let history = self.append(&block(b"##FH", &[0, history_comment], &fh))?;
        let comment = self.text(b"##MD", &self.comment.clone())?;
        // The header's links: first data group, file history, comment.
        self.out.seek(SeekFrom::Start(HD_AT + BLOCK_HEADER_BYTES))?;
        for link in [data_group, history, 0, 0, 0, comment] {
            self.out.write_all(&link.to_le_bytes())?;
        }
        // The data block's length: its header and every record.
        self.out.seek(SeekFrom::Start(DT_AT + 8))?;
        self.out.write_all(&(data_end - DT_AT).to_le_bytes())?;
        self.out.flush()
    }
}

/// What a channel block says about a channel.
#[derive(Clone, Copy)]
struct Channel {
    name: &'static str,
    kind: u8,
    sync: u8,
    data_type: u8,
    byte_offset: u32,
    bits: u32,
    flags: u32,
    unit: Option<&'static str>,
    /// Link to the source block (0: none).
    source: u64,
}

const PART: Channel = Channel {
    name: "",
    kind: CN_VALUE,
    sync: SYNC_NONE,
    data_type: UNSIGNED_LE,
    byte_offset: FRAME_AT,
    bits: 8,
    flags: 0,
    unit: None,
    source: 0,
};

const TIME: Channel = Channel {
    name: "t",
    kind: CN_MASTER,
    sync: SYNC_TIME,
    data_type: FLOAT_LE,
    byte_offset: TIME_AT,
    bits: 64,
    unit: Some("s"),
    ..PART
};

const DATA_FRAME: Channel = Channel {
    name: "CAN_DataFrame",
    data_type: BYTE_ARRAY,
    bits: (RECORD_BYTES - FRAME_AT) * 8,
    flags: CN_BUS_EVENT,
    ..PART
};

const FRAME_PARTS: [Channel; 6] = [
    Channel {
        name: "CAN_DataFrame.BusChannel",
        ..PART
    },
    Channel {
        name: "CAN_DataFrame.ID",
        byte_offset: FRAME_AT + 1,
        bits: 32,
        ..PART
    },
    Channel {
        name: "CAN_DataFrame.IDE",
        byte_offset: FRAME_AT + 5,
        ..PART
    },
    Channel {
        name: "CAN_DataFrame.DLC",
        byte_offset: FRAME_AT + 6,
        ..PART
    },
    Channel {
        name: "CAN_DataFrame.DataLength",
        byte_offset: FRAME_AT + 7,
        ..PART
    },
    Channel {
        name: "CAN_DataFrame.DataBytes",
        data_type: BYTE_ARRAY,
        byte_offset: FRAME_AT + 8,
        bits: 64,
        ..PART
    },
];

/// The identification block: file id, version 4.10, the program.
fn identification() -> [u8; ID_BYTES as usize] {
    let mut id = [0u8; ID_BYTES as usize];
    let fields: [(&[u8], usize); 4] = [
        (b"MDF     ", 0),
        (b"4.10    ", 8),
        (b"aer-rasp", 16),
        (&410u16.to_le_bytes(), 28),
    ];
    for (bytes, at) in fields {
        if let Some(slot) = id.get_mut(at..at + bytes.len()) {
            slot.copy_from_slice(bytes);
        }
    }
    id
}

/// A block: id, reserved, length, link count, links, data.
fn block(kind: &[u8; 4], links: &[u64], data: &[u8]) -> Vec<u8> {
    let length = BLOCK_HEADER_BYTES + 8 * links.len() as u64 + data.len() as u64;
    let mut bytes = Vec::with_capacity(usize::try_from(length).unwrap_or(0));
    bytes.extend_from_slice(kind);
    bytes.extend_from_slice(&[0; 4]);
    bytes.extend_from_slice(&length.to_le_bytes());
    bytes.extend_from_slice(&(links.len() as u64).to_le_bytes());
    for link in links {
        bytes.extend_from_slice(&link.to_le_bytes());
    }
    bytes.extend_from_slice(data);
    bytes
}

/// The header's comment: the export's metadata as the standard's common properties, and
/// which bus each channel is.
fn header_comment(metadata: &[(String, String)], channels: &str) -> String {
    let mut xml = String::from("<HDcomment><TX>CAN frames from the AER raw log; channels: ");
    xml.push_str(&escape(channels));
    xml.push_str("</TX><common_properties>");
    for (key, value) in metadata {
        xml.push_str(&format!(
            "<e name=\"{}\">{}</e>",
            escape(key),
            escape(value)
        ));
    }
    xml.push_str("</common_properties></HDcomment>");
    xml
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_data_block_follows_the_header_block() {
        let hd = block(b"##HD", &[0; HD_LINKS], &[0; 32]);
        assert_eq!(HD_AT + hd.len() as u64, DT_AT);
        assert_eq!(DT_AT % 8, 0);
    }

    #[test]
    fn metadata_is_escaped_for_the_xml_comment() {
        let xml = header_comment(&[("driver".into(), "Ana \"fast\" <&>".into())], "1 = can0");
        assert!(xml.contains("<e name=\"driver\">Ana &quot;fast&quot; &lt;&amp;&gt;</e>"));
    }
}
