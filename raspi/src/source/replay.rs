//! A recorded candump log (`candump -l` / `-L`), at recorded speed or flat out.

use super::{Batcher, BusNames, Input, Sender};
use aer_host::candump::parse_line;
use aer_host::clock::now_us;
use aer_host::counters::{Counters, worth_logging};
use std::io::BufRead;
use std::time::Duration;
use tokio::time::Instant;
use tokio_util::sync::CancellationToken;
use tracing::warn;

/// How a log is replayed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReplayOptions {
    /// As fast as possible instead of at recorded speed.
    pub fast: bool,
    /// Stamp frames with the time they are replayed instead of the recorded time (the demo:
    /// the data looks live to subscribers).
    pub restamp: bool,
}

impl ReplayOptions {
    /// Flat out with the recorded timestamps (tests, benchmarks).
    pub const FAST: Self = Self {
        fast: true,
        restamp: false,
    };
}

/// What a replay did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ReplayStats {
    pub lines: u64,
    pub frames: u64,
    pub bad_lines: u64,
}

/// Replays `log` into `out` until its end, `cancel`, or nothing downstream listening. Broken
/// lines are counted (`bad_lines`) and skipped.
pub async fn replay(
    log: impl BufRead,
    out: Sender,
    counters: &Counters,
    options: ReplayOptions,
    cancel: &CancellationToken,
) -> ReplayStats {
    let mut stats = ReplayStats::default();
    let mut batcher = Batcher::new(out);
    let mut buses = BusNames::default();
    let mut origin: Option<(u64, Instant)> = None;
    for (number, line) in log.lines().enumerate() {
        if cancel.is_cancelled() {
            break;
        }
        stats.lines += 1;
        let line = match line {
            Ok(line) => line,
            Err(error) => {
                // Not UTF-8 or unreadable: counted like any broken line.
                stats.bad_lines += 1;
                bad_line(counters, number, &error);
                continue;
            }
        };
        if line.trim().is_empty() {
            continue;
        }
        let mut announced = None;
        let parsed = parse_line(&line, |name| {
            let (index, announcement) = buses.index(name);
            announced = announcement;
            index
        });
        let mut frame = match parsed {
            Ok(frame) => frame,
            Err(error) => {
                stats.bad_lines += 1;
                bad_line(counters, number, &error);
                continue;
            }
        };
        if let Some(announcement) = announced {
            if !batcher.push(announcement).await {
                break;
            }
        }
        if !options.fast {
            let (first_us, start) = *origin.get_or_insert((frame.ts_us, Instant::now()));
            let due = start + Duration::from_micros(frame.ts_us.saturating_sub(first_us));
            if due > Instant::now() {
                if !batcher.flush().await {
                    break;
                }
                tokio::select! {
                    () = tokio::time::sleep_until(due) => {}
                    () = cancel.cancelled() => break,
                }
            }
        }
        if options.restamp {
            frame.ts_us = now_us();
        }
        stats.frames += 1;
        if !batcher.push(Input::Frame(frame)).await {
            break;
        }
    }
    batcher.flush().await;
    stats
}

fn bad_line(counters: &Counters, number: usize, error: &dyn std::fmt::Display) {
    let count = Counters::bump(&counters.bad_lines);
    if worth_logging(count) {
        warn!(line = number + 1, %error, count, "log line skipped");
    }
}
