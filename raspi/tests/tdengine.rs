//! Against a real TDengine (none can be installed on the build machines): set
//! `AER_TDENGINE_DSN=taos+ws://host:6041` to run it. The forwarder creates the database and
//! super tables, moves a replayed session, and the row counts match the local store.

use aer_host::reports::counters::Counters;
use aer_raspi::config::TdengineConfig;
use aer_raspi::forward;
use aer_raspi::ingest::Stage;
use aer_raspi::sink::Sink;
use aer_raspi::sink::store::StoreSink;
use aer_raspi::source::Replies;
use aer_raspi::store;
use std::sync::Arc;
use std::time::Duration;
use taos::{AsyncFetchable, AsyncQueryable, AsyncTBuilder, TaosBuilder};
use tokio_util::sync::CancellationToken;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_forwarder_moves_every_row_into_tdengine() {
    let Ok(dsn) = std::env::var("AER_TDENGINE_DSN") else {
        eprintln!(
            "SKIPPED: AER_TDENGINE_DSN is not set (no TDengine server on this machine); the SQL is unit-tested in src/sql.rs"
        );
        return;
    };
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("s.sqlite");
    let counters = Arc::new(Counters::default());
    let writer = store::StoreWriter::start(store::open(&path).expect("store"), counters.clone());
    // A car id of its own, so earlier runs' rows do not count.
    let car = format!("it{}", std::process::id());
    let sinks: Vec<Box<dyn Sink>> = vec![Box::new(StoreSink::new(
        writer.sender().expect("store open"),
        &car,
    ))];
    let stage = Stage::new(counters.clone(), sinks, Replies::default());
    let log = include_str!("../data/session.log");
    let (stage, _) = stage.replay_all(log.as_bytes(), &counters).await;
    drop(stage);
    writer.finish();
    let stored = counters.snapshot().stored;

    let cancel = CancellationToken::new();
    let config = TdengineConfig {
        enabled: true,
        dsn: dsn.clone(),
        ..TdengineConfig::default()
    };
    let forwarder = tokio::spawn(forward::run(
        config,
        path,
        counters.clone(),
        Arc::default(),
        cancel.clone(),
    ));
    tokio::time::timeout(Duration::from_secs(120), async {
        while counters.snapshot().forwarded < stored {
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
    })
    .await
    .expect("every stored row forwarded within 2 minutes");
    cancel.cancel();
    let _ = forwarder.await;

    let taos = TaosBuilder::from_dsn(&dsn)
        .expect("dsn")
        .build()
        .await
        .expect("connect");
    let rows = taos
        .query(format!(
            "SELECT count(*) FROM `{}`.`telemetry` WHERE car_id = '{car}'",
            TdengineConfig::default().database
        ))
        .await
        .expect("query")
        .to_records()
        .await
        .expect("rows");
    let count = rows
        .first()
        .and_then(|r| r.first())
        .map(|v| v.to_string().unwrap_or_default());
    assert_eq!(count.as_deref(), Some("4500"));
}
