//! The forwarder against a fake TDengine that refuses what the real one refuses: a statement
//! with a tag longer than its VARCHAR is refused whole. A poisoned batch must not stall the
//! table: the bad rows are found, set aside and counted, everything else goes in, and the
//! cursor moves on. An outage sets nothing aside.

use aer::tables::{ColumnType, TABLES};
use aer_host::reports::counters::{Counters, ServiceCounters};
use aer_raspi::config::TdengineConfig;
use aer_raspi::forward::{Destination, Worker, next_batch};
use aer_raspi::health::Health;
use aer_raspi::ingest::Stage;
use aer_raspi::sink::Sink;
use aer_raspi::sink::store::StoreSink;
use aer_raspi::source::Replies;
use aer_raspi::store::{self as store, StoreWriter, WhenFull, WriterOptions};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio_util::sync::CancellationToken;

const SESSION: &str = include_str!("../data/session.log");

/// What the fake database holds and how it behaves.
#[derive(Default)]
struct Fake {
    down: bool,
}

#[derive(Clone, Default)]
struct FakeTdengine(Arc<Mutex<Fake>>);

/// The string literals of every `TAGS (...)` clause, each with its table.
fn tag_literals(sql: &str) -> Vec<(String, Vec<String>)> {
    let mut found = Vec::new();
    let mut rest = sql;
    while let Some(at) = rest.find(" USING `") {
        rest = &rest[at + 8..];
        let table = rest.split('`').nth(2).unwrap_or_default().to_owned();
        let Some(tags) = rest.find("TAGS (").map(|t| &rest[t + 6..]) else {
            break;
        };
        let tags = tags.split(')').next().unwrap_or_default();
        let literals = tags
            .split(", ")
            .filter(|t| t.starts_with('\''))
            .map(|t| t.trim_matches('\'').to_owned())
            .collect();
        found.push((table, literals));
    }
    found
}

impl Destination for FakeTdengine {
    async fn exec(&mut self, sql: &str) -> Result<(), String> {
        let fake = self.0.lock().expect("fake");
        if fake.down {
            return Err("connection reset".into());
        }
        for (table, literals) in tag_literals(sql) {
            let Some(table) = TABLES.iter().find(|t| t.name == table) else {
                return Err(format!("Table does not exist: {table}"));
            };
            let widths = table.tags.iter().filter_map(|c| match c.ty {
                ColumnType::VarChar(n) => Some(usize::from(n)),
                _ => None,
            });
            for (literal, width) in literals.iter().zip(widths) {
                if literal.len() > width {
                    // TDengine's answer, and it refuses the whole statement.
                    return Err("Value too long for column/tag".into());
                }
            }
        }
        Ok(())
    }

    async fn alive(&mut self) -> bool {
        !self.0.lock().expect("fake").down
    }
}

/// A store holding the session's first seconds, some frames on a bus whose name is too long
/// for TDengine's 16-byte tag.
async fn poisoned_store(dir: &std::path::Path) -> std::path::PathBuf {
    let path = dir.join("s.sqlite");
    let counters = Arc::new(Counters::default());
    let writer = StoreWriter::with_options(
        store::open(&path).expect("store"),
        counters.clone(),
        WriterOptions {
            when_full: WhenFull::Wait,
            ..WriterOptions::default()
        },
    );
    let lines: Vec<String> = SESSION
        .lines()
        .take(3_000)
        .enumerate()
        .map(|(i, line)| {
            // Every 500th line comes from an interface with a 26-byte name.
            if i % 500 == 7 {
                line.replacen(" can1 ", " a-very-long-interface-name ", 1)
                    .replacen(" can0 ", " a-very-long-interface-name ", 1)
            } else {
                line.to_owned()
            }
        })
        .collect();
    let sinks: Vec<Box<dyn Sink>> = vec![Box::new(StoreSink::new(
        writer.sender().expect("open"),
        "car1",
    ))];
    let stage = Stage::new(counters.clone(), sinks, Replies::default());
    let text = lines.join("\n");
    let (stage, _) = stage.replay_all(text.as_bytes(), &counters).await;
    drop(stage);
    tokio::task::spawn_blocking(move || writer.finish())
        .await
        .expect("writer");
    path
}

/// Rows waiting after the cursor, in every table.
fn waiting(path: &std::path::Path) -> usize {
    let db = store::open(path).expect("store");
    (0..TABLES.len())
        .map(|t| next_batch(&db, t, 100_000).expect("batch").rows.len())
        .sum()
}

