//! Renders the telemetry packet: the no_std firmware packer (`telemetry.rs`) and the Pi's Deku
//! decoder (`telemetry_deku.rs`). Both convert through the same generated per-field functions,
//! so they cannot disagree on scaling.

mod field;

use askama::Template;

use super::phys_rust;
use crate::model::{Database, PhysType, Telemetry, WireType};
use crate::naming::snake;
use field::{FieldConversion, FieldDefault, FieldPlacement, FieldView};

#[derive(Template)]
#[template(path = "telemetry.rs", escape = "none")]
pub(crate) struct TelemetryTemplate<'a> {
    pub source: &'a str,
    pub t: &'a Telemetry,
    pub fingerprint: String,
    pub enums: Vec<String>,
    pub fields: Vec<FieldView>,
    pub flag_bytes: usize,
    /// One arm per DBC message that telemetry fields mirror.
    pub mirrors: Vec<MirrorArm>,
    /// The packet's sender (a DBC node), for the docs.
    pub sender: String,
    /// The sender transmits a message that fields mirror (`from_parts` takes it).
    pub has_sent: bool,
}

/// The fields that mirror one message's signals.
pub(crate) struct MirrorArm {
    /// `AnyMessage` variant (the message's type name).
    pub variant: String,
    /// The packet's sender transmits this message itself: its field in `TelemetrySent`
    /// (snake_case), through which `from_parts` takes the message as sent.
    pub sent: Option<String>,
    pub copies: Vec<MirrorCopy>,
}

/// `self.<field> = m.<signal>`, converted where the types differ.
pub(crate) struct MirrorCopy {
    pub field: String,
    pub signal: String,
    /// The signal is multiplexed: copy only when present.
    pub optional: bool,
    /// The field's type, when the signal's differs.
    pub cast: Option<String>,
}

#[derive(Template)]
#[template(path = "telemetry_deku.rs", escape = "none")]
pub(crate) struct DekuTemplate<'a> {
    pub source: &'a str,
    pub t: &'a Telemetry,
    pub fields: Vec<FieldView>,
    pub flag_bytes: usize,
}

fn flag_count(t: &Telemetry) -> usize {
    t.fields.iter().filter(|f| f.wire == WireType::Flag).count()
}

fn field_views(db: &Database, t: &Telemetry) -> Vec<FieldView> {
    // Flags follow every byte-aligned field.
    let first_flag_byte = t.len - flag_count(t).div_ceil(8);
    t.fields
        .iter()
        .enumerate()
        .map(|(i, f)| FieldView::new(db, first_flag_byte, i, f))
        .collect()
}

pub(crate) fn render(
    db: &Database,
    t: &Telemetry,
    source: &str,
    fingerprint: u32,
) -> Result<String, askama::Error> {
    let mut enums: Vec<String> = t
        .fields
        .iter()
        .filter_map(|f| match f.phys {
            PhysType::Enum(i) => db.enums.get(i).map(|e| e.type_name.clone()),
            _ => None,
        })
        .collect();
    enums.sort();
    enums.dedup();
    let mirrors = mirror_arms(db, t);
    TelemetryTemplate {
        source,
        t,
        fingerprint: format!("0x{fingerprint:08X}"),
        enums,
        fields: field_views(db, t),
        flag_bytes: flag_count(t).div_ceil(8),
        has_sent: mirrors.iter().any(|arm| arm.sent.is_some()),
        mirrors,
        sender: t.sender.clone().unwrap_or_else(|| "the sender".to_owned()),
    }
    .render()
}

/// Groups the fields that mirror DBC signals by message, in DBC message order.
fn mirror_arms(db: &Database, t: &Telemetry) -> Vec<MirrorArm> {
    db.messages
        .iter()
        .filter_map(|message| {
            let copies: Vec<MirrorCopy> = t
                .fields
                .iter()
                .filter_map(|field| {
                    let (msg, sig) = field.source.as_deref()?.split_once('.')?;
                    if msg != message.name {
                        return None;
                    }
                    let signal = message.signals.iter().find(|s| s.name == sig)?;
                    Some(MirrorCopy {
                        field: field.name.clone(),
                        signal: signal.field.clone(),
                        optional: signal.mux.is_some(),
                        cast: (signal.phys != field.phys).then(|| phys_rust(db, field.phys)),
                    })
                })
                .collect();
            let sent_by_sender = t.sender.is_some() && message.transmitter == t.sender;
            (!copies.is_empty()).then(|| MirrorArm {
                variant: message.type_name.clone(),
                sent: sent_by_sender.then(|| snake(&message.type_name)),
                copies,
            })
        })
        .collect()
}

pub(crate) fn render_deku(
    db: &Database,
    t: &Telemetry,
    source: &str,
) -> Result<String, askama::Error> {
    DekuTemplate {
        source,
        t,
        fields: field_views(db, t),
        flag_bytes: flag_count(t).div_ceil(8),
    }
    .render()
}
