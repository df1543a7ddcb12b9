//! Latency from a packet's last CAN frame entering the service's pipeline (`Pipeline`, as
//! `serve` runs it: ingest, raw log, store writer, embedded broker) to its delivery at an MQTT
//! subscriber (rumqttc, loopback), at 100 Hz and 1 kHz, in one run for both forms the pit can
//! read: the JSON telemetry topic, and the compact pit stream (`aer-pit/car1/stream`, decoded
//! with the Pi's own ingest as the dashboard does). The traffic is the bundled session
//! (raspi/data/session.log: every frame on both buses the CCM's logic sent in the car model),
//! one batch per telemetry packet, handed over at the packet rate. Prints, for each,
//! p50, p99 and max, and the bytes on MQTT per second for what it carries (the JSON: the
//! telemetry topic only; the stream: every frame). Run: `cargo bench -p aer-raspi --bench
//! latency`.

use aer::mqtt::{Sample, TELEMETRY, TelemetryRecord};
use aer_host::clock::now_us;
use aer_host::decode::{Ingest, Record};
use aer_host::formats::candump::{LoggedFrame, parse_line};
use aer_host::formats::pit_stream::{self, Item};
use aer_host::reports::counters::Counters;
use aer_raspi::broker;
use aer_raspi::config::Config;
use aer_raspi::service::{Job, Pipeline};
use aer_raspi::source::Input;
use rumqttc::{AsyncClient, Event, MqttOptions, Packet, QoS};
use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// The bundled session's frames in batches, each ending with a telemetry packet's last frame,
/// with that packet's sequence number: what a source hands the pipeline per packet.
fn packet_batches() -> Vec<(u16, Vec<LoggedFrame>)> {
    let log = include_str!("../data/session.log");
    let mut ingest = Ingest::new(Arc::new(Counters::default()));
    let mut batches = Vec::new();
    let mut batch = Vec::new();
    for line in log.lines() {
        let Ok(frame) = parse_line(line, |name| u8::from(name == "can1")) else {
            continue;
        };
        batch.push(frame);
        let mut completed = None;
        ingest.on_frame(
            &frame,
            |record| {
                if let Record::Telemetry { header, .. } = record {
                    completed = Some(header.sequence);
                }
            },
            |_, _| {},
        );
        if let Some(sequence) = completed {
            batches.push((sequence, std::mem::take(&mut batch)));
        }
    }
    batches
}

/// What one form delivered: latencies and bytes on MQTT (payload, topic, fixed header).
#[derive(Default)]
struct Delivered {
    latencies: Vec<Duration>,
    bytes: usize,
}

impl Delivered {
    fn report(&self, what: &str, packets: u16, seconds: f64) {
        let mut latencies = self.latencies.clone();
        latencies.sort();
        println!(
            "    {what:<12} {} of {packets} delivered; p50 {:?}, p99 {:?}, max {:?}; {:.1} kbit/s on MQTT",
            latencies.len(),
            percentile(&latencies, 0.5),
            percentile(&latencies, 0.99),
            latencies.last().copied().unwrap_or_default(),
            self.bytes as f64 * 8.0 / seconds / 1000.0
        );
    }
}

fn percentile(sorted: &[Duration], p: f64) -> Duration {
    let index = ((sorted.len() as f64 - 1.0) * p).round() as usize;
    sorted.get(index).copied().unwrap_or_default()
}

