//! Prints the bench day's transcripts (docs/bench-day.md quotes them): `cargo run -p
//! aer-m7-check --example bench_day`.

fn main() {
    let mut out = String::new();
    if aer_m7_check::bench_day::transcripts(&mut out).is_err() {
        eprintln!("a transcript failed");
        std::process::exit(1);
    }
    print!("{out}");
}
