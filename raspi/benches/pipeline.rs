//! Pipeline throughput: the bundled session (4,500 packets and every other frame on both
//! buses) through the ingest stage (ISO-TP, the generated decoders) to the sinks (published in
//! process into the embedded broker, written to the SQLite store), against today's design
//! (serde_json of the whole struct plus one line-protocol string per packet,
//! vehicle-facts.md) on the same packets. The `ingest` figures start from parsed frames; the
//! `replay` figure adds the replay source (reading the log's text) and its channel; the `raw
//! log` figure adds the black-box raw log of every frame (encoded by ingest, written and
//! synced by its thread), as the service runs by default.
//!
//! Run on one core (pipeline, store writer, MQTT client and broker share it):
//! `taskset -c 0 cargo bench -p aer-raspi --bench pipeline`.

use aer::telemetry::Telemetry;
use aer_host::config::BrokerConfig;
use aer_host::decode::decode_log;
use aer_host::formats::candump::parse_line;
use aer_host::reports::counters::Counters;
use aer_raspi::broker;
use aer_raspi::health::Health;
use aer_raspi::ingest::Stage;
use aer_raspi::rawlog::RawTap;
use aer_raspi::rawlog::segments::Budget;
use aer_raspi::rawlog::writer::{RawWriter, Settings};
use aer_raspi::sink::Sink;
use aer_raspi::sink::mqtt as publish;
use aer_raspi::sink::store::StoreSink;
use aer_raspi::source::{BusNames, Input, Replies};
use aer_raspi::store;
use criterion::{BatchSize, Criterion, Throughput, criterion_group, criterion_main};
use std::fmt::Write as _;
use std::hint::black_box;
use std::sync::Arc;
use std::time::Duration;
use tokio_util::sync::CancellationToken;

const SESSION: &str = include_str!("../data/session.log");
/// Messages the broker queue may hold: the benchmark publishes a whole session at once.
const QUEUE: usize = 400_000;

/// The log's lines as a source hands them on: bus announcements and parsed frames.
fn inputs(log: &str) -> Vec<Input> {
    let mut buses = BusNames::default();
    let mut inputs = Vec::new();
    for line in log.lines() {
        let mut announced = None;
        let parsed = parse_line(line, |name| {
            let (index, announcement) = buses.index(name);
            announced = announcement;
            index
        });
        if let Ok(frame) = parsed {
            inputs.extend(announced);
            inputs.push(Input::Frame(frame));
        }
    }
    inputs
}

/// Today's Pi: one JSON document of the whole struct (with `ts` in ms) and one line-protocol
/// string with every field as a float.
fn todays_design(ts_us: u64, telemetry: &Telemetry, json: &mut String, line: &mut String) {
    #[derive(serde::Serialize)]
    struct Today<'a> {
        ts: u64,
        #[serde(flatten)]
        telemetry: &'a Telemetry,
    }
    json.clear();
    json.push_str(
        &serde_json::to_string(&Today {
            ts: ts_us / 1_000,
            telemetry,
        })
        .unwrap_or_default(),
    );
    line.clear();
    line.push_str("telemetry,car=car1 ");
    struct Fields<'a>(&'a mut String, bool);
    impl aer::runtime::SignalVisitor for Fields<'_> {
        fn signal(
            &mut self,
            s: &'static aer::runtime::SignalMeta,
            v: aer::runtime::Value,
            _: Option<&'static str>,
        ) {
            if self.1 {
                self.0.push(',');
            }
            self.1 = true;
            let _ = write!(self.0, "{}={}", s.name, v.to_f64() as f32);
        }
    }
    telemetry.visit(&mut Fields(line, false));
    let _ = write!(line, " {}", ts_us * 1_000);
}

