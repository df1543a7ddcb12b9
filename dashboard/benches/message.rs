//! The dashboard's cost per telemetry message (decode the MQTT payload with its typed topic,
//! update the model) and per frame (build and lay out each view), on the bundled session.

use aer::mqtt::TELEMETRY;
use aer_dashboard::config::{Config, View};
use aer_dashboard::model::Dashboard;
use aer_dashboard::screenshot::{self, DRIVER_SIZE, PIT_SIZE};
use aer_dashboard::session;
use aer_dashboard::session::BUNDLED_SESSION;
use aer_dashboard::ui::App;
use criterion::{BatchSize, Criterion, Throughput, criterion_group, criterion_main};
use std::hint::black_box;
use std::time::{Duration, Instant};

fn per_message(c: &mut Criterion) {
    let session = session::load(BUNDLED_SESSION, "car1");
    let payloads: Vec<Vec<u8>> = session
        .samples
        .iter()
        .map(|s| TELEMETRY.encode(s).expect("encode"))
        .collect();
    let config = Config::default();
    let mut group = c.benchmark_group("telemetry message");
    group.throughput(Throughput::Elements(1));

    let mut i = 0;
    group.bench_function("decode payload (typed topic, JSON)", |b| {
        b.iter(|| {
            i = (i + 1) % payloads.len();
            black_box(TELEMETRY.decode(&payloads[i]).expect("decode"))
        })
    });

    let mut model = Dashboard::new(&config);
    let start = Instant::now();
    let mut n = 0u64;
    group.bench_function("update model", |b| {
        b.iter(|| {
            n += 1;
            let sample = &session.samples[n as usize % session.samples.len()];
            model.telemetry(black_box(sample), start + Duration::from_millis(n * 10));
        })
    });

    let mut model = Dashboard::new(&config);
    let mut n = 0u64;
    group.bench_function("decode + update (whole message)", |b| {
        b.iter(|| {
            n += 1;
            let payload = &payloads[n as usize % payloads.len()];
            let sample = TELEMETRY.decode(black_box(payload)).expect("decode");
            model.telemetry(&sample, start + Duration::from_millis(n * 10));
        })
    });
    group.finish();
}

fn per_frame(c: &mut Criterion) {
    let config = Config::default();
    let session = session::load(BUNDLED_SESSION, "car1");
    let (model, now) = screenshot::replayed(&config, &session, None);
    let mut offscreen = screenshot::Offscreen::new().expect("renderer");
    let mut group = c.benchmark_group("frame");
    for (view, size, name) in [
        (
            View::Driver,
            DRIVER_SIZE,
            "driver view: build + lay out + draw (tiny-skia)",
        ),
        (
            View::Pit,
            PIT_SIZE,
            "pit view: build + lay out + draw (tiny-skia)",
        ),
    ] {
        group.bench_function(name, |b| {
            b.iter_batched(
                || App::with_model(&config, model.clone(), view, now),
                |app| black_box(offscreen.render(&app, size)),
                BatchSize::SmallInput,
            )
        });
    }
    group.finish();
}

criterion_group!(benches, per_message, per_frame);
criterion_main!(benches);
