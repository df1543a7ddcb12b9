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

/// A readable label from a DBC signal's comment: its first phrase (up to the first `.`, `:`
/// or `;`, without a closing `, in <unit>`), when that is short enough for a column heading;
/// `None` for a signal without a comment, where the signal's name has to do.
fn comment_label(comment: &'static str) -> Option<&'static str> {
    let end = comment.find(['.', ':', ';']).unwrap_or(comment.len());
    let phrase = comment.get(..end)?;
    let phrase = phrase
        .find(", in ")
        .map_or(phrase, |unit| phrase.get(..unit).unwrap_or(phrase));
    let phrase = phrase.trim();
    (!phrase.is_empty() && phrase.len() <= LABEL_MAX).then_some(phrase)
}

/// The longest phrase of a comment taken as a column's label (characters).
const LABEL_MAX: usize = 48;

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
                    comment_label(meta.comment).unwrap_or(meta.name)
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

/// One property of a JSON Schema: the key, its column type, what it means, and whether it is
/// always present.
pub(crate) struct Property<'a> {
    pub name: &'a str,
    pub ty: ColumnType,
    pub description: Description,
    pub required: bool,
}

/// The JSON Schema of a table's MQTT payloads: every column but the ones the topic itself
/// says (the car, the schema fingerprint): `ts` in seconds since the epoch, `bus` on CAN
/// topics, then the values.
pub(crate) fn topic_schema(table: &'static Table, title: &str) -> Value {
    let properties = columns(table)
        .into_iter()
        .filter(|(column, _)| column.name == "bus" || !is_tag(table, column.name))
        .map(|(column, description)| {
            let time = column.name == "ts";
            Property {
                name: column.name,
                ty: column.ty,
                description: if time {
                    Description {
                        unit: "s",
                        description: "When the Pi received the frame (or, for telemetry, the packet's last frame), seconds since the Unix epoch (UTC).",
                        ..description
                    }
                } else {
                    description
                },
                required: time || column.name == "bus",
            }
        });
    schema_of(title, properties)
}

/// Each MQTT topic's suffix (`telemetry`, `can/dti_speed`) with the JSON Schema of its
/// payloads, which the service publishes, retained, on `schema/<suffix>`: a subscriber finds
/// the label, unit, description and value names of every key there, once, instead of in every
/// payload.
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

/// A JSON Schema with one property per entry, titled with its label, described with its unit
/// and comment; enum properties list their values and get a `<name>_label` string beside them.
pub(crate) fn schema_of<'a>(
    title: &str,
    described: impl IntoIterator<Item = Property<'a>>,
) -> Value {
    let mut properties = Map::new();
    for Property {
        name,
        ty,
        description: d,
        required,
    } in described
    {
        let ty = json_type(ty);
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
        let mut text = d.description.to_owned();
        if !d.unit.is_empty() {
            property.insert("unit".into(), json!(d.unit));
            text = format!("{text} [{}]", d.unit).trim().to_owned();
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
                "description": format!("The value of `{name}` by name."),
                "enum": labels,
            })
        });
        properties.insert(name.into(), Value::Object(property));
        if let Some(label) = label {
            properties.insert(format!("{name}_label"), label);
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
    use super::{columns, topic_schema};
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
    fn every_topic_has_a_property_per_value_and_a_label_beside_each_enum() {
        for table in TABLES {
            let schema = topic_schema(table, table.name);
            let properties = schema["properties"].as_object().expect("properties");
            for column in table.local_columns() {
                let tag = table.tags.iter().any(|t| t.name == column.name);
                assert_eq!(
                    properties.contains_key(column.name),
                    !tag || column.name == "bus",
                    "{}",
                    column.name
                );
            }
        }
        let schema = topic_schema(&TELEMETRY, "telemetry");
        assert_eq!(schema["properties"]["soc"]["unit"], "%");
        assert_eq!(schema["properties"]["soc"]["title"], "SOC");
        assert_eq!(schema["properties"]["ts"]["unit"], "s");
        assert!(schema["properties"]["vehicle_state_label"]["enum"].is_array());
    }

    #[test]
    fn can_signals_are_labelled_from_their_comment_where_there_is_one() {
        let find = |table: &str, column: &str| {
            let table = TABLES.iter().find(|t| t.name == table).expect(table);
            columns(table)
                .into_iter()
                .find(|(c, _)| c.name == column)
                .map(|(_, d)| d.label)
                .expect(column)
        };
        // "Torque request: 0.392 % of MOTOR_MAX_TORQUE ..." reads as its first phrase.
        assert_eq!(find("can_vcu1", "vcu_torque_req"), "Torque request");
        // A signal without a comment keeps its DBC name.
        assert_eq!(
            find("can_vcu1", "vcu_authentication_status"),
            "VCU_AuthenticationStatus"
        );
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
            columns(TABLES.iter().find(|t| t.name == "can_mcu1").expect("mcu1"))
                .into_iter()
                .find(|(c, _)| c.name == "mcu_motor_speed")
                .map(|(_, d)| d.label)
                .expect("column")
        );
        assert!(mcu1["properties"]["mcu_main_state_label"]["enum"].is_array());
    }
}
