//! Renders the typed MQTT topics: one per packet or message, each bound to its payload type,
//! and the direct JSON writers the publisher uses: snake_case keys (the Rust field names, as in
//! the store and the exports), each enum's name beside its number, numbers to the resolution
//! their scaling gives them, and the bus on CAN topics.

use askama::Template;

use crate::model::{Database, PhysType, Signal, Telemetry, WireType};

#[derive(Template)]
#[template(path = "mqtt.rs", escape = "none")]
pub(crate) struct MqttTemplate<'a> {
    pub source: &'a str,
    pub telemetry_type: &'a str,
    pub messages: Vec<MessageTopic>,
    /// Telemetry fields as the direct JSON writer writes them.
    pub json_fields: Vec<JsonField>,
    /// Bytes reserved for a telemetry payload: enough for every field at its widest.
    pub json_capacity: usize,
    /// Some payload has flags (their writer is emitted only then).
    pub json_bool: bool,
    /// Some payload has an enum (the label writer is emitted only then).
    pub json_enum: bool,
    /// Some payload has a value rounded to its resolution.
    pub json_fixed: bool,
}

/// A CAN message's topic.
pub(crate) struct MessageTopic {
    /// The constant's name, such as `MCU1`.
    pub const_name: String,
    /// Below the car's prefix, such as `can/mcu1`.
    pub suffix: String,
    /// The payload's message type.
    pub type_name: String,
    /// Its JSON writer's name, such as `mcu1_json`.
    pub writer: String,
    pub fields: Vec<JsonField>,
    pub json_capacity: usize,
}

/// A value and the JSON writer for its type.
pub(crate) struct JsonField {
    /// The key (the Rust field name).
    pub name: String,
    pub kind: JsonKind,
    /// A multiplexed signal: the key is left out when the signal is absent.
    pub optional: bool,
    /// A scaled signal with named values: the function that names a value, for
    /// `<name>_label` beside the number.
    pub label_fn: Option<String>,
}

pub(crate) enum JsonKind {
    Bool,
    /// An enum: its raw value, then `<name>_label` with its name (`null` if it has none).
    Enum,
    Int,
    /// A physical value rounded to this many decimals (its scaling's resolution).
    Fixed(usize),
    /// A float written in full (shortest round-trip form).
    Float,
}

/// The decimals that `factor` and `offset` can produce: the smallest `d` (at most 9) for
/// which both are whole multiples of `10^-d`; `None` when one has no such `d` (such as 1/3).
pub(crate) fn resolution_decimals(factor: f64, offset: f64) -> Option<usize> {
    let decimals = |x: f64| {
        (0..=9).find(|&d| {
            // Within a millionth of the last decimal (float noise), and not rounded to nothing.
            let scaled = x * 10f64.powi(d);
            (scaled - scaled.round()).abs() <= 1e-6 && (x == 0.0 || scaled.round() != 0.0)
        })
    };
    Some(decimals(factor)?.max(decimals(offset)?) as usize)
}

fn kind(phys: PhysType, float_on_wire: bool, factor: f64, offset: f64) -> JsonKind {
    match phys {
        PhysType::Bool => JsonKind::Bool,
        PhysType::Enum(_) => JsonKind::Enum,
        PhysType::Int(_) => JsonKind::Int,
        PhysType::F32 | PhysType::F64 if float_on_wire => JsonKind::Float,
        PhysType::F32 | PhysType::F64 => {
            resolution_decimals(factor, offset).map_or(JsonKind::Float, JsonKind::Fixed)
        }
    }
}

fn signal_field(type_name: &str, signal: &Signal) -> JsonField {
    JsonField {
        name: signal.field.clone(),
        kind: kind(
            signal.phys,
            signal.is_float_raw(),
            signal.factor,
            signal.offset,
        ),
        optional: signal.mux.is_some(),
        label_fn: (!signal.value_labels.is_empty()).then(|| {
            format!(
                "crate::can::{type_name}::{}_label",
                signal.field.trim_end_matches('_')
            )
        }),
    }
}

/// Key, quotes, colon, comma and a 24-character number per field (an enum's label up to 40
/// more), plus `ts`, the header or the bus.
fn capacity(fields: &[JsonField]) -> usize {
    64 + fields
        .iter()
        .map(|f| {
            f.name.len()
                + 28
                + if matches!(f.kind, JsonKind::Enum) {
                    56
                } else {
                    0
                }
        })
        .sum::<usize>()
}

pub(crate) fn render(db: &Database, t: &Telemetry, source: &str) -> Result<String, askama::Error> {
    let json_fields: Vec<JsonField> = t
        .fields
        .iter()
        .map(|f| JsonField {
            name: f.name.clone(),
            kind: kind(f.phys, f.wire == WireType::F32, f.scale, f.offset),
            optional: false,
            label_fn: None,
        })
        .collect();
    let messages: Vec<MessageTopic> = db
        .messages
        .iter()
        .map(|m| {
            let fields: Vec<JsonField> = m
                .signals
                .iter()
                .map(|s| signal_field(&m.type_name, s))
                .collect();
            MessageTopic {
                const_name: m.item_name.to_ascii_uppercase(),
                suffix: format!("can/{}", m.item_name),
                type_name: m.type_name.clone(),
                writer: format!("{}_json", m.item_name),
                json_capacity: capacity(&fields),
                fields,
            }
        })
        .collect();
    let all = || {
        json_fields
            .iter()
            .chain(messages.iter().flat_map(|m| &m.fields))
    };
    MqttTemplate {
        source,
        telemetry_type: &t.type_name,
        json_bool: all().any(|f| matches!(f.kind, JsonKind::Bool)),
        json_enum: all().any(|f| matches!(f.kind, JsonKind::Enum) || f.label_fn.is_some()),
        json_fixed: all().any(|f| matches!(f.kind, JsonKind::Fixed(_))),
        json_capacity: capacity(&json_fields),
        json_fields,
        messages,
    }
    .render()
}

#[cfg(test)]
mod tests {
    use super::resolution_decimals;

    #[test]
    fn the_resolution_is_the_decimals_of_factor_and_offset() {
        assert_eq!(resolution_decimals(1.0, 0.0), Some(0));
        assert_eq!(resolution_decimals(0.1, 0.0), Some(1));
        assert_eq!(resolution_decimals(0.25, -40.0), Some(2));
        assert_eq!(resolution_decimals(1.0192, 0.0), Some(4));
        assert_eq!(resolution_decimals(0.001, 0.5), Some(3));
        assert_eq!(resolution_decimals(0.0625, 0.0), Some(4));
        assert_eq!(resolution_decimals(1.0 / 3.0, 0.0), None);
        assert_eq!(resolution_decimals(1e-12, 0.0), None);
    }
}
