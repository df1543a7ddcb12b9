//! What several of the service's test files build the same way.

use aer_raspi::sink::store;

/// A default telemetry row of `car1` with sequence `seq`, stamped 1 ms + `seq` us.
pub fn telemetry_row(seq: u16) -> store::Row {
    store::Row {
        car_id: "car1".into(),
        ts_us: 1_000 + u64::from(seq),
        data: store::RowData::Telemetry {
            header: aer::telemetry::TelemetryHeader {
                sequence: seq,
                timestamp_us: 0,
            },
            telemetry: aer::telemetry::Telemetry::zeroed(),
        },
    }
}
