//! Renders the typed MQTT topics: one per packet or message, each bound to its payload type.

use askama::Template;

use crate::model::{Database, PhysType, Telemetry};
use crate::naming::{screaming, snake};

#[derive(Template)]
#[template(path = "mqtt.rs", escape = "none")]
pub struct MqttTemplate<'a> {
    pub source: &'a str,
    pub telemetry_type: &'a str,
    pub messages: Vec<(String, String, String)>,
    /// Telemetry fields as written by the direct JSON writer: (name, writer call).
    pub json_fields: Vec<(String, String)>,
    /// Bytes reserved for a telemetry payload: enough for every field at its widest.
    pub json_capacity: usize,
    /// The packet has flags (their writer is emitted only then).
    pub json_bool: bool,
}

pub fn render(db: &Database, t: &Telemetry, source: &str) -> Result<String, askama::Error> {
    let json_fields: Vec<(String, String)> = t
        .fields
        .iter()
        .map(|f| {
            let name = &f.name;
            let call = match f.phys {
                PhysType::Bool => format!("json_bool(out, self.telemetry.{name})"),
                PhysType::Enum(_) => format!("json_int(out, self.telemetry.{name}.into_raw())"),
                PhysType::Int(_) => format!("json_int(out, self.telemetry.{name})"),
                PhysType::F32 | PhysType::F64 => {
                    format!("json_float(out, self.telemetry.{name})")
                }
            };
            (name.clone(), call)
        })
        .collect();
    // Key, quotes, colon, comma and a 24-character number per field, plus the header.
    let json_capacity = 64 + json_fields.iter().map(|(n, _)| n.len() + 28).sum::<usize>();
    MqttTemplate {
        source,
        telemetry_type: &t.type_name,
        json_bool: t.fields.iter().any(|f| f.phys == PhysType::Bool),
        json_fields,
        json_capacity,
        messages: db
            .messages
            .iter()
            .map(|m| {
                let name = snake(&m.name).trim_end_matches('_').to_owned();
                (
                    screaming(&m.name),
                    format!("can/{name}"),
                    m.type_name.clone(),
                )
            })
            .collect(),
    }
    .render()
}