fn bench(c: &mut Criterion) {
    let packets: Vec<(u64, Telemetry)> = decode_log(SESSION)
        .packets
        .into_iter()
        .map(|(ts_us, _, telemetry)| (ts_us, telemetry))
        .collect();
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .expect("runtime");
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("port");
    let text = broker::DEFAULT_CONFIG.replace("127.0.0.1:1883", &format!("127.0.0.1:{port}"));
    let counters = Arc::new(Counters::default());
    let mqtt = BrokerConfig {
        port,
        ..BrokerConfig::default()
    };
    // Ours publishes as the service does, in process into the embedded broker; today's Pi
    // publishes with rumqttc over loopback TCP to its embedded broker (through the gate, so
    // outside the topics only the service may publish under).
    let (publisher, today_publisher) = runtime.block_on(async {
        let config = broker::parse(&text).expect("broker config");
        let broker = broker::start(config, counters.clone(), CancellationToken::new())
            .await
            .expect("broker");
        let (publisher, driver) = publish::embedded(
            broker.link,
            broker.spares,
            QUEUE,
            "aer/car1".into(),
            counters.clone(),
            Arc::default(),
        );
        tokio::spawn(publish::drive(driver, tokio::sync::watch::channel(false).0));
        let (today, driver) =
            publish::connect(&mqtt, QUEUE, "today", "today/car1".into(), counters.clone())
                .expect("no TLS to set up");
        let (up_tx, mut up) = tokio::sync::watch::channel(false);
        tokio::spawn(publish::drive(driver, up_tx));
        let _ = tokio::time::timeout(Duration::from_secs(10), up.wait_for(|u| *u)).await;
        (publisher, today)
    });
    let dir = tempfile::tempdir().expect("temp dir");
    // The CCM's packets alone (ISO-TP frames and flow control), without the other nodes.
    let telemetry_log: String = SESSION
        .lines()
        .filter(|line| line.contains(" 666#") || line.contains(" 777#"))
        .flat_map(|line| [line, "\n"])
        .collect();
    // A running service: the store is open (tables created) before the clock starts; the
    // clock stops once its writer has committed the last row.
    let path = dir.path().join("bench.sqlite");
    let raw_dir = dir.path().join("raw");
    let service = |raw_log: bool| {
        let _ = std::fs::remove_file(&path);
        let _ = std::fs::remove_dir_all(&raw_dir);
        let writer =
            store::StoreWriter::start(store::open(&path).expect("store"), counters.clone());
        let sinks: Vec<Box<dyn Sink>> = vec![
            Box::new(publisher.clone()),
            Box::new(StoreSink::new(writer.sender().expect("store open"), "car1")),
        ];
        let mut stage = Stage::new(counters.clone(), sinks, Replies::default());
        let mut raw = None;
        if raw_log {
            let settings = Settings {
                dir: raw_dir.clone(),
                segment_bytes: 16 << 20,
                segment_age: Duration::from_secs(3600),
                sync_every: Duration::from_secs(1),
                budget: Budget {
                    max_bytes: u64::MAX,
                    max_age: None,
                    min_free_bytes: 0,
                },
            };
            let (raw_writer, blocks) =
                RawWriter::start(settings, counters.clone(), Arc::new(Health::default()))
                    .expect("raw log");
            stage = stage.with_raw_log(RawTap::new(blocks, counters.clone()));
            raw = Some(raw_writer);
        }
        Service { stage, writer, raw }
    };
    let session = inputs(SESSION);
    let telemetry_only = inputs(&telemetry_log);
    let ingest = |service: Service, inputs: &[Input]| {
        let Service {
            mut stage,
            writer,
            raw,
        } = service;
        runtime.block_on(async {
            for input in inputs {
                stage.take(input.clone());
            }
            stage.flush();
        });
        drop(stage);
        writer.finish();
        if let Some(raw) = raw {
            raw.finish();
        }
    };
    let replay = |service: Service, log: &str| {
        let (stage, _) = runtime.block_on(service.stage.replay_all(log.as_bytes(), &counters));
        drop(stage);
        service.writer.finish();
    };

    let mut group = c.benchmark_group("pipeline");
    group.sample_size(10);
    group.throughput(Throughput::Elements(packets.len() as u64));
    group.bench_function(
        "ours: session, packets + every CAN frame, ingest + MQTT + store",
        |b| {
            b.iter_batched(
                || service(false),
                |s| ingest(s, &session),
                BatchSize::PerIteration,
            );
        },
    );
    group.bench_function(
        "ours: session, packets + every CAN frame, ingest + MQTT + store + raw log",
        |b| {
            b.iter_batched(
                || service(true),
                |s| ingest(s, &session),
                BatchSize::PerIteration,
            );
        },
    );
    group.bench_function("ours: packets only, ingest + MQTT + store", |b| {
        b.iter_batched(
            || service(false),
            |s| ingest(s, &telemetry_only),
            BatchSize::PerIteration,
        );
    });
    group.bench_function(
        "ours: session from the log's text, replay + ingest + MQTT + store",
        |b| {
            b.iter_batched(
                || service(false),
                |s| replay(s, SESSION),
                BatchSize::PerIteration,
            );
        },
    );
    group.bench_function("today: JSON + line protocol", |b| {
        let mut json = String::new();
        let mut line = String::new();
        b.iter(|| {
            for (ts, telemetry) in &packets {
                todays_design(*ts, telemetry, &mut json, &mut line);
                black_box((&json, &line));
            }
        });
    });
    group.bench_function("today: JSON + line protocol + MQTT publish", |b| {
        let mut json = String::new();
        let mut line = String::new();
        b.iter(|| {
            for (ts, telemetry) in &packets {
                todays_design(*ts, telemetry, &mut json, &mut line);
                today_publisher.publish_json("telemetry_today", &json, false);
                black_box(&line);
            }
        });
    });
    group.finish();
    let dropped = counters.snapshot().publish_dropped;
    assert_eq!(dropped, 0, "the benchmark must not drop MQTT messages");
}

/// The service's parts a benchmark round runs: ingest, the store's writer, the raw log's.
struct Service {
    stage: Stage,
    writer: store::StoreWriter,
    raw: Option<RawWriter>,
}

criterion_group!(benches, bench);
criterion_main!(benches);
