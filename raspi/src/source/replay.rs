//! A recorded log, at recorded speed or flat out: candump text (`candump -l` / `-L`) or a
//! segment of the service's own raw log.

use super::{Batcher, BusNames, Input, Sender};
use aer_host::clock::now_us;
use aer_host::formats::candump::{LoggedFrame, parse_line};
use aer_host::formats::raw_format::SegmentReader;
use aer_host::reports::counters::{Counters, worth_logging};
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

/// Hands frames on at their recorded pace (or flat out), restamped if asked.
struct Pacer {
    batcher: Batcher,
    buses: BusNames,
    options: ReplayOptions,
    origin: Option<(u64, Instant)>,
}

impl Pacer {
    fn new(out: Sender, options: ReplayOptions) -> Self {
        Self {
            batcher: Batcher::new(out),
            buses: BusNames::default(),
            options,
            origin: None,
        }
    }

    /// Sends `frame` from interface `interface` when it is due; false once nothing
    /// downstream listens or `cancel` fired.
    async fn send(
        &mut self,
        interface: &str,
        mut frame: LoggedFrame,
        cancel: &CancellationToken,
    ) -> bool {
        let (bus, announcement) = self.buses.index(interface);
        frame.bus = bus;
        if let Some(announcement) = announcement
            && !self.batcher.push(announcement).await
        {
            return false;
        }
        if !self.options.fast {
            let (first_us, start) = *self.origin.get_or_insert((frame.ts_us, Instant::now()));
            let due = start + Duration::from_micros(frame.ts_us.saturating_sub(first_us));
            if due > Instant::now() {
                if !self.batcher.flush().await {
                    return false;
                }
                tokio::select! {
                    () = tokio::time::sleep_until(due) => {}
                    () = cancel.cancelled() => return false,
                }
            }
        }
        if self.options.restamp {
            frame.ts_us = now_us();
        }
        self.batcher.push(Input::Frame(frame)).await
    }

    async fn finish(mut self) {
        self.batcher.flush().await;
    }
}

/// Replays a raw log segment (`data`, its whole bytes) into `out` until its end, `cancel`, or
/// nothing downstream listening. Damaged or cut-short blocks are counted (`bad_lines`),
/// logged and skipped.
pub(crate) async fn replay_segment(
    data: &[u8],
    out: Sender,
    counters: &Counters,
    options: ReplayOptions,
    cancel: &CancellationToken,
) -> Result<ReplayStats, aer_host::formats::raw_format::RawError> {
    let reader = SegmentReader::new(data)?;
    let mut stats = ReplayStats::default();
    let mut pacer = Pacer::new(out, options);
    for (number, item) in reader.enumerate() {
        if cancel.is_cancelled() {
            break;
        }
        stats.lines += 1;
        match item {
            Ok(raw) => {
                stats.frames += 1;
                if !pacer.send(&raw.interface, raw.frame, cancel).await {
                    break;
                }
            }
            Err(error) => {
                stats.bad_lines += 1;
                bad_line(counters, number, &error);
            }
        }
    }
    pacer.finish().await;
    Ok(stats)
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
    let mut pacer = Pacer::new(out, options);
    let mut interface = String::new();
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
        let parsed = parse_line(&line, |name| {
            interface.clear();
            interface.push_str(name);
            0
        });
        let frame = match parsed {
            Ok(frame) => frame,
            Err(error) => {
                stats.bad_lines += 1;
                bad_line(counters, number, &error);
                continue;
            }
        };
        stats.frames += 1;
        if !pacer.send(&interface, frame, cancel).await {
            break;
        }
    }
    pacer.finish().await;
    stats
}

fn bad_line(counters: &Counters, number: usize, error: &dyn std::fmt::Display) {
    let count = Counters::bump(&counters.bad_lines);
    if worth_logging(count) {
        warn!(line = number + 1, %error, count, "log line skipped");
    }
}
