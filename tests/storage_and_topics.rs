//! The generated TDengine schema and MQTT topics: what the Pi creates, migrates and publishes.

use aer::can::{AnyMessage, Mcu1, McuMainState};
use aer::mqtt::{self, TelemetryRecord};
use aer::tables::{self, ColumnType, TABLES};
use aer::telemetry::{Telemetry, TelemetryHeader};

#[test]
fn telemetry_table_has_a_lossless_typed_column_per_field() {
    let t = &tables::TELEMETRY;
    assert_eq!(t.columns[0].name, "ts");
    assert_eq!(t.columns[0].ty, ColumnType::Timestamp);
    assert_eq!(t.columns.len(), 3 + Telemetry::FIELDS.len());
    let ty = |name: &str| t.columns.iter().find(|c| c.name == name).map(|c| c.ty);
    assert_eq!(
        ty("motor_temp"),
        Some(ColumnType::I16),
        "offset -40 on a u8: exact integers"
    );
    assert_eq!(ty("fault_bse"), Some(ColumnType::Bool));
    assert_eq!(
        ty("mcu_main_state"),
        Some(ColumnType::U8),
        "enums as their raw value"
    );
    assert_eq!(ty("shocktravel1"), Some(ColumnType::F32));
    assert_eq!(ColumnType::I16.tdengine(), "SMALLINT");
    assert_eq!(ColumnType::U8.tdengine(), "TINYINT UNSIGNED");
    assert_eq!(ColumnType::VarChar(32).tdengine(), "VARCHAR(32)");
    assert_eq!(ColumnType::F32.sqlite(), "REAL");
    assert_eq!(ColumnType::Timestamp.sqlite(), "INTEGER");
    assert_eq!(
        t.tags.iter().map(|c| c.name).collect::<Vec<_>>(),
        ["car_id", "schema_fingerprint"]
    );
    let marks = t.tdengine.insert.matches('?').count();
    assert_eq!(
        marks,
        1 + t.tags.len() + t.columns.len(),
        "{}",
        t.tdengine.insert
    );
    assert!(
        t.tdengine
            .create
            .starts_with("CREATE STABLE IF NOT EXISTS `telemetry` (`ts` TIMESTAMP")
    );
}

#[test]
fn every_can_message_has_a_table_found_without_searching() {
    assert_eq!(TABLES.len(), 1 + aer::can::MESSAGES.len());
    for (index, table) in TABLES.iter().enumerate() {
        assert_eq!(table.index, index, "{}", table.name);
    }
    let mcu1 = Mcu1::decode(&[0; Mcu1::LEN]).expect("an all-zero MCU1 decodes");
    let table = tables::for_message(&AnyMessage::Mcu1(mcu1));
    assert_eq!(table.name, "can_mcu1");
    assert_eq!(table.columns.len(), 1 + Mcu1::META.signals.len());
    // Signal i of the message is column 1 + i.
    for (i, signal) in Mcu1::META.signals.iter().enumerate() {
        assert_eq!(usize::from(signal.index), i);
    }
    let speed = Mcu1::META
        .signals
        .iter()
        .find(|s| s.name == "MCU_MotorSpeed")
        .expect("MCU_MotorSpeed");
    assert_eq!(
        table.columns[1 + usize::from(speed.index)].name,
        "mcu_motor_speed"
    );
    assert!(
        table
            .columns
            .iter()
            .any(|c| c.name == "mcu_motor_speed" && c.ty == ColumnType::F64)
    );
    assert!(table.tags.iter().any(|c| c.name == "bus"));
    // Every message's frames go to the table at its position (telemetry is first).
    for (i, meta) in aer::can::MESSAGES.iter().enumerate() {
        let table = TABLES[1 + i];
        assert_eq!(table.columns.len(), 1 + meta.signals.len(), "{}", meta.name);
    }
    let script = include_str!("../generated/sql/tdengine.sql");
    for table in TABLES {
        assert!(
            script.contains(table.tdengine.create),
            "{} missing from the .sql script",
            table.name
        );
    }
}

