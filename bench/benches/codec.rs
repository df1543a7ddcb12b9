//! Decode and encode time per frame on the same in-range frames: the aer-codegen codec,
//! dbc-codegen 0.4.0 (the strongest Rust peer) and cantools' generated C (gcc -O2, codec and
//! harness in one translation unit), all generated from the same DBC file.
//!
//! decode: payload -> every physical value, each one read (ours: `AnyMessage::decode` then
//! every value through `visit`; dbc-codegen: parse + every getter; C: unpack + every signal's
//! decode, added up). encode: physical values -> payload (ours: `encode`, with range checks and
//! rounding to nearest; dbc-codegen: `new`, through a boxed closure per message; C: every
//! signal's encode, which truncates and does not check, then pack). Instruction counts of the
//! same operations: `src/bin/instructions.rs`.

use std::hint::black_box;

use aer_bench::{aer_suite, vehicle_suite};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};

macro_rules! codec_bench {
    ($fn_name:ident, $suite:ident, $label:literal) => {
        fn $fn_name(c: &mut Criterion) {
            let s = $suite::prepare();
            eprintln!("{}: {} frames", $label, s.frames.len());
            let mut group = c.benchmark_group(concat!("decode/", $label));
            group.throughput(Throughput::Elements(s.frames.len() as u64));
            group.bench_function("aer-codegen", |b| {
                b.iter(|| black_box($suite::ours_decode(&s)))
            });
            group.bench_function("dbc-codegen-0.4.0", |b| b.iter(|| $suite::peer_decode(&s)));
            group.bench_function("cantools-c", |b| b.iter(|| black_box($suite::c_decode(&s))));
            group.finish();

            let mut group = c.benchmark_group(concat!("encode/", $label));
            group.throughput(Throughput::Elements(s.frames.len() as u64));
            let mut out = [0u8; 64];
            group.bench_function("aer-codegen", |b| {
                b.iter(|| black_box($suite::ours_encode(&s, &mut out)))
            });
            group.bench_function("dbc-codegen-0.4.0", |b| {
                b.iter(|| black_box($suite::peer_encode(&s, &mut out)))
            });
            group.bench_function("cantools-c", |b| {
                b.iter(|| black_box($suite::c_encode(&s, &mut out)))
            });
            group.finish();
        }
    };
}

codec_bench!(car, aer_suite, "aer.dbc");
codec_bench!(largest_corpus_file, vehicle_suite, "vehicle.dbc");

criterion_group!(benches, car, largest_corpus_file);
criterion_main!(benches);
