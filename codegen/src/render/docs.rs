//! Renders the bus documentation: Markdown pages for the team's mdBook site, one for the CAN
//! matrix and one for the telemetry packet's layout, from the same model as the code, so the
//! documentation cannot drift from what the car sends.

use askama::Template;

use crate::bus_load::{BusLoad, DEFAULT_BIT_RATE, WARN_LOAD, isotp_frames};
use crate::model::{
    ByteOrder, ChecksumAlgorithm, Database, Encoding, Message, Placement, Signal,
    TELEMETRY_HEADER_LEN, Telemetry, TelemetryField, WireType,
};
use crate::render::fragment::StrLit;
use crate::render::meta::{labels, signal_labels};

#[derive(Template)]
#[template(path = "docs/can.md", escape = "none")]
pub(crate) struct CanMatrix<'a> {
    pub source: &'a str,
    pub fingerprint: u32,
    pub messages: Vec<MessageDoc>,
    pub loads: Vec<BusLoadDoc>,
    /// The bit rate the loads are relative to, and where it comes from.
    pub bit_rate: String,
    pub warn_percent: String,
    /// The telemetry's bus with the packet grown by its planned headroom, empty without one.
    pub headroom: String,
}

#[derive(Template)]
#[template(path = "docs/telemetry.md", escape = "none")]
pub(crate) struct TelemetryLayout<'a> {
    pub source: &'a str,
    pub fingerprint: u32,
    pub name: String,
    pub description: String,
    pub tx_id: String,
    pub flow_control_id: String,
    pub period_ms: u32,
    pub timeout_ms: u32,
    pub len: usize,
    pub frames: IsoTpFrames,
    pub rows: Vec<FieldDoc>,
}

/// How many CAN frames one packet takes with ISO-TP over classic CAN (normal addressing):
/// a single frame carries 7 bytes; otherwise a first frame carries 6, each consecutive frame
/// 7, and the receiver answers the first frame with one flow control frame (block size 0).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct IsoTpFrames {
    pub consecutive: usize,
    pub flow_control: usize,
}

impl IsoTpFrames {
    pub(crate) fn for_len(len: usize) -> Self {
        if len <= 7 {
            Self {
                consecutive: 0,
                flow_control: 0,
            }
        } else {
            Self {
                consecutive: (len - 6).div_ceil(7),
                flow_control: 1,
            }
        }
    }

    /// Every frame on the bus for one packet.
    pub(crate) fn total(&self) -> usize {
        1 + self.consecutive + self.flow_control
    }
}

pub(crate) struct BusLoadDoc {
    pub bus: String,
    pub messages: usize,
    pub on_demand: usize,
    pub frames_per_s: String,
    pub kbit_per_s: String,
    pub load: String,
}

pub(crate) struct MessageDoc {
    pub name: String,
    pub anchor: String,
    pub id: String,
    pub len: usize,
    pub sender: String,
    pub cycle: String,
    /// The counter and checksum it carries, as a sentence (empty without).
    pub integrity: String,
    pub comment: String,
    pub signals: Vec<SignalDoc>,
}

pub(crate) struct SignalDoc {
    pub name: String,
    pub bits: String,
    pub byte_order: &'static str,
    pub kind: &'static str,
    pub scaling: String,
    pub range: String,
    pub unit: String,
    pub receivers: String,
    pub presence: String,
    pub values: String,
    pub comment: String,
}

pub(crate) struct FieldDoc {
    pub offset: String,
    pub size: String,
    pub name: String,
    pub label: String,
    pub wire: &'static str,
    pub scaling: String,
    pub range: String,
    pub unit: String,
    pub source: String,
    pub values: String,
    pub description: String,
}

/// "Rolling counter `X` (+1 per frame); checksum `Y` (SumXorFF over the other bytes)."
fn integrity(m: &Message) -> String {
    let counter = m.counter.and_then(|c| {
        let s = m.signals.get(c.signal)?;
        Some(format!(
            "rolling counter `{}` (+{} per frame)",
            s.name, c.step
        ))
    });
    let checksum = m.checksum.and_then(|c| {
        let s = m.signals.get(c.signal)?;
        let name = ChecksumAlgorithm::NAMES
            .iter()
            .find(|(_, a)| *a == c.algorithm)
            .map_or("", |(n, _)| *n);
        Some(format!(
            "checksum `{}` ({name} over the other bytes)",
            s.name
        ))
    });
    let parts: Vec<String> = counter.into_iter().chain(checksum).collect();
    if parts.is_empty() {
        return String::new();
    }
    let text = parts.join("; ");
    let capitalised =
        text.get(..1).map_or(String::new(), str::to_uppercase) + text.get(1..).unwrap_or_default();
    let refused = match (m.counter.is_some(), m.checksum.is_some()) {
        (true, true) => "whose checksum is wrong or whose counter repeats or skips",
        (true, false) => "whose counter repeats or skips",
        _ => "whose checksum is wrong",
    };
    format!("{capitalised}. Receivers refuse a frame {refused}.")
}

