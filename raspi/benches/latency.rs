//! Latency from a packet's last CAN frame entering the service's pipeline (`Pipeline`, as
//! `serve` runs it: ingest, raw log, store writer, embedded broker) to its delivery at an MQTT
//! subscriber (rumqttc, loopback), at 100 Hz and 1 kHz.
//! The traffic is the closed-loop car model's (every frame on both buses), one telemetry
//! packet per 10 ms of model time. Prints p50, p99 and max. Run: `cargo bench -p aer-raspi
//! --bench latency`.

use aer::mqtt::{Sample, TELEMETRY, TelemetryRecord};
use aer::telemetry::Telemetry;
use aer_car_model::chassis::Mode;
use aer_car_model::driver::Cycle;
use aer_car_model::faults::FaultPlan;
use aer_car_model::{BusTap, ClosedLoop, ModelParams};
use aer_flexcan::CanFrame;
use aer_host::candump::LoggedFrame;
use aer_host::clock::now_us;
use aer_raspi::broker;
use aer_raspi::config::Config;
use aer_raspi::service::{Job, Pipeline};
use aer_raspi::source::Input;
use embedded_can::{Frame, Id};
use rumqttc::{AsyncClient, Event, MqttOptions, Packet, QoS};
use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// One model step's frames.
#[derive(Default)]
struct Frames(Vec<(usize, CanFrame)>);

impl BusTap for Frames {
    fn frame(&mut self, _: u64, bus: usize, frame: &CanFrame) {
        self.0.push((bus, *frame));
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
        subscriber
            .subscribe("aer/car1/telemetry", QoS::AtMostOnce)
            .await
            .expect("subscribe");
        loop {
            if let Ok(Event::Incoming(Packet::SubAck(_))) = events.poll().await {
                break;
            }
        }
        let sent: Arc<Mutex<HashMap<u16, Instant>>> = Arc::default();
        let received: Arc<Mutex<Vec<Duration>>> = Arc::default();
        {
            let (sent, received) = (sent.clone(), received.clone());
            tokio::spawn(async move {
                while let Ok(event) = events.poll().await {
                    if let Event::Incoming(Packet::Publish(p)) = event {
                        let at = Instant::now();
                        if let Ok(sample) = TELEMETRY.decode(&p.payload) {
                            let sample: Sample<TelemetryRecord> = sample;
                            let start = sent
                                .lock()
                                .ok()
                                .and_then(|s| s.get(&sample.value.header.sequence).copied());
                            if let (Some(start), Ok(mut received)) = (start, received.lock()) {
                                received.push(at - start);
                            }
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
        let telemetry = Id::Standard(embedded_can::StandardId::new(Telemetry::TX_ID).expect("id"));

        for (rate, packets) in [(100u32, 1_000u16), (1_000, 5_000)] {
            if let Ok(mut r) = received.lock() {
                r.clear();
            }
            if let Ok(mut s) = sent.lock() {
                s.clear();
            }
            let mut model = ClosedLoop::new(
                ModelParams::NOMINAL,
                Mode::Road,
                Cycle::Autocross,
                FaultPlan::NONE,
            );
            let period = Duration::from_secs(1) / rate;
            let mut next = tokio::time::Instant::now();
            for sequence in 0..packets {
                next += period;
                let mut frames = Frames::default();
                model.run_until(model.now_ms() + 10, &mut frames);
                // The step ends with the telemetry packet: its last frame is the clock's start.
                // One batch a step, as a source sends what it read: the clock starts when the
                // batch holding the packet's last frame is handed to the pipeline.
                let batch = frames
                    .0
                    .iter()
                    .filter_map(|(bus, frame)| {
                        LoggedFrame::new(now_us(), *bus as u8, frame.id(), frame.data())
                    })
                    .map(Input::Frame)
                    .collect();
                if frames.0.iter().any(|(_, f)| f.id() == telemetry)
                    && let Ok(mut s) = sent.lock()
                {
                    s.insert(sequence, Instant::now());
                }
                input.send(batch).await.expect("pipeline running");
                tokio::time::sleep_until(next).await;
            }
            // Let the last deliveries arrive (bounded wait for the tail, not a synchronisation).
            let deadline = tokio::time::Instant::now() + Duration::from_secs(2);
            while received.lock().map_or(0, |r| r.len()) < usize::from(packets)
                && tokio::time::Instant::now() < deadline
            {
                tokio::time::sleep(Duration::from_millis(10)).await;
            }
            let mut latencies = received.lock().map(|r| r.clone()).unwrap_or_default();
            latencies.sort();
            println!(
                "{rate:>5} Hz: {} of {packets} delivered; p50 {:?}, p99 {:?}, max {:?}",
                latencies.len(),
                percentile(&latencies, 0.5),
                percentile(&latencies, 0.99),
                latencies.last().copied().unwrap_or_default()
            );
        }
        drop(input);
        running
            .await
            .expect("pipeline task")
            .expect("pipeline stops cleanly");
    });
}