fn main() {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .expect("runtime");
    runtime.block_on(async {
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .and_then(|l| l.local_addr())
            .map(|a| a.port())
            .expect("port");
        let dir = tempfile::tempdir().expect("temp dir");
        let broker_config = dir.path().join("rumqttd.toml");
        let text = broker::DEFAULT_CONFIG.replace("127.0.0.1:1883", &format!("127.0.0.1:{port}"));
        std::fs::write(&broker_config, text).expect("broker config");
        let mut config = Config::default();
        config.broker.config = Some(broker_config);
        config.store.path = dir.path().join("l.sqlite");
        config.raw_log.dir = dir.path().join("raw");
        let mut pipeline = Pipeline::start(config, Job::Fed).await.expect("pipeline");
        let input = pipeline.input().expect("a fed pipeline's input");
        let running = tokio::spawn(pipeline.run(std::future::pending()));

        let mut options = MqttOptions::new("latency-subscriber", "127.0.0.1", port);
        options.set_max_packet_size(64 * 1024, 64 * 1024);
        let (subscriber, mut events) = AsyncClient::new(options, 100);
        let mut network = events.network_options();
        network.set_tcp_nodelay(true);
        events.set_network_options(network);
        let stream_topic = pit_stream::topic("aer/car1");
        for topic in ["aer/car1/telemetry", stream_topic.as_str()] {
            subscriber
                .subscribe(topic, QoS::AtMostOnce)
                .await
                .expect("subscribe");
            loop {
                if let Ok(Event::Incoming(Packet::SubAck(_))) = events.poll().await {
                    break;
                }
            }
        }
        let sent: Arc<Mutex<HashMap<u16, Instant>>> = Arc::default();
        let json: Arc<Mutex<Delivered>> = Arc::default();
        let stream: Arc<Mutex<Delivered>> = Arc::default();
        {
            let (sent, json, stream) = (sent.clone(), json.clone(), stream.clone());
            let mut ingest = Ingest::new(Arc::new(Counters::default()));
            tokio::spawn(async move {
                while let Ok(event) = events.poll().await {
                    let Event::Incoming(Packet::Publish(p)) = event else {
                        continue;
                    };
                    let at = Instant::now();
                    let latency = |sequence: u16| {
                        let start = sent.lock().ok().and_then(|s| s.get(&sequence).copied());
                        start.map(|start| at - start)
                    };
                    let wire = p.payload.len() + p.topic.len() + 4;
                    if p.topic == stream_topic {
                        let Ok(batch) = pit_stream::decode(&p.payload) else {
                            continue;
                        };
                        let mut sequences = Vec::new();
                        for item in &batch.items {
                            if let Item::Frame(frame) = item {
                                ingest.on_frame(
                                    frame,
                                    |record| {
                                        if let Record::Telemetry { header, .. } = record {
                                            sequences.push(header.sequence);
                                        }
                                    },
                                    |_, _| {},
                                );
                            }
                        }
                        if let Ok(mut stream) = stream.lock() {
                            stream.bytes += wire;
                            let latencies = sequences.into_iter().filter_map(latency);
                            stream.latencies.extend(latencies);
                        }
                    } else if let Ok(sample) = TELEMETRY.decode(&p.payload) {
                        let sample: Sample<TelemetryRecord> = sample;
                        if let Ok(mut json) = json.lock() {
                            json.bytes += wire;
                            json.latencies.extend(latency(sample.value.header.sequence));
                        }
                    }
                }
            });
        }

        let buses = ["can0", "can1"]
            .into_iter()
            .enumerate()
            .map(|(index, name)| Input::Bus {
                index: index as u8,
                name: name.into(),
            });
        input.send(buses.collect()).await.expect("pipeline running");
        let batches = packet_batches();

        for (rate, packets) in [(100u32, 1_000u16), (1_000, 4_000)] {
            for delivered in [&json, &stream] {
                if let Ok(mut d) = delivered.lock() {
                    *d = Delivered::default();
                }
            }
            if let Ok(mut s) = sent.lock() {
                s.clear();
            }
            let period = Duration::from_secs(1) / rate;
            let started = tokio::time::Instant::now();
            let mut next = started;
            for (sequence, frames) in batches.iter().take(usize::from(packets)) {
                next += period;
                // The clock starts when the batch holding the packet's last frame is handed to
                // the pipeline, each frame stamped with the time it is handed over.
                let now = now_us();
                let batch = frames
                    .iter()
                    .map(|frame| {
                        Input::Frame(LoggedFrame {
                            ts_us: now,
                            ..*frame
                        })
                    })
                    .collect();
                if let Ok(mut s) = sent.lock() {
                    s.insert(*sequence, Instant::now());
                }
                input.send(batch).await.expect("pipeline running");
                tokio::time::sleep_until(next).await;
            }
            let seconds = started.elapsed().as_secs_f64();
            // Let the last deliveries arrive (bounded wait for the tail, not a synchronisation).
            let deadline = tokio::time::Instant::now() + Duration::from_secs(2);
            let delivered = |d: &Arc<Mutex<Delivered>>| d.lock().map_or(0, |d| d.latencies.len());
            while (delivered(&json) < usize::from(packets)
                || delivered(&stream) < usize::from(packets))
                && tokio::time::Instant::now() < deadline
            {
                tokio::time::sleep(Duration::from_millis(10)).await;
            }
            println!("{rate:>5} Hz:");
            for (what, delivered) in [("JSON topic", &json), ("pit stream", &stream)] {
                if let Ok(d) = delivered.lock() {
                    d.report(what, packets, seconds);
                }
            }
        }
        drop(input);
        running
            .await
            .expect("pipeline task")
            .expect("pipeline stops cleanly");
    });
}