/// Exports label their columns from the table itself: every value column finds its field or
/// signal (unit, comment, value labels); `ts` and the packet header have none.
#[test]
fn every_value_column_finds_what_the_schema_says_about_it() {
    for table in TABLES {
        let values = table.columns.len() - table.signals.len();
        for (i, column) in table.columns.iter().enumerate() {
            match table.signal(i) {
                Some(meta) => {
                    assert!(i >= values, "{}.{}", table.name, column.name);
                    // Columns carry the Rust field's name: snake case of the signal's.
                    let snake = meta.name.to_ascii_lowercase().replace('_', "");
                    assert_eq!(snake, column.name.replace('_', ""), "{}", table.name);
                }
                None => assert!(i < values, "{}.{} has no signal", table.name, column.name),
            }
        }
    }
    let soc = tables::TELEMETRY.signal(
        tables::TELEMETRY
            .columns
            .iter()
            .position(|c| c.name == "soc")
            .unwrap_or(0),
    );
    assert_eq!(soc.map(|m| m.unit), Some("%"));
}

#[test]
fn a_live_database_lacking_columns_gets_alter_statements() {
    let t = &tables::TELEMETRY;
    let existing: Vec<&str> = t
        .columns
        .iter()
        .map(|c| c.name)
        .filter(|n| *n != "shocktravel4")
        .collect();
    let missing: Vec<_> = t.missing_columns(&existing).collect();
    assert_eq!(missing.len(), 1);
    assert_eq!(
        t.tdengine_add_column(missing[0]),
        "ALTER STABLE `telemetry` ADD COLUMN `shocktravel4` FLOAT"
    );
    assert_eq!(
        t.sqlite_add_column(missing[0]),
        "ALTER TABLE \"telemetry\" ADD COLUMN \"shocktravel4\" REAL"
    );
    // TDengine reports column names in lower case; names compare case-insensitively.
    let upper: Vec<String> = t.columns.iter().map(|c| c.name.to_uppercase()).collect();
    let upper: Vec<&str> = upper.iter().map(String::as_str).collect();
    assert_eq!(t.missing_columns(&upper).count(), 0);
}

#[test]
fn topics_live_under_the_car_prefix() {
    assert_eq!(mqtt::TELEMETRY.path("aer/car1"), "aer/car1/telemetry");
    assert_eq!(mqtt::can::MCU1.path("aer/car1/"), "aer/car1/can/mcu1");
    assert_eq!(mqtt::SUFFIXES.len(), 1 + aer::can::MESSAGES.len());
    // A service's own topics (the Pi's status, say) are made the same way.
    let status: mqtt::Topic<()> = mqtt::Topic::new("status");
    assert_eq!(status.path("aer/car1"), "aer/car1/status");
    // The Pi and the dashboard both build the car's prefix with this, from their configs.
    assert_eq!(mqtt::car_prefix("aer", "car1"), "aer/car1");
    assert_eq!(mqtt::car_prefix("team/aer//", "car2"), "team/aer/car2");
    assert!(
        mqtt::SUFFIXES
            .iter()
            .all(|s| !s.contains('+') && !s.contains('#'))
    );
}

/// Within float noise: a published number is the exact decimal of a value on its scaling's
/// grid, so it differs from the decoded `f64` by representation error only.
fn same_number(published: f64, decoded: f64) -> bool {
    (published - decoded).abs() <= 1e-9 * decoded.abs().max(1.0)
}