fn total_rows(path: &std::path::Path) -> usize {
    let db = store::open(path).expect("store");
    TABLES
        .iter()
        .map(|t| {
            db.query_row(&format!("SELECT count(*) FROM \"{}\"", t.name), [], |r| {
                r.get::<_, i64>(0)
            })
            .expect("count") as usize
        })
        .sum()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_poisoned_batch_is_split_its_bad_rows_set_aside_and_the_rest_forwarded() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = poisoned_store(dir.path()).await;
    let total = total_rows(&path);
    let poisoned: usize = {
        let db = store::open(&path).expect("store");
        TABLES
            .iter()
            .filter(|t| t.tags.iter().any(|c| c.name == "bus"))
            .map(|t| {
                db.query_row(
                    &format!(
                        "SELECT count(*) FROM \"{}\" WHERE bus = 'a-very-long-interface-name'",
                        t.name
                    ),
                    [],
                    |r| r.get::<_, i64>(0),
                )
                .expect("count") as usize
            })
            .sum()
    };
    assert!(poisoned > 0 && poisoned < total);

    let fake = FakeTdengine::default();
    let counters = Counters::default();
    let health = Health::default();
    // Runs until every row has been dealt with (bounded), then stops.
    let finished = forward_until(
        &path,
        &TdengineConfig::default(),
        &fake,
        &counters,
        &health,
        |c| c.forwarded + c.forward_set_aside >= total as u64,
    )
    .await;
    assert!(finished, "the forwarder stalled: {:?}", counters.snapshot());

    let snapshot = counters.snapshot();
    assert_eq!(
        snapshot.forward_set_aside as usize, poisoned,
        "exactly the bad rows"
    );
    assert_eq!(snapshot.forwarded as usize, total - poisoned);
    assert_eq!(waiting(&path), 0, "the cursor moved past them");
    let db = store::open(&path).expect("store");
    let (kept, reason): (i64, String) = db
        .query_row(
            "SELECT count(*), max(error) FROM forward_set_aside",
            [],
            |r| Ok((r.get(0)?, r.get(1)?)),
        )
        .expect("set aside");
    assert_eq!(kept as usize, poisoned, "kept, with TDengine's reason");
    assert!(reason.contains("too long"), "{reason}");
    let problem = health.forward_refused.error().expect("reported");
    assert!(problem.contains("set aside"), "{problem}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_outage_sets_nothing_aside_and_moves_no_cursor() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = poisoned_store(dir.path()).await;
    let before = waiting(&path);
    let fake = FakeTdengine::default();
    fake.0.lock().expect("fake").down = true;
    let counters = Counters::default();
    let health = Health::default();
    let config = TdengineConfig {
        dsn: "taos+ws://root:s3cret@pit:6041".into(),
        ..TdengineConfig::default()
    };
    let noticed = forward_until(&path, &config, &fake, &counters, &health, |c| {
        c.forward_errors > 0
    })
    .await;
    assert!(noticed, "the outage is noticed");
    assert_eq!(counters.snapshot().forward_set_aside, 0);
    assert_eq!(waiting(&path), before, "every row still waits");
    let problem = health.forward.error().expect("reported");
    assert!(
        problem.contains("unreachable") && !problem.contains("s3cret"),
        "{problem}"
    );
}

/// Runs a worker over every table against `fake` until `done` holds for the counters, then
/// stops it; false if that did not happen within a minute.
async fn forward_until(
    path: &std::path::Path,
    config: &TdengineConfig,
    fake: &FakeTdengine,
    counters: &Counters,
    health: &Health,
    done: impl Fn(&ServiceCounters) -> bool,
) -> bool {
    let worker = Worker {
        config,
        tables: (0..TABLES.len()).collect(),
        counters,
        health,
    };
    let cancel = CancellationToken::new();
    let connect = || {
        let fake = fake.clone();
        async move { Ok::<_, String>(fake) }
    };
    let run = worker.run(path, connect, &cancel);
    let watch = async {
        while !done(&counters.snapshot()) {
            tokio::task::yield_now().await;
        }
        cancel.cancel();
    };
    tokio::time::timeout(Duration::from_secs(60), async {
        tokio::join!(run, watch);
    })
    .await
    .is_ok()
}
