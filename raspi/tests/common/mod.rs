//! What several of the service's test files build the same way (each uses some of it).
#![allow(dead_code)]

use aer_host::counters::Counters;
use aer_raspi::ingest::Stage;
use aer_raspi::sink::Sink;
use aer_raspi::sink::store::StoreSink;
use aer_raspi::source::Replies;
use aer_raspi::store::{self, StoreWriter, WhenFull, WriterOptions};
use std::sync::Arc;

/// The bundled session (candump -l).
pub const SESSION: &str = include_str!("../../data/session.log");

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

/// Replays the bundled session into the store at `path` (in the session open there, if any).
pub fn record_session(path: &std::path::Path) {
    let counters = Arc::new(Counters::default());
    let writer = StoreWriter::with_options(
        store::open(path).expect("store"),
        counters.clone(),
        WriterOptions {
            when_full: WhenFull::Wait,
            ..WriterOptions::default()
        },
    );
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("runtime");
    let sinks: Vec<Box<dyn Sink>> = vec![Box::new(StoreSink::new(
        writer.sender().expect("open"),
        "car1",
    ))];
    let stage = Stage::new(counters.clone(), sinks, Replies::default());
    let (stage, _) = runtime.block_on(stage.replay_all(SESSION.as_bytes(), &counters));
    drop(stage);
    writer.finish();
}