#[test]
fn payloads_are_flat_json_with_ts_in_seconds_enum_names_and_no_float_noise() {
    let (_, mut snapshot) = Telemetry::unpack(&{
        let mut b = [0u8; Telemetry::LEN];
        b[..4].copy_from_slice(&aer::telemetry::TELEMETRY_FINGERPRINT.to_le_bytes());
        b
    })
    .expect("valid");
    snapshot.mcu_main_state = McuMainState::Run;
    snapshot.motor_speed = 1234.5;
    snapshot.motor_torque = Telemetry::motor_torque_from_raw(200);
    let record = TelemetryRecord {
        header: TelemetryHeader {
            sequence: 9,
            timestamp_us: 77,
        },
        telemetry: snapshot,
    };
    let bytes = record.to_json(1_763_683_200.25);
    let text = String::from_utf8(bytes.clone()).expect("UTF-8");
    let json: serde_json::Value = serde_json::from_slice(&bytes).expect("JSON");
    assert_eq!(json["ts"], 1_763_683_200.25);
    assert_eq!(json["sequence"], 9);
    assert_eq!(json["motor_speed"], 1234.5);
    assert_eq!(json["mcu_main_state"], 3, "the number, for plots");
    assert_eq!(
        json["mcu_main_state_label"], "RUN",
        "and the name, for people"
    );
    assert!(
        text.contains("\"motor_torque\":203.84,"),
        "to the resolution of 1.0192 Nm: {text}"
    );
    assert!(text.contains("\"apps_travel\":0.0,"), "{text}");
    assert_eq!(json["fault_bse"], false);
    let read = mqtt::TELEMETRY.decode(&bytes).expect("reads back");
    assert_eq!(read.value.header, record.header);
    assert_eq!(read.value.telemetry.mcu_main_state, McuMainState::Run);
    assert!(same_number(
        f64::from(read.value.telemetry.motor_torque),
        f64::from(snapshot.motor_torque)
    ));

    let frame = Mcu1::decode(&[0x10, 0, 200, 0, 0, 3 << 3, 0, 0]).expect("decodes");
    let (suffix, bytes) = mqtt::encode_message(&AnyMessage::Mcu1(frame), 1.5, "can1");
    assert_eq!(suffix, mqtt::can::MCU1.suffix());
    let text = String::from_utf8(bytes.clone()).expect("UTF-8");
    let json: serde_json::Value = serde_json::from_slice(&bytes).expect("JSON");
    assert_eq!(json["ts"], 1.5);
    assert_eq!(
        json["bus"], "can1",
        "a message seen on two buses says which"
    );
    assert_eq!(
        json["mcu_main_state"], 3,
        "keys are the snake_case names, as in the store"
    );
    assert_eq!(json["mcu_main_state_label"], "RUN");
    assert_eq!(json["mcu_motor_speed"], 1024.0);
    assert!(text.contains("\"mcu_actual_torque\":203.84,"), "{text}");
    let read = mqtt::can::MCU1
        .decode(&bytes)
        .expect("the typed topic reads it");
    assert_eq!(read.value.mcu_main_state, frame.mcu_main_state);
    assert!(same_number(
        read.value.mcu_actual_torque,
        frame.mcu_actual_torque
    ));
}

proptest::proptest! {
    /// Every message of the schema, any payload: the published JSON has `ts`, `bus`, and every
    /// signal present under its store column's name with the decoded value (within float
    /// noise), each enum's name beside it.
    #[test]
    fn every_message_publishes_what_it_decoded(
        index in 0..aer::can::MESSAGES.len(),
        data in proptest::collection::vec(proptest::num::u8::ANY, 64),
    ) {
        let meta = aer::can::MESSAGES[index];
        let table = TABLES[index + 1];
        proptest::prop_assert_eq!(table.signals.len(), meta.signals.len());
        let Ok(message) = AnyMessage::decode(meta.id, meta.extended, &data[..meta.len]) else {
            return Ok(()); // a multiplexor value the schema does not know
        };
        let (_, bytes) = mqtt::encode_message(&message, 12.25, "can0");
        let published: serde_json::Value = serde_json::from_slice(&bytes).expect("valid JSON");
        proptest::prop_assert_eq!(&published["ts"], 12.25);
        proptest::prop_assert_eq!(&published["bus"], "can0");
        let mut decoded = Vec::new();
        message.visit(&mut Collect(&mut decoded));
        for (signal, value, label) in decoded {
            let key = table.columns[1 + usize::from(signal.index)].name;
            let out = &published[key];
            match out {
                serde_json::Value::Bool(b) => proptest::prop_assert_eq!(*b, value.to_f64() != 0.0),
                _ => {
                    let got = out.as_f64().expect("a number");
                    proptest::prop_assert!(
                        same_number(got, value.to_f64()),
                        "{}: {} vs {:?}", key, got, value
                    );
                }
            }
            if !signal.labels.is_empty() {
                proptest::prop_assert_eq!(
                    &published[format!("{key}_label").as_str()],
                    &serde_json::json!(label)
                );
            }
        }
    }
}

/// Every signal present: its metadata, value and label.
struct Collect<'a>(
    &'a mut Vec<(
        &'static aer::runtime::SignalMeta,
        aer::runtime::Value,
        Option<&'static str>,
    )>,
);

impl aer::runtime::SignalVisitor for Collect<'_> {
    fn signal(
        &mut self,
        meta: &'static aer::runtime::SignalMeta,
        value: aer::runtime::Value,
        label: Option<&'static str>,
    ) {
        self.0.push((meta, value, label));
    }
}