/// Text for a Markdown table cell: one line, pipes escaped.
fn cell(text: &str) -> String {
    text.split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
        .replace('|', "\\|")
}

fn range(min: Option<f64>, max: Option<f64>) -> String {
    match (min, max) {
        (Some(min), Some(max)) => format!("{min} .. {max}"),
        (Some(min), None) => format!(">= {min}"),
        (None, Some(max)) => format!("<= {max}"),
        (None, None) => String::new(),
    }
}

fn scaling(factor: f64, offset: f64) -> String {
    if offset == 0.0 {
        format!("x {factor}")
    } else {
        format!("x {factor} + {offset}")
    }
}

fn values(labels: Vec<(i128, StrLit)>) -> String {
    let text: Vec<String> = labels
        .iter()
        .map(|(value, label)| format!("{value} = {}", label.0))
        .collect();
    cell(&text.join(", "))
}

fn id(id: u32, extended: bool) -> String {
    if extended {
        format!("0x{id:08X} (ext.)")
    } else {
        format!("0x{id:03X}")
    }
}

fn signal_doc(db: &Database, message: &Message, s: &Signal) -> SignalDoc {
    let presence = match &s.mux {
        Some(mux) => {
            let selector = message
                .signals
                .get(mux.selector)
                .map_or("?", |m| m.name.as_str());
            let ranges = crate::model::MuxCondition::describe(&mux.ranges, "..", ", ");
            format!("when {selector} = {ranges}")
        }
        None if s.is_multiplexor => "multiplexor".to_owned(),
        None => String::new(),
    };
    SignalDoc {
        name: cell(&s.name),
        bits: format!("{} \\| {}", s.start_bit, s.len),
        byte_order: match s.byte_order {
            ByteOrder::LittleEndian => "Intel",
            ByteOrder::BigEndian => "Motorola",
        },
        kind: match s.encoding {
            Encoding::Unsigned => "unsigned",
            Encoding::Signed => "signed",
            Encoding::Float32 => "float32",
            Encoding::Float64 => "float64",
        },
        scaling: scaling(s.factor, s.offset),
        range: range(s.min, s.max),
        unit: cell(&s.unit),
        receivers: cell(&s.receivers.join(", ")),
        presence,
        values: values(signal_labels(db, s)),
        comment: cell(s.comment.as_deref().unwrap_or_default()),
    }
}

pub(crate) fn render_can(
    db: &Database,
    loads: &[BusLoad],
    headroom: Option<(&Telemetry, BusLoad)>,
    source: &str,
    fingerprint: u32,
) -> askama::Result<String> {
    let messages = db
        .messages
        .iter()
        .map(|m| MessageDoc {
            name: cell(&m.name),
            anchor: m.name.to_lowercase(),
            id: id(m.id, m.extended),
            len: m.len,
            sender: cell(m.transmitter.as_deref().unwrap_or("-")),
            cycle: match (m.cycle_time_ms, m.timeout_ms) {
                (Some(ms), Some(limit)) => format!("{ms} ms (lost after {limit} ms)"),
                (Some(ms), None) => format!("{ms} ms"),
                (None, _) => "on event".to_owned(),
            },
            integrity: integrity(m),
            comment: cell(m.comment.as_deref().unwrap_or_default()),
            signals: m.signals.iter().map(|s| signal_doc(db, m, s)).collect(),
        })
        .collect();
    let loads = loads
        .iter()
        .map(|l| BusLoadDoc {
            bus: cell(&l.bus),
            messages: l.messages,
            on_demand: l.on_demand,
            frames_per_s: format!("{:.0}", l.frames_per_s),
            kbit_per_s: format!("{:.1}", l.bits_per_s / 1_000.0),
            load: format!("{:.1} %", l.load * 100.0),
        })
        .collect();
    let bit_rate = db.bit_rate.map_or_else(
        || {
            format!(
                "{} kbit/s (assumed: the schema gives no `Baudrate`)",
                DEFAULT_BIT_RATE / 1_000
            )
        },
        |rate| format!("{} kbit/s", rate / 1_000),
    );
    CanMatrix {
        source,
        fingerprint,
        messages,
        loads,
        bit_rate,
        warn_percent: format!("{:.0}", WARN_LOAD * 100.0),
        headroom: headroom.map_or_else(String::new, |(t, planned)| {
            let grown = t.len + t.headroom_bytes;
            format!(
                "Room kept for the next sensors (`headroom_bytes` in telemetry.yaml): with the \
                 packet {} bytes longer ({grown} bytes, {} ISO-TP frames instead of {}), bus \
                 {} would carry {:.1} kbit/s, {:.1} %; the generator warns (W0211) above {:.0} %.",
                t.headroom_bytes,
                isotp_frames(grown),
                isotp_frames(t.len),
                planned.bus,
                planned.bits_per_s / 1_000.0,
                planned.load * 100.0,
                WARN_LOAD * 100.0
            )
        }),
    }
    .render()
}

