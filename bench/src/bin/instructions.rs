//! Runs one benchmarked operation many times, for callgrind to count its instructions:
//! `instructions SUITE OP [ROUNDS]` with SUITE `aer` or `vehicle` and OP one of
//! `ours_decode`, `peer_decode`, `c_decode`, `ours_encode`, `peer_encode`, `c_encode`.
//! Prints the frames per round; `tools/codec_instructions.sh` runs it under callgrind,
//! counting only inside the operation's function, and divides.

use std::hint::black_box;

use aer_bench::{aer_suite, vehicle_suite};

macro_rules! run {
    ($suite:ident, $op:expr, $rounds:expr) => {{
        let s = $suite::prepare();
        let mut out = [0u8; 64];
        for _ in 0..$rounds {
            match $op {
                "ours_decode" => drop(black_box($suite::ours_decode(&s))),
                "peer_decode" => $suite::peer_decode(&s),
                "c_decode" => drop(black_box($suite::c_decode(&s))),
                "ours_encode" => drop(black_box($suite::ours_encode(&s, &mut out))),
                "peer_encode" => drop(black_box($suite::peer_encode(&s, &mut out))),
                "c_encode" => drop(black_box($suite::c_encode(&s, &mut out))),
                other => {
                    eprintln!("unknown operation {other}");
                    std::process::exit(2);
                }
            }
        }
        s.frames.len()
    }};
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let (Some(suite), Some(op)) = (args.get(1), args.get(2)) else {
        eprintln!("usage: instructions aer|vehicle OP [ROUNDS]");
        std::process::exit(2);
    };
    let rounds: usize = args.get(3).and_then(|r| r.parse().ok()).unwrap_or(100);
    let frames = match suite.as_str() {
        "aer" => run!(aer_suite, op.as_str(), rounds),
        "vehicle" => run!(vehicle_suite, op.as_str(), rounds),
        other => {
            eprintln!("unknown suite {other}");
            std::process::exit(2);
        }
    };
    println!("{frames}");
}
