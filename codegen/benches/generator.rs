//! The generator's cost on synthetic DBCs: checking (parse and validate) and rendering the
//! codec, at 1k, 10k and 100k signals, and a deeply multiplexed message. Formatting the
//! output with rustfmt is outside the figures (it is a separate process; see docs/schema.md).
//!
//! `cargo bench -p aer-codegen --bench generator`

use std::fmt::Write as _;
use std::hint::black_box;
use std::path::Path;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};

/// `signals` signals, eight 8-bit ones a message, each with a comment, a start-value
/// attribute and (every eighth) value descriptions; each message with a comment and a cycle
/// time, as a vendor's file has them.
fn flat_dbc(signals: usize) -> String {
    let mut text = String::from("VERSION \"\"\n\nNS_ :\n\nBS_:\n\nBU_: ECU\n\n");
    let mut extra = String::new();
    for m in 0..signals.div_ceil(8) {
        let id = if m < 0x7FF {
            m + 1
        } else {
            (m + 1) | 0x8000_0000
        };
        let _ = writeln!(text, "BO_ {id} Msg{m}: 8 ECU");
        for s in 0..8 {
            let _ = writeln!(
                text,
                " SG_ Sig{m}_{s} : {}|8@1+ (0.5,-10) [-10|117.5] \"unit\" Vector__XXX",
                s * 8
            );
            let _ = writeln!(
                extra,
                "CM_ SG_ {id} Sig{m}_{s} \"Signal {s} of message {m}.\";"
            );
            let _ = writeln!(extra, "BA_ \"GenSigStartValue\" SG_ {id} Sig{m}_{s} 20;");
        }
        let _ = writeln!(extra, "VAL_ {id} Sig{m}_7 0 \"Off\" 1 \"On\" 2 \"Error\" ;");
        let _ = writeln!(extra, "CM_ BO_ {id} \"Message {m}.\";");
        let _ = writeln!(extra, "BA_ \"GenMsgCycleTime\" BO_ {id} 100;");
        text.push('\n');
    }
    text.push_str("BA_DEF_ BO_ \"GenMsgCycleTime\" INT 0 65535;\n");
    text.push_str("BA_DEF_ SG_ \"GenSigStartValue\" INT 0 100000;\n");
    text.push_str(&extra);
    text
}

/// One 64-byte message: a chain of 31 nested multiplexors, each selecting the next (value 1)
/// and `per_level` alternatives (values 2 and up) at the same bits.
fn deep_mux_dbc(per_level: usize) -> String {
    let depth = 31;
    let mut text =
        String::from("VERSION \"\"\n\nNS_ :\n\nBS_:\n\nBU_: ECU\n\nBO_ 1 Chain: 64 ECU\n");
    let mut mul = String::new();
    text.push_str(" SG_ C0 M : 0|8@1+ (1,0) [0|255] \"\" Vector__XXX\n");
    for d in 1..depth {
        let _ = writeln!(
            text,
            " SG_ C{d} m1M : {}|8@1+ (1,0) [0|255] \"\" Vector__XXX",
            d * 8
        );
        let _ = writeln!(mul, "SG_MUL_VAL_ 1 C{d} C{} 1-1;", d - 1);
    }
    for d in 0..depth {
        for v in 2..per_level + 2 {
            let _ = writeln!(
                text,
                " SG_ L{d}_{v} m{v} : {}|8@1+ (1,0) [0|255] \"\" Vector__XXX",
                (32 + d) * 8
            );
            let _ = writeln!(mul, "SG_MUL_VAL_ 1 L{d}_{v} C{d} {v}-{v};");
        }
    }
    text.push('\n');
    text.push_str(&mul);
    text
}

fn check(text: &str) -> aer_codegen::model::Database {
    let path = Path::new("synthetic.dbc");
    aer_codegen::parse_dbc(path, text.to_owned(), &[])
        .expect("valid")
        .0
}

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("generator");
    group.sample_size(10);
    let cases = [
        ("1k signals", flat_dbc(1_000), 1_000),
        ("10k signals", flat_dbc(10_000), 10_000),
        ("100k signals", flat_dbc(100_000), 100_000),
        ("deep mux, 7k signals", deep_mux_dbc(225), 30 + 31 * 225 + 1),
    ];
    for (name, text, signals) in &cases {
        group.throughput(Throughput::Elements(*signals as u64));
        group.bench_with_input(BenchmarkId::new("check", name), text, |b, text| {
            b.iter(|| black_box(check(text)));
        });
        let db = check(text);
        assert_eq!(
            db.messages.iter().map(|m| m.signals.len()).sum::<usize>(),
            *signals,
            "{name}"
        );
        group.bench_with_input(BenchmarkId::new("render", name), &db, |b, db| {
            b.iter(|| {
                black_box(
                    aer_codegen::codec_files(db, "synthetic.dbc", "Bench.", "synthetic_can")
                        .expect("renders"),
                )
            });
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
