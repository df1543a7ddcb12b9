//! The disk misbehaves; live telemetry does not notice. A store that fills up, turns read-only
//! or is locked by someone else drops rows (counted, reported) while every packet still
//! reaches MQTT; a store that works again takes rows again; a damaged store file is moved
//! aside at start-up; the raw log keeps every frame; retention keeps the store in its budget.

mod common;

use aer::mqtt::TELEMETRY;
use aer_host::formats::raw_format::SegmentReader;
use aer_host::reports::counters::Counters;
use aer_raspi::broker;
use aer_raspi::export::Format;
use aer_raspi::health::Health;
use aer_raspi::ingest::Stage;
use aer_raspi::rawlog::RawTap;
use aer_raspi::rawlog::segments;
use aer_raspi::rawlog::writer::{RawWriter, Settings};
use aer_raspi::sink::Sink;
use aer_raspi::sink::mqtt as publish;
use aer_raspi::sink::store::StoreSink;
use aer_raspi::source::Replies;
use aer_raspi::store::{self as store, Budget, Retention, StoreWriter, WriterOptions, session};
use rumqttc::{AsyncClient, Event, MqttOptions, Packet, QoS};
use rusqlite::Connection;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::mpsc;
use tokio_util::sync::CancellationToken;

const SESSION: &str = include_str!("../data/session.log");
const PACKETS: usize = 4_500;

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("a free port")
}

/// The embedded broker on a free port with a subscriber to the telemetry topic: returns the
/// publisher and a channel that receives one `()` per telemetry message.
async fn broker_and_subscriber(
    counters: &Arc<Counters>,
) -> (publish::Publisher, mpsc::UnboundedReceiver<()>) {
    let port = free_port();
    let text = broker::DEFAULT_CONFIG
        .replace("127.0.0.1:1883", &format!("127.0.0.1:{port}"))
        .replace("max_segment_size = 262144", "max_segment_size = 67108864");
    let mut config = broker::parse(&text).expect("broker config");
    config.stall_limit = Duration::from_secs(120);
    let broker = broker::start(config, counters.clone(), CancellationToken::new())
        .await
        .expect("broker");
    let mut options = MqttOptions::new("storage-faults-subscriber", "127.0.0.1", port);
    options.set_max_packet_size(64 * 1024, 64 * 1024);
    let (client, mut events) = AsyncClient::new(options, 100);
    client
        .subscribe(TELEMETRY.path("aer/car1"), QoS::AtMostOnce)
        .await
        .expect("subscribe");
    let (seen_tx, seen) = mpsc::unbounded_channel();
    let (subscribed_tx, subscribed) = tokio::sync::oneshot::channel();
    tokio::spawn(async move {
        let _client = client;
        let mut subscribed_tx = Some(subscribed_tx);
        while let Ok(event) = events.poll().await {
            match event {
                Event::Incoming(Packet::SubAck(_)) => {
                    if let Some(tx) = subscribed_tx.take() {
                        let _ = tx.send(());
                    }
                }
                Event::Incoming(Packet::Publish(_)) if seen_tx.send(()).is_err() => return,
                _ => {}
            }
        }
    });
    tokio::time::timeout(Duration::from_secs(10), subscribed)
        .await
        .expect("subscribed in time")
        .expect("subscriber alive");
    let (publisher, driver) = publish::embedded(
        broker.link,
        broker.spares,
        200_000,
        "aer/car1".into(),
        counters.clone(),
        Arc::default(),
    );
    let (up_tx, mut up) = tokio::sync::watch::channel(false);
    tokio::spawn(publish::drive(driver, up_tx));
    let _ = tokio::time::timeout(Duration::from_secs(10), up.wait_for(|u| *u)).await;
    (publisher, seen)
}

/// Waits (bounded) until `count` messages arrived.
async fn receive(seen: &mut mpsc::UnboundedReceiver<()>, count: usize) -> usize {
    let mut received = 0;
    let _ = tokio::time::timeout(Duration::from_secs(60), async {
        while received < count && seen.recv().await.is_some() {
            received += 1;
        }
    })
    .await;
    received
}

