//! Renders the typed MQTT topics: one per packet or message, each bound to its payload type.

use askama::Template;

use crate::model::{Database, Telemetry};
use crate::naming::{screaming, snake};

#[derive(Template)]
#[template(path = "mqtt.rs", escape = "none")]
pub struct MqttTemplate<'a> {
    pub source: &'a str,
    pub telemetry_type: &'a str,
    pub messages: Vec<(String, String, String)>,
}

pub fn render(db: &Database, t: &Telemetry, source: &str) -> Result<String, askama::Error> {
    MqttTemplate {
        source,
        telemetry_type: &t.type_name,
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
