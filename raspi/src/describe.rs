//! What each exported column means, from the generated schema: label, unit, description and
//! value labels, for the CSV sidecar, the Parquet metadata, the MCAP JSON Schemas and the
//! retained `schema/...` topics that describe each MQTT topic's payload.

use aer::tables::{Column, ColumnType, TABLES, Table};
use aer::telemetry::Telemetry;
use serde_json::{Map, Value, json};

/// One column, described.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Description {
    pub label: &'static str,
    pub unit: &'static str,
    pub description: &'static str,
    /// Named raw values of an enum column.
    pub values: &'static [(i128, &'static str)],
}

/// The columns every table has that are not a field or signal.
fn fixed(name: &'static str) -> Description {
    let (label, unit, description) = match name {
        "car_id" => ("Car", "", "The car the data came from."),
        "bus" => ("Bus", "", "The CAN interface the frame arrived on."),
        "schema_fingerprint" => (
            "Schema fingerprint",
            "",
            "Fingerprint of the schema the Pi decoded with.",
        ),
        "ts" => (
            "Receive time",
            "us",
            "When the Pi received the frame or packet, microseconds since the Unix epoch.",
        ),
        "sequence" => (
            "Sequence number",
            "",
            "The CCM's packet counter, wrapping at 65,536; a gap is a lost packet.",
        ),
        "timestamp_us" => (
            "CCM time",
            "us",
            "The CCM's clock when the snapshot was taken.",
        ),
        other => (other, "", ""),
    };
    Description {
        label,
        unit,
        description,
        values: &[],
    }
}

/// Every local column of `table` (tags, then columns) with its description.
pub fn columns(table: &'static Table) -> Vec<(&'static Column, Description)> {
    let tags = table.tags.iter().map(|c| (c, fixed(c.name)));
    let columns = table.columns.iter().enumerate().map(|(i, c)| {
        let description = match table.signal(i) {
            Some(meta) => Description {
                label: if std::ptr::eq(table, &aer::tables::TELEMETRY) {
                    Telemetry::DISPLAY
                        .get(usize::from(meta.index))
                        .map_or(meta.name, |d| d.label)
                } else {
                    meta.name
                },
                unit: meta.unit,
                description: meta.comment,
                values: meta.labels,
            },
            None => fixed(c.name),
        };
        (c, description)
    });
    tags.chain(columns).collect()
}

/// The JSON type of a column's values in the MCAP messages.
fn json_type(ty: ColumnType) -> &'static str {
    match ty {
        ColumnType::Bool => "boolean",
        ColumnType::F32 | ColumnType::F64 | ColumnType::Timestamp => "number",
        ColumnType::VarChar(_) => "string",
        _ => "integer",
    }
}

/// The JSON Schema of a table's MCAP messages: one property per column (`ts` in seconds, as
/// on the MQTT topics), titled with the label, described with the unit and the schema's
/// comment; enum columns list their values and get a `<name>_label` string beside them.
pub(crate) fn json_schema(table: &'static Table, title: &str) -> Value {
    schema_of(table, title, columns(table))
}

/// The JSON Schema of a table's MQTT payloads, as [`json_schema`] without the columns the topic
/// itself says (the car, the schema fingerprint): `ts`, `bus` on CAN topics, then the values.
pub(crate) fn topic_schema(table: &'static Table, title: &str) -> Value {
    let described = columns(table)
        .into_iter()
        .filter(|(column, _)| column.name == "bus" || !is_tag(table, column.name))
        .collect();
    schema_of(table, title, described)
}

/// Each MQTT topic's suffix (`telemetry`, `can/mcu1`) with the JSON Schema of its payloads,
/// which the service publishes, retained, on `schema/<suffix>`: a subscriber finds the label,
/// unit, description and value names of every key there, once, instead of in every payload.
pub(crate) fn topic_schemas() -> Vec<(&'static str, Value)> {
    TABLES
        .iter()
        .zip(aer::mqtt::SUFFIXES)
        .map(|(table, suffix)| (suffix, topic_schema(table, suffix)))
        .collect()
}

fn is_tag(table: &Table, name: &str) -> bool {
    table.tags.iter().any(|tag| tag.name == name)
}

