//! Decode and encode time per frame: the aer-codegen codec against dbc-codegen 0.4.0 (the
//! strongest Rust peer), generated from the same DBC file, on the same in-range frames.
//!
//! decode: payload -> every physical value (ours: `decode`; peer: parse + every getter).
//! encode: physical values -> payload (ours: `encode`; peer: `new`), both behind the same boxed
//! closure so the harness costs the same on both sides.

use std::hint::black_box;

use aer_bench::{aer, vehicle};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use embedded_can::{ExtendedId, Id, StandardId};

type Encoder = Box<dyn Fn(&mut [u8]) -> usize>;

struct Frame {
    id: u32,
    extended: bool,
    data: Vec<u8>,
}

fn can_id(f: &Frame) -> Id {
    if f.extended {
        Id::Extended(ExtendedId::new(f.id).expect("valid id"))
    } else {
        Id::Standard(StandardId::new(f.id as u16).expect("valid id"))
    }
}

/// Deterministic pseudo-random bytes (xorshift64*).
struct Rng(u64);

impl Rng {
    fn byte(&mut self) -> u8 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 56) as u8
    }
}

macro_rules! codec_bench {
    ($fn_name:ident, $module:ident, $label:literal) => {
        fn $fn_name(c: &mut Criterion) {
            use $module::ours::can::{AnyMessage, MESSAGES};
            use $module::peer_harness;
            let mut rng = Rng(0x5EED_0000_0000_0001);
            let mut frames = Vec::new();
            // Four in-range frames per message: random payloads that both codecs re-encode.
            for meta in MESSAGES.iter() {
                let mut found = 0;
                for _ in 0..200 {
                    let data: Vec<u8> = (0..meta.len).map(|_| rng.byte()).collect();
                    let Ok(msg) = AnyMessage::decode(meta.id, meta.extended, &data) else { continue };
                    let mut out = [0u8; 64];
                    let Ok(n) = msg.encode(&mut out) else { continue };
                    let frame = Frame { id: meta.id, extended: meta.extended, data: out[..n].to_vec() };
                    let ok = peer_harness::prepare(can_id(&frame), &frame.data).is_some_and(|enc| enc(&mut [0u8; 64]) > 0);
                    if ok {
                        frames.push(frame);
                        found += 1;
                        if found == 4 {
                            break;
                        }
                    }
                }
            }
            let ours_enc: Vec<Encoder> = frames
                .iter()
                .map(|f| {
                    let msg = AnyMessage::decode(f.id, f.extended, &f.data).expect("decodes");
                    Box::new(move |out: &mut [u8]| msg.encode(out).unwrap_or(0)) as Encoder
                })
                .collect();
            let peer_enc: Vec<Encoder> = frames
                .iter()
                .map(|f| peer_harness::prepare(can_id(f), &f.data).expect("prepared"))
                .collect();
            eprintln!("{}: {} frames from {} messages", $label, frames.len(), MESSAGES.len());

            let mut group = c.benchmark_group(concat!("decode/", $label));
            group.throughput(Throughput::Elements(frames.len() as u64));
            group.bench_function("aer-codegen", |b| {
                b.iter(|| {
                    for f in &frames {
                        let _ = black_box(AnyMessage::decode(black_box(f.id), f.extended, black_box(&f.data)));
                    }
                })
            });
            let ids: Vec<Id> = frames.iter().map(can_id).collect();
            group.bench_function("dbc-codegen-0.4.0", |b| {
                b.iter(|| {
                    for (f, id) in frames.iter().zip(&ids) {
                        peer_harness::decode(black_box(*id), black_box(&f.data));
                    }
                })
            });
            group.finish();

            let mut group = c.benchmark_group(concat!("encode/", $label));
            group.throughput(Throughput::Elements(frames.len() as u64));
            let mut out = [0u8; 64];
            group.bench_function("aer-codegen", |b| {
                b.iter(|| {
                    for enc in &ours_enc {
                        black_box(enc(black_box(&mut out)));
                    }
                })
            });
            group.bench_function("dbc-codegen-0.4.0", |b| {
                b.iter(|| {
                    for enc in &peer_enc {
                        black_box(enc(black_box(&mut out)));
                    }
                })
            });
            group.finish();
        }
    };
}

codec_bench!(car, aer, "aer.dbc");
codec_bench!(largest_corpus_file, vehicle, "vehicle.dbc");

criterion_group!(benches, car, largest_corpus_file);
criterion_main!(benches);