fn field_doc(db: &Database, f: &TelemetryField) -> FieldDoc {
    let (offset, size) = match f.placement {
        Placement::Bytes(offset) => (offset.to_string(), f.wire.bytes().to_string()),
        Placement::Bit(offset, bit) => (format!("{offset}.{bit}"), "1 bit".to_owned()),
    };
    let wire = match f.wire {
        WireType::Flag => "flag",
        other => other.rust(),
    };
    FieldDoc {
        offset,
        size,
        name: cell(&f.name),
        label: cell(f.display.label.as_deref().unwrap_or(&f.name)),
        wire,
        scaling: scaling(f.scale, f.offset),
        range: range(f.min, f.max),
        unit: cell(&f.unit),
        source: f
            .source
            .as_deref()
            .map_or_else(String::new, |s| format!("`{s}`")),
        values: values(labels(db, f.phys)),
        description: cell(&f.description),
    }
}

pub(crate) fn render_telemetry(
    db: &Database,
    t: &Telemetry,
    source: &str,
    fingerprint: u32,
) -> askama::Result<String> {
    let header = [
        ("0", "4", "fingerprint", "Schema fingerprint", "u32"),
        ("4", "2", "sequence", "Sequence number", "u16"),
        ("6", "4", "timestamp_us", "CCM time", "u32"),
    ];
    debug_assert_eq!(TELEMETRY_HEADER_LEN, 10);
    let mut rows: Vec<FieldDoc> = header
        .iter()
        .map(|&(offset, size, name, label, wire)| FieldDoc {
            offset: offset.into(),
            size: size.into(),
            name: name.into(),
            label: label.into(),
            wire,
            scaling: String::new(),
            range: String::new(),
            unit: if name == "timestamp_us" {
                "us".into()
            } else {
                String::new()
            },
            source: "header".into(),
            values: String::new(),
            description: match name {
                "fingerprint" => {
                    format!("Always 0x{fingerprint:08X} for this layout; the Pi refuses any other.")
                }
                "sequence" => "Counts packets, wrapping at 65,536; a gap is a lost packet.".into(),
                _ => {
                    "The CCM's clock when the snapshot was taken (wraps after 71.6 minutes).".into()
                }
            },
        })
        .collect();
    rows.extend(t.fields.iter().map(|f| field_doc(db, f)));
    TelemetryLayout {
        source,
        fingerprint,
        name: t.type_name.clone(),
        description: cell(&t.description),
        tx_id: format!("0x{:03X}", t.tx_id),
        flow_control_id: format!("0x{:03X}", t.flow_control_id),
        period_ms: t.period_ms,
        timeout_ms: t.timeout_ms,
        len: t.len,
        frames: IsoTpFrames::for_len(t.len),
        rows,
    }
    .render()
}

#[cfg(test)]
mod tests {
    use super::IsoTpFrames;

    #[test]
    fn iso_tp_frame_counts_follow_the_first_and_consecutive_frame_payloads() {
        // 7 bytes fit a single frame; 8..=13 need a first frame (6) and one consecutive (7).
        assert_eq!(IsoTpFrames::for_len(7).total(), 1);
        assert_eq!(IsoTpFrames::for_len(8).total(), 3);
        assert_eq!(IsoTpFrames::for_len(13).total(), 3);
        assert_eq!(IsoTpFrames::for_len(14).total(), 4);
        // The team's 118-byte layout: 17 data frames and a flow control (docs/schema.md).
        assert_eq!(IsoTpFrames::for_len(118).total(), 18);
        assert_eq!(IsoTpFrames::for_len(72).total(), 12);
    }
}
