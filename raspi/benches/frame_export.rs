//! The bus-logging exports: the bundled session's 99,450 frames (both buses, from its candump
//! log, as the raw log's export reads them) written as BLF, ASC and MF4, frames per second;
//! beside them, in the same run, the peer a CANalyzer user reaches for today: python-can's
//! BLF and ASC writers (`can.Logger`) on the same log, timed by Python (skipped, and said so,
//! without the project's venv). Run: `cargo bench -p aer-raspi --bench frame_export`.

use aer_raspi::export::Format;
use aer_raspi::export::frames::{self, source::FrameSource};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

fn session_log() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("data/session.log")
}

fn exports(c: &mut Criterion) {
    let source = FrameSource {
        files: vec![session_log()],
        ..FrameSource::default()
    };
    let summary = source.summary().expect("the bundled log reads");
    let dir = tempfile::tempdir().expect("temp dir");
    let mut group = c.benchmark_group("frame export");
    group
        .throughput(Throughput::Elements(summary.frames as u64))
        .sample_size(10)
        .measurement_time(Duration::from_secs(10));
    for format in [Format::Blf, Format::Asc, Format::Mf4] {
        let name = frames::file_name(format).expect("a bus-logging format");
        let path = dir.path().join(name);
        group.bench_function(name, |b| {
            b.iter(|| frames::write(format, &source, &summary, &path, &[]).expect("written"));
        });
    }
    group.finish();
    python_can(&session_log());
}

/// python-can writing the same log, timed by Python.
fn python_can(log: &Path) {
    let python = Path::new(env!("CARGO_MANIFEST_DIR")).join("../.venv/bin/python");
    let script = r#"
import sys, tempfile, time, can
frames = list(can.LogReader(sys.argv[1]))
for suffix in (".blf", ".asc"):
    with tempfile.TemporaryDirectory() as d:
        best = None
        for _ in range(3):
            start = time.perf_counter()
            with can.Logger(d + "/session" + suffix) as out:
                for frame in frames:
                    out.on_message_received(frame)
            took = time.perf_counter() - start
            best = took if best is None else min(best, took)
        print(f"python-can {can.__version__} {suffix[1:].upper()}: {len(frames)} frames in {best * 1e3:.0f} ms "
              f"({len(frames) / best / 1e3:.0f} kframes/s; best of 3, the log already read)")
"#;
    match Command::new(&python)
        .arg("-c")
        .arg(script)
        .arg(log)
        .output()
    {
        Ok(out) if out.status.success() => print!("{}", String::from_utf8_lossy(&out.stdout)),
        _ => println!(
            "SKIPPED: python-can's writers need {} with python-can (tools/requirements.txt)",
            python.display()
        ),
    }
}

criterion_group!(benches, exports);
criterion_main!(benches);