fn schema_of(
    table: &'static Table,
    title: &str,
    described: Vec<(&'static Column, Description)>,
) -> Value {
    let mut properties = Map::new();
    for (column, d) in described {
        let required = column.name == "ts" || is_tag(table, column.name);
        let ty = json_type(column.ty);
        let mut property = Map::new();
        property.insert(
            "type".into(),
            if required {
                json!(ty)
            } else {
                json!([ty, "null"])
            },
        );
        property.insert("title".into(), json!(d.label));
        let unit = if column.name == "ts" { "s" } else { d.unit };
        let mut text = d.description.to_owned();
        if column.name == "ts" {
            text = "When the Pi received the frame or packet, seconds since the Unix epoch.".into();
        }
        if !unit.is_empty() {
            property.insert("unit".into(), json!(unit));
            text = format!("{text} [{unit}]").trim().to_owned();
        }
        property.insert("description".into(), json!(text));
        let label = (!d.values.is_empty()).then(|| {
            let one_of: Vec<Value> = d
                .values
                .iter()
                .map(|(value, label)| json!({ "const": value, "title": label }))
                .collect();
            property.insert("oneOf".into(), json!(one_of));
            let labels: Vec<&str> = d.values.iter().map(|(_, label)| *label).collect();
            json!({
                "type": ["string", "null"],
                "title": format!("{} (name)", d.label),
                "description": format!("The value of `{}` by name.", column.name),
                "enum": labels,
            })
        });
        properties.insert(column.name.into(), Value::Object(property));
        if let Some(label) = label {
            properties.insert(format!("{}_label", column.name), label);
        }
    }
    json!({
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": title,
        "type": "object",
        "properties": properties,
    })
}

#[cfg(test)]
mod tests {
    use super::{columns, json_schema};
    use aer::tables::{TABLES, TELEMETRY};

    #[test]
    fn telemetry_columns_carry_the_schema_labels_and_units() {
        let described = columns(&TELEMETRY);
        let find = |name: &str| {
            described
                .iter()
                .find(|(c, _)| c.name == name)
                .map(|(_, d)| *d)
        };
        let throttle = find("apps_travel").expect("apps_travel");
        assert_eq!((throttle.label, throttle.unit), ("Throttle", "%"));
        let state = find("vehicle_state").expect("vehicle_state");
        assert!(state.values.iter().any(|(_, l)| *l == "DRIVING"));
        assert_eq!(find("ts").map(|d| d.unit), Some("us"));
    }

    #[test]
    fn every_table_has_a_property_per_column_and_a_label_beside_each_enum() {
        for table in TABLES {
            let schema = json_schema(table, table.name);
            let properties = schema["properties"].as_object().expect("properties");
            for column in table.local_columns() {
                assert!(properties.contains_key(column.name), "{}", column.name);
            }
        }
        let schema = json_schema(&TELEMETRY, "telemetry");
        assert_eq!(schema["properties"]["soc"]["unit"], "%");
        assert_eq!(schema["properties"]["soc"]["title"], "SOC");
        assert!(schema["properties"]["vehicle_state_label"]["enum"].is_array());
    }

    #[test]
    fn each_topic_has_its_table_s_schema_without_the_topic_s_own_tags() {
        let schemas = super::topic_schemas();
        assert_eq!(schemas.len(), TABLES.len());
        for ((suffix, schema), table) in schemas.iter().zip(TABLES) {
            assert_eq!(
                suffix.replace('/', "_"),
                table.name,
                "topic and table agree"
            );
            let properties = schema["properties"].as_object().expect("properties");
            assert!(!properties.contains_key("car_id"), "{suffix}");
            assert!(!properties.contains_key("schema_fingerprint"), "{suffix}");
            assert_eq!(
                properties.contains_key("bus"),
                suffix.starts_with("can/"),
                "{suffix}"
            );
        }
        let (_, mcu1) = schemas
            .iter()
            .find(|(suffix, _)| *suffix == "can/mcu1")
            .expect("can/mcu1");
        assert_eq!(mcu1["properties"]["mcu_motor_speed"]["unit"], "rpm");
        assert_eq!(
            mcu1["properties"]["mcu_motor_speed"]["title"],
            "MCU_MotorSpeed"
        );
        assert!(mcu1["properties"]["mcu_main_state_label"]["enum"].is_array());
    }
}
