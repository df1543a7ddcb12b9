//! Renders the typed MQTT topics: one per packet or message, each bound to its payload type.

use askama::Template;

use crate::model::{Database, PhysType, Telemetry};

#[derive(Template)]
#[template(path = "mqtt.rs", escape = "none")]
pub struct MqttTemplate<'a> {
    pub source: &'a str,
    pub telemetry_type: &'a str,
    pub messages: Vec<MessageTopic>,
    /// Telemetry fields as the direct JSON writer writes them.
    pub json_fields: Vec<JsonField>,
    /// Bytes reserved for a telemetry payload: enough for every field at its widest.
    pub json_capacity: usize,
    /// The packet has flags (their writer is emitted only then).
    pub json_bool: bool,
}

/// A CAN message's topic.
pub struct MessageTopic {
    /// The constant's name, such as `MCU1`.
    pub const_name: String,
    /// Below the car's prefix, such as `can/mcu1`.
    pub suffix: String,
    /// The payload's message type.
    pub type_name: String,
}

/// A telemetry field and the JSON writer for its type.
pub struct JsonField {
    pub name: String,
    pub kind: JsonKind,
}

pub enum JsonKind {
    Bool,
    /// An enum, written as its raw value.
    Enum,
    Int,
    Float,
}

pub fn render(db: &Database, t: &Telemetry, source: &str) -> Result<String, askama::Error> {
    let json_fields: Vec<JsonField> = t
        .fields
        .iter()
        .map(|f| JsonField {
            name: f.name.clone(),
            kind: match f.phys {
                PhysType::Bool => JsonKind::Bool,
                PhysType::Enum(_) => JsonKind::Enum,
                PhysType::Int(_) => JsonKind::Int,
                PhysType::F32 | PhysType::F64 => JsonKind::Float,
            },
        })
        .collect();
    // Key, quotes, colon, comma and a 24-character number per field, plus the header.
    let json_capacity = 64 + json_fields.iter().map(|f| f.name.len() + 28).sum::<usize>();
    MqttTemplate {
        source,
        telemetry_type: &t.type_name,
        json_bool: t.fields.iter().any(|f| f.phys == PhysType::Bool),
        json_fields,
        json_capacity,
        messages: db
            .messages
            .iter()
            .map(|m| MessageTopic {
                const_name: m.item_name.to_ascii_uppercase(),
                suffix: format!("can/{}", m.item_name),
                type_name: m.type_name.clone(),
            })
            .collect(),
    }
    .render()
}