/// Replays the session through MQTT and a store whose connection `spoil` breaks first.
async fn session_with_a_failing_store(
    spoil: impl FnOnce(&Connection),
) -> (
    aer_host::reports::counters::ServiceCounters,
    usize,
    Option<String>,
) {
    let dir = tempfile::tempdir().expect("temp dir");
    let counters = Arc::new(Counters::default());
    let health = Arc::new(Health::default());
    let db = store::open(&dir.path().join("s.sqlite")).expect("store");
    spoil(&db);
    let watched = health.clone();
    let writer = StoreWriter::with_options(
        db,
        counters.clone(),
        WriterOptions {
            health: health.clone(),
            queue_rows: Some(2_000),
            ..WriterOptions::default()
        },
    );
    let (publisher, mut seen) = broker_and_subscriber(&counters).await;
    let sinks: Vec<Box<dyn Sink>> = vec![
        Box::new(publisher.clone()),
        Box::new(StoreSink::new(writer.sender().expect("open"), "car1")),
    ];
    let stage = Stage::new(counters.clone(), sinks, Replies::default());
    let (stage, _) = stage.replay_all(SESSION.as_bytes(), &counters).await;
    drop(stage);
    let received = receive(&mut seen, PACKETS).await;
    // The writer commits once a second: wait (bounded) for its first attempt.
    let error = tokio::time::timeout(Duration::from_secs(10), async {
        loop {
            if let Some(error) = watched.store.error() {
                return error;
            }
            tokio::task::yield_now().await;
        }
    })
    .await
    .ok();
    tokio::task::spawn_blocking(move || writer.finish())
        .await
        .expect("writer stops");
    (counters.snapshot(), received, error)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn live_telemetry_keeps_flowing_when_the_disk_is_full() {
    // A file that may not grow at all: SQLite reports "database or disk is full" exactly as
    // on a full SD card.
    let (counters, received, error) = session_with_a_failing_store(|db| {
        let pages: i64 = db
            .query_row("PRAGMA page_count", [], |r| r.get(0))
            .expect("pages");
        db.pragma_update(None, "max_page_count", pages)
            .expect("limit");
    })
    .await;
    assert_eq!(received, PACKETS, "every packet reached MQTT");
    assert!(counters.store_errors > 0, "{counters:?}");
    assert!(counters.store_dropped > 0, "{counters:?}");
    assert_eq!(
        counters.stored + counters.store_dropped,
        counters.packets + counters.messages,
        "every row is stored or counted as dropped"
    );
    let error = error.expect("the failure is reported");
    assert!(error.contains("full"), "{error}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn live_telemetry_keeps_flowing_when_the_disk_turns_read_only() {
    let (counters, received, error) = session_with_a_failing_store(|db| {
        db.pragma_update(None, "query_only", true)
            .expect("read-only");
    })
    .await;
    assert_eq!(received, PACKETS);
    assert_eq!(counters.stored, 0);
    assert_eq!(counters.store_dropped, counters.packets + counters.messages);
    assert!(error.is_some_and(|e| e.contains("readonly") || e.contains("read-only")));
}

#[test]
fn a_store_that_works_again_takes_rows_again_and_clears_its_error() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("s.sqlite");
    let counters = Arc::new(Counters::default());
    let health = Arc::new(Health::default());
    // Someone else holds the write lock: every commit fails with "database is locked".
    let other = store::open(&path).expect("store");
    other.execute_batch("BEGIN EXCLUSIVE").expect("lock");
    let writer = StoreWriter::with_options(
        store::open(&path).expect("store"),
        counters.clone(),
        WriterOptions {
            health: health.clone(),
            ..WriterOptions::default()
        },
    );
    let sender = writer.sender().expect("open");
    let row = common::telemetry_row;
    for seq in 0..10 {
        assert!(sender.send(row(seq)));
    }
    // Wait (bounded) until the failure is reported, then release the lock.
    let deadline = std::time::Instant::now() + Duration::from_secs(10);
    while health.store.error().is_none() && std::time::Instant::now() < deadline {
        std::thread::yield_now();
    }
    assert!(health.store.error().is_some_and(|e| e.contains("locked")));
    other.execute_batch("COMMIT").expect("unlock");
    drop(sender);
    writer.finish();
    let snapshot = counters.snapshot();
    assert_eq!((snapshot.stored, snapshot.store_dropped), (10, 0));
    assert!(snapshot.store_errors >= 1);
    assert_eq!(
        health.store.error(),
        None,
        "the error clears once writes work"
    );
}

#[test]
fn a_damaged_store_is_moved_aside_and_a_fresh_one_started() {
    let dir = tempfile::tempdir().expect("temp dir");
    // Garbage where the store should be.
    let garbage = dir.path().join("garbage.sqlite");
    std::fs::write(&garbage, vec![0x5A; 10_000]).expect("write");
    let (db, report) = store::open_or_recover(&garbage).expect("starts anyway");
    let report = report.expect("the recovery is reported");
    assert!(report.contains("damaged"), "{report}");
    let aside: Vec<_> = std::fs::read_dir(dir.path())
        .expect("dir")
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .filter(|name| name.starts_with("garbage.sqlite.damaged-"))
        .collect();
    assert_eq!(aside.len(), 1, "the damaged file is kept for inspection");
    let tables: i64 = db
        .query_row(
            "SELECT count(*) FROM sqlite_master WHERE type = 'table'",
            [],
            |r| r.get(0),
        )
        .expect("fresh store");
    assert!(tables > 10);

    // A store cut short (a crash while copying it, a bad SD card sector).
    let truncated = dir.path().join("truncated.sqlite");
    {
        let db = store::open(&truncated).expect("store");
        db.execute_batch(
            "CREATE TABLE filler(x BLOB); WITH RECURSIVE n(i) AS (SELECT 1 UNION ALL SELECT i + 1 FROM n WHERE i < 200) INSERT INTO filler SELECT randomblob(2000) FROM n;",
        )
        .expect("fill");
        db.query_row("PRAGMA wal_checkpoint(TRUNCATE)", [], |_| Ok(()))
            .expect("checkpoint");
    }
    let len = std::fs::metadata(&truncated).expect("size").len();
    let file = std::fs::OpenOptions::new()
        .write(true)
        .open(&truncated)
        .expect("open");
    file.set_len(len / 2).expect("truncate");
    drop(file);
    assert!(matches!(
        store::open(&truncated),
        Err(store::StoreError::Damaged { .. })
    ));
    let (_, report) = store::open_or_recover(&truncated).expect("starts anyway");
    assert!(report.is_some());
}

#[test]
fn the_raw_log_keeps_every_frame_and_reads_back_as_the_log() {
    let dir = tempfile::tempdir().expect("temp dir");
    let counters = Arc::new(Counters::default());
    let health = Arc::new(Health::default());
    let settings = Settings {
        dir: dir.path().join("raw"),
        segment_bytes: 32 * 1024,
        segment_age: Duration::from_secs(3_600),
        sync_every: Duration::from_millis(100),
        budget: segments::Budget {
            max_bytes: u64::MAX,
            max_age: None,
            min_free_bytes: 0,
        },
    };
    let (writer, blocks) = RawWriter::start(settings, counters.clone(), health).expect("raw log");
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("runtime");
    let stage = Stage::new(counters.clone(), Vec::new(), Replies::default())
        .with_raw_log(RawTap::new(blocks, counters.clone()));
    let (stage, stats) = runtime.block_on(stage.replay_all(SESSION.as_bytes(), &counters));
    drop(stage);
    writer.finish();
    let snapshot = counters.snapshot();
    assert_eq!(snapshot.raw_frames, stats.frames);
    assert_eq!(snapshot.raw_dropped, 0);
    // Several segments (32 KiB each), which together are the log, line for line.
    let segments = segments::list(&dir.path().join("raw"));
    assert!(segments.len() > 3, "{} segments", segments.len());
    // Compressed: what keeps a season on the card (docs/pi-service.md, "Disk budget").
    let bytes: u64 = segments.iter().map(|(_, len)| len).sum();
    eprintln!(
        "raw log: {bytes} bytes for {} frames ({:.2} per frame)",
        stats.frames,
        bytes as f64 / stats.frames as f64
    );
    assert!(
        bytes < stats.frames * 4,
        "{bytes} bytes for {} frames",
        stats.frames
    );
    let mut lines = Vec::new();
    for (path, _) in &segments {
        let data = std::fs::read(path).expect("segment");
        for frame in SegmentReader::new(&data).expect("header") {
            lines.push(frame.expect("undamaged").to_candump());
        }
    }
    let original: Vec<&str> = SESSION.lines().filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(lines.len(), original.len());
    assert!(
        lines
            .iter()
            .zip(&original)
            .all(|(ours, theirs)| ours == theirs)
    );

    // `aer-raspi raw-export --format`: the segments as the bus tools' files, which python-can
    // (BLF, ASC) and asammdf (MF4) read back frame for frame as the log.
    let out = dir.path().join("bus-tools");
    std::fs::create_dir_all(&out).expect("folder");
    for (format, name) in [
        (Format::Blf, "session.blf"),
        (Format::Asc, "session.asc"),
        (Format::Mf4, "session.mf4"),
    ] {
        let written =
            aer_raspi::export::raw_log::to_file(&[dir.path().join("raw")], format, &out.join(name))
                .expect("written");
        assert_eq!(written.rows, original.len(), "{format:?}");
    }
    // Segments with no frames write nothing and say so.
    let empty = dir.path().join("no-segments");
    std::fs::create_dir_all(&empty).expect("folder");
    let nothing = aer_raspi::export::raw_log::to_file(&[empty], Format::Blf, &out.join("none.blf"))
        .expect_err("nothing to write");
    assert!(nothing.to_string().contains("no frames in"), "{nothing}");
    assert!(!out.join("none.blf").exists());
    let checked = common::check_frames(&common::session_log(), &out, None);
    assert!(
        checked.is_empty() || checked.contains(&format!("{} frames equal", original.len())),
        "{checked}"
    );
}

fn telemetry_rows(db: &Connection) -> i64 {
    db.query_row("SELECT count(*) FROM telemetry", [], |r| r.get(0))
        .expect("count")
}

/// Bytes of the store's pages in use.
fn used(db: &Connection) -> u64 {
    let pragma = |name: &str| -> i64 {
        db.query_row(&format!("PRAGMA {name}"), [], |r| r.get(0))
            .expect("pragma")
    };
    ((pragma("page_count") - pragma("freelist_count")) * pragma("page_size")) as u64
}

#[test]
fn retention_keeps_the_store_within_its_budget_forwarded_rows_first() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("s.sqlite");
    common::record_session(&path);
    let db = store::open(&path).expect("store");
    assert_eq!(telemetry_rows(&db), PACKETS as i64);
    // The first 1,000 telemetry rows were forwarded.
    aer_raspi::forward::advance(&db, 0, 1_000).expect("cursor");
    let before = used(&db);
    let budget = Budget {
        max_bytes: before * 9 / 10,
        max_age: None,
        min_free_bytes: 0,
        interval: Duration::ZERO,
    };
    let pruned = Retention::new(path.clone(), budget)
        .with_free_space(|_| None)
        .prune(&db)
        .expect("prune");
    assert!(pruned.rows > 0);
    assert!(used(&db) <= before * 9 / 10, "within the budget");
    let oldest: i64 = db
        .query_row("SELECT min(id) FROM telemetry", [], |r| r.get(0))
        .expect("oldest");
    assert!(oldest > 1_000, "the forwarded telemetry went first");
    // Age: everything older than a second goes (the session is from the past).
    let by_age = Budget {
        max_bytes: u64::MAX,
        max_age: Some(Duration::from_secs(1)),
        min_free_bytes: 0,
        interval: Duration::ZERO,
    };
    Retention::new(path.clone(), by_age)
        .with_free_space(|_| None)
        .prune(&db)
        .expect("prune");
    assert_eq!(telemetry_rows(&db), 0);
}

