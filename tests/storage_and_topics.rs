//! The generated TDengine schema and MQTT topics: what the Pi creates, migrates and publishes.

use aer::can::{Mcu1, McuMainState};
use aer::mqtt::{self, Sample, TelemetryRecord};
use aer::tdengine::{self, SUPER_TABLES};
use aer::telemetry::{Telemetry, TelemetryHeader};

#[test]
fn the_database_fits_a_raspberry_pi() {
    let sql = tdengine::CREATE_DATABASE;
    for option in ["PRECISION 'us'", "VGROUPS 1", "BUFFER 16"] {
        assert!(sql.contains(option), "{sql}");
    }
    assert_eq!(tdengine::DATABASE, "aer");
}

#[test]
fn telemetry_table_has_a_lossless_typed_column_per_field() {
    let t = &tdengine::TELEMETRY;
    assert_eq!(t.columns[0].name, "ts");
    assert_eq!(t.columns[0].sql_type, "TIMESTAMP");
    assert_eq!(t.columns.len(), 3 + Telemetry::FIELDS.len());
    let ty = |name: &str| {
        t.columns
            .iter()
            .find(|c| c.name == name)
            .map(|c| c.sql_type)
    };
    assert_eq!(
        ty("motor_temp"),
        Some("SMALLINT"),
        "offset -40 on a u8: exact integers"
    );
    assert_eq!(ty("fault_bse"), Some("BOOL"));
    assert_eq!(
        ty("mcu_main_state"),
        Some("TINYINT UNSIGNED"),
        "enums as their raw value"
    );
    assert_eq!(ty("shocktravel1"), Some("FLOAT"));
    assert_eq!(
        t.tags.iter().map(|c| c.name).collect::<Vec<_>>(),
        ["car_id", "schema_fingerprint"]
    );
    let marks = t.insert.matches('?').count();
    assert_eq!(marks, 1 + t.tags.len() + t.columns.len(), "{}", t.insert);
    assert!(
        t.create
            .starts_with("CREATE STABLE IF NOT EXISTS `telemetry` (`ts` TIMESTAMP")
    );
}

#[test]
fn every_can_message_has_a_super_table() {
    assert_eq!(SUPER_TABLES.len(), 1 + aer::can::MESSAGES.len());
    let mcu1 = SUPER_TABLES
        .iter()
        .find(|t| t.name == "can_mcu1")
        .expect("MCU1 table");
    assert_eq!(mcu1.columns.len(), 1 + Mcu1::META.signals.len());
    assert!(
        mcu1.columns
            .iter()
            .any(|c| c.name == "mcu_motor_speed" && c.sql_type == "DOUBLE")
    );
    assert!(mcu1.tags.iter().any(|c| c.name == "bus"));
    let script = include_str!("../generated/sql/tdengine.sql");
    for table in SUPER_TABLES {
        assert!(
            script.contains(table.create),
            "{} missing from the .sql script",
            table.name
        );
    }
}

#[test]
fn a_live_database_lacking_columns_gets_alter_statements() {
    let t = &tdengine::TELEMETRY;
    let existing: Vec<&str> = t
        .columns
        .iter()
        .map(|c| c.name)
        .filter(|n| *n != "shocktravel4")
        .collect();
    let missing: Vec<_> = t.missing_columns(&existing).collect();
    assert_eq!(missing.len(), 1);
    assert_eq!(
        t.add_column_sql(missing[0]),
        "ALTER STABLE `telemetry` ADD COLUMN `shocktravel4` FLOAT"
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

#[test]
fn payloads_are_flat_json_with_ts_in_seconds() {
    let (_, mut snapshot) = Telemetry::unpack(&{
        let mut b = [0u8; Telemetry::LEN];
        b[..4].copy_from_slice(&aer::telemetry::TELEMETRY_FINGERPRINT.to_le_bytes());
        b
    })
    .expect("valid");
    snapshot.mcu_main_state = McuMainState::Run;
    snapshot.motor_speed = 1234.5;
    let sample = Sample {
        ts: 1_763_683_200.25,
        value: TelemetryRecord {
            header: TelemetryHeader {
                sequence: 9,
                timestamp_us: 77,
            },
            telemetry: snapshot,
        },
    };
    let bytes = mqtt::TELEMETRY.encode(&sample).expect("serializes");
    let json: serde_json::Value = serde_json::from_slice(&bytes).expect("JSON");
    assert_eq!(json["ts"], 1_763_683_200.25);
    assert_eq!(json["sequence"], 9);
    assert_eq!(json["motor_speed"], 1234.5);
    assert_eq!(json["mcu_main_state"], 3, "enums as numbers, for plots");
    assert_eq!(json["fault_bse"], false);
    assert_eq!(mqtt::TELEMETRY.decode(&bytes).expect("reads back"), sample);

    let frame = Mcu1::decode(&[0x10, 0, 100, 0, 0, 3 << 3, 0, 0]).expect("decodes");
    let bytes = mqtt::can::MCU1
        .encode(&Sample {
            ts: 1.5,
            value: frame,
        })
        .expect("serializes");
    let json: serde_json::Value = serde_json::from_slice(&bytes).expect("JSON");
    assert_eq!(
        json["MCU_MainState"], 3,
        "CAN payload keys are the DBC signal names"
    );
    assert_eq!(json["MCU_MotorSpeed"], 1024.0);
    assert_eq!(json["ts"], 1.5);
}
