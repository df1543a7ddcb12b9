//! Renders the no_std codec's messages module from the model (the runtime beside it is
//! [`crate::runtime`]).

mod signal;

use askama::Template;

use super::doc_lines;
use super::fragment::{OptionLit, StrLit};
use crate::model::{ByteOrder, Database, EnumType, Message, PhysType};
use signal::{Conversion, Fit, FloatWire, PhysAsF64, Presence, RawCodec, SignalView, ValueKind};

#[derive(Template)]
#[template(path = "can.rs", escape = "none")]
pub(crate) struct CanTemplate<'a> {
    pub source: &'a str,
    pub db_name: &'a str,
    pub fingerprint: String,
    pub enums: Vec<EnumView>,
    pub messages: Vec<MessageView>,
}

pub(crate) struct EnumView {
    pub name: String,
    pub repr: &'static str,
    pub variants: Vec<VariantView>,
    pub used_by: String,
}

pub(crate) struct VariantView {
    pub ident: String,
    pub value: i128,
    pub label: StrLit,
    pub label_doc: String,
}

pub(crate) struct MessageView {
    pub type_name: String,
    pub name: StrLit,
    /// The static array of the signals' metadata.
    pub meta_static: String,
    pub docs: Vec<String>,
    pub id: String,
    pub extended: bool,
    pub len: usize,
    pub cycle_time: OptionLit<u32>,
    pub timeout: OptionLit<u32>,
    /// `Some(CounterMeta { .. })` or `None`.
    pub counter: String,
    /// `Some(ChecksumMeta { .. })` or `None`.
    pub checksum: String,
    pub comment: StrLit,
    /// The transmitter, `Some("CCM")` or `None`.
    pub sender: OptionLit<StrLit>,
    /// The `AerBus` names.
    pub buses: Vec<StrLit>,
    pub signals: Vec<SignalView>,
    /// Indices into `signals` in the order decode/encode must process them (multiplexors
    /// first).
    pub order: Vec<usize>,
    /// `decode_visit` binds every signal to a local named after its field: false when one
    /// would hide the `visitor` parameter (it then decodes and visits the message instead).
    pub fused_visit: bool,
}

impl MessageView {
    /// The signals in decode/encode order.
    pub(crate) fn ordered(&self) -> impl Iterator<Item = &SignalView> {
        self.order.iter().filter_map(|&i| self.signals.get(i))
    }
}

pub(crate) fn render_can(
    db: &Database,
    source: &str,
    fingerprint: u32,
) -> Result<String, askama::Error> {
    // Which signals use each enum, in one pass (not a pass over every signal per enum).
    let mut users: Vec<Vec<String>> = vec![Vec::new(); db.enums.len()];
    for m in &db.messages {
        for s in &m.signals {
            if let PhysType::Enum(index) = s.phys {
                if let Some(list) = users.get_mut(index) {
                    list.push(format!("`{}.{}`", m.name, s.name));
                }
            }
        }
    }
    let enums = db
        .enums
        .iter()
        .zip(users)
        .map(|(e, users)| enum_view(e, &users))
        .collect();
    let messages = db.messages.iter().map(|m| message_view(db, m)).collect();
    CanTemplate {
        source,
        db_name: &db.name,
        fingerprint: format!("0x{fingerprint:08X}"),
        enums,
        messages,
    }
    .render()
}

/// `users`: the signals whose type it is, as `` `Message.Signal` ``.
fn enum_view(e: &EnumType, users: &[String]) -> EnumView {
    EnumView {
        name: e.type_name.clone(),
        repr: e.repr.rust(),
        variants: e
            .variants
            .iter()
            .map(|v| VariantView {
                ident: v.ident.clone(),
                value: v.value,
                label: StrLit(v.label.clone()),
                label_doc: if v.label.trim().is_empty() {
                    "(no name)".to_owned()
                } else {
                    v.label.replace('`', "'")
                },
            })
            .collect(),
        used_by: if users.is_empty() {
            "Named values from the schema's value table.".to_owned()
        } else {
            format!("Values of {}.", users.join(", "))
        },
    }
}

fn message_view(db: &Database, m: &Message) -> MessageView {
    MessageView {
        type_name: m.type_name.clone(),
        name: StrLit(m.name.clone()),
        meta_static: format!("{}_SIGNALS", m.item_name.to_ascii_uppercase()),
        docs: message_docs(m),
        id: format!("0x{:X}", m.id),
        extended: m.extended,
        len: m.len,
        cycle_time: OptionLit(m.cycle_time_ms),
        timeout: OptionLit(m.timeout_ms),
        counter: counter_literal(m),
        checksum: checksum_literal(m),
        comment: StrLit(m.comment.clone().unwrap_or_default()),
        sender: OptionLit(m.transmitter.clone().map(StrLit)),
        buses: m.buses.iter().cloned().map(StrLit).collect(),
        signals: m
            .signals
            .iter()
            .enumerate()
            .map(|(i, s)| SignalView::new(db, m, i, s))
            .collect(),
        order: m.eval_order.clone(),
        fused_visit: !m.signals.iter().any(|s| s.field == "visitor"),
    }
}

/// The message's `CounterMeta`: its bits, least significant first.
fn counter_literal(m: &Message) -> String {
    let Some((counter, signal)) = m
        .counter
        .and_then(|c| m.signals.get(c.signal).map(|s| (c, s)))
    else {
        return "None".to_owned();
    };
    let mut bits = signal.bits();
    if signal.byte_order == ByteOrder::BigEndian {
        bits.reverse();
    }
    let bits: Vec<String> = bits.iter().map(u32::to_string).collect();
    format!(
        "Some(runtime::CounterMeta {{ signal: {}, bits: &[{}], step: {} }})",
        StrLit(signal.name.clone()),
        bits.join(", "),
        counter.step
    )
}

/// The message's `ChecksumMeta`.
fn checksum_literal(m: &Message) -> String {
    let Some((checksum, signal)) = m
        .checksum
        .and_then(|c| m.signals.get(c.signal).map(|s| (c, s)))
    else {
        return "None".to_owned();
    };
    format!(
        "Some(runtime::ChecksumMeta {{ signal: {}, byte: {}, algorithm: runtime::ChecksumAlgorithm::{} }})",
        StrLit(signal.name.clone()),
        checksum.byte,
        checksum.algorithm.variant()
    )
}

/// The schema's comment, then the wire facts.
fn message_docs(m: &Message) -> Vec<String> {
    let mut docs = m.comment.as_deref().map(doc_lines).unwrap_or_default();
    if !docs.is_empty() {
        docs.push(String::new());
    }
    let kind = if m.extended { "extended" } else { "standard" };
    let mut facts = format!(
        "`{}`: {kind} id 0x{:X}, {} bytes{}",
        m.name,
        m.id,
        m.len,
        if m.fd { " (CAN FD)" } else { "" }
    );
    if let Some(ms) = m.cycle_time_ms {
        facts.push_str(&format!(", every {ms} ms"));
    }
    if let Some(ms) = m.timeout_ms {
        facts.push_str(&format!(", lost after {ms} ms"));
    }
    if let Some(tx) = &m.transmitter {
        facts.push_str(&format!(", sent by {tx}"));
    }
    facts.push('.');
    docs.push(facts);
    docs
}