#[test]
fn the_free_space_floor_never_takes_the_session_being_recorded() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("s.sqlite");
    let begin = |source: &str| {
        let db = store::open(&path).expect("store");
        session::begin(&db, &session::Metadata::default(), source, 0).expect("session")
    };
    let last_session = begin("earlier");
    common::record_session(&path);
    let current = begin("live");
    common::record_session(&path);
    let db = store::open(&path).expect("store");
    let current_rows = session::rows(&db, current, "telemetry")
        .expect("rows")
        .expect("the session has telemetry");
    assert_eq!(current_rows.1 - current_rows.0 + 1, PACKETS as i64);
    let floor = 1 << 30;
    let at_floor = Budget {
        max_bytes: u64::MAX,
        max_age: None,
        min_free_bytes: floor,
        interval: Duration::ZERO,
    };

    // A card smaller than the floor: removing the earlier session cannot lift it, so nothing
    // goes and the disk is reported low.
    let pruned = Retention::new(path.clone(), at_floor.clone())
        .with_free_space(|_| Some(0))
        .prune(&db)
        .expect("prune");
    assert_eq!(pruned.rows, 0, "nothing pruned that could not help");
    let why = pruned.disk_low.expect("the disk is reported low");
    assert!(why.contains("session being recorded is kept"), "{why}");
    assert_eq!(telemetry_rows(&db), 2 * PACKETS as i64);

    // Short by a quarter of the store: the earlier session's oldest rows go, enough of them
    // to reach the floor, and none of the current session's.
    let short = used(&db) / 4;
    let pruned = Retention::new(path.clone(), at_floor.clone())
        .with_free_space(move |_| Some(floor - short))
        .prune(&db)
        .expect("prune");
    assert_eq!(pruned.disk_low, None, "the floor is reached");
    assert!(pruned.rows > 0);
    let oldest: i64 = db
        .query_row("SELECT min(id) FROM telemetry", [], |r| r.get(0))
        .expect("oldest");
    assert!(
        oldest > 1 && oldest < current_rows.0,
        "only earlier rows went"
    );
    let earlier = session::rows(&db, last_session, "telemetry")
        .expect("rows")
        .expect("recorded");
    assert!(oldest <= earlier.1, "the earlier session is not all gone");
    let kept: i64 = db
        .query_row(
            "SELECT count(*) FROM telemetry WHERE id >= ?1",
            [current_rows.0],
            |r| r.get(0),
        )
        .expect("count");
    assert_eq!(kept, PACKETS as i64, "the current session keeps every row");

    // Shorter than everything earlier can give: nothing goes, the disk is low.
    let left = telemetry_rows(&db);
    let pruned = Retention::new(path.clone(), at_floor)
        .with_free_space(move |_| Some(floor / 2))
        .prune(&db)
        .expect("prune");
    assert!(pruned.disk_low.is_some());
    assert_eq!((pruned.rows, telemetry_rows(&db)), (0, left));
}
