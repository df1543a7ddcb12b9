//! Pipeline throughput: the bundled session (4,500 packets, 67,950 frames) through ISO-TP and
//! the generated decoders, published with rumqttc to the embedded broker and written to the
//! SQLite store, against today's design (serde_json of the whole struct plus one line-protocol
//! string per packet, vehicle-facts.md) on the same packets.
//!
//! Run on one core (pipeline, store writer, MQTT client and broker share it):
//! `taskset -c 0 cargo bench -p aer-raspi --bench pipeline`.

use aer::telemetry::Telemetry;
use aer_raspi::candump::{LoggedFrame, parse_line};
use aer_raspi::config::MqttConfig;
use aer_raspi::metrics::Counters;
use aer_raspi::pipeline::Pipeline;
use aer_raspi::source::decode_log;
use aer_raspi::{broker, publish, store};
use criterion::{BatchSize, Criterion, Throughput, criterion_group, criterion_main};
use std::collections::HashMap;
use std::fmt::Write as _;
use std::hint::black_box;
use std::sync::Arc;
use std::time::Duration;

const SESSION: &str = include_str!("../data/session.log");

fn frames() -> Vec<LoggedFrame> {
    let mut buses = HashMap::new();
    SESSION
        .lines()
        .filter_map(|line| {
            parse_line(line, |name| {
                let next = buses.len() as u8;
                *buses.entry(name.to_owned()).or_insert(next)
            })
            .ok()
        })
        .collect()
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
    let frames = frames();
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
    let link =
        broker::spawn(toml::from_str(&text).expect("broker config"), "bench").expect("broker");
    let counters = Arc::new(Counters::default());
    let mqtt = MqttConfig {
        port,
        queue: 200_000,
        ..MqttConfig::default()
    };
    // Ours publishes as the service does, in process into the embedded broker; today's Pi
    // publishes with rumqttc over loopback TCP to its embedded broker.
    let (publisher, today_publisher) = runtime.block_on(async {
        let (publisher, driver) =
            publish::embedded(link, mqtt.queue, "aer/car1".into(), counters.clone());
        tokio::spawn(publish::drive(driver, tokio::sync::watch::channel(false).0));
        let (today, driver) = publish::connect(&mqtt, "today", "aer/car1".into(), counters.clone());
        let (up_tx, mut up) = tokio::sync::watch::channel(false);
        tokio::spawn(publish::drive(driver, up_tx));
        let _ = tokio::time::timeout(Duration::from_secs(10), up.wait_for(|u| *u)).await;
        (publisher, today)
    });
    let dir = tempfile::tempdir().expect("temp dir");
    // The CCM's packets alone (ISO-TP frames and flow control), without the other nodes.
    let telemetry_frames: Vec<LoggedFrame> = frames
        .iter()
        .filter(|f| matches!(f.id, embedded_can::Id::Standard(id) if id.as_raw() == 0x666 || id.as_raw() == 0x777))
        .copied()
        .collect();
    // A running service: the store is open (tables created) before the clock starts; the
    // clock stops once its writer has committed the last row.
    let path = dir.path().join("bench.sqlite");
    let service = || {
        let _ = std::fs::remove_file(&path);
        let writer =
            store::StoreWriter::start(store::open(&path).expect("store"), counters.clone());
        let pipeline = Pipeline::new(
            counters.clone(),
            "car1".into(),
            vec!["can0".into(), "can1".into()],
            Some(publisher.clone()),
            writer.sender(),
        );
        (pipeline, writer)
    };
    let ours = |(mut pipeline, writer): (Pipeline, store::StoreWriter), frames: &[LoggedFrame]| {
        for frame in frames {
            pipeline.feed(frame, |_, _| {});
        }
        drop(pipeline);
        writer.finish();
    };

    let mut group = c.benchmark_group("pipeline");
    group.sample_size(10);
    group.throughput(Throughput::Elements(packets.len() as u64));
    group.bench_function(
        "ours: session, packets + 18,450 CAN frames, decode + MQTT + store",
        |b| {
            b.iter_batched(service, |s| ours(s, &frames), BatchSize::PerIteration);
        },
    );
    group.bench_function("ours: packets only, decode + MQTT + store", |b| {
        b.iter_batched(
            service,
            |s| ours(s, &telemetry_frames),
            BatchSize::PerIteration,
        );
    });
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

criterion_group!(benches, bench);
criterion_main!(benches);
