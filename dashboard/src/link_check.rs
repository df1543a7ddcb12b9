//! The pit view's link and model without a window: follows the car until the session is
//! whole (every packet wanted held, nothing being caught up) or time runs out, and reports
//! what arrived and how. For checking a link end to end: the virtual Pi's radio scenario runs
//! it behind netem, as the pit laptop's dashboard would run.

use crate::config::Config;
use crate::link::{self, Event, Settings};
use crate::model::{Dashboard, Update};
use iced::futures::StreamExt;
use serde::Serialize;
use std::time::{Duration, Instant, SystemTime};

/// What the follower saw.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Report {
    /// Every wanted packet held and nothing being caught up, before the time ran out.
    pub whole: bool,
    /// Telemetry packets in the session record (live and history merged).
    pub packets: usize,
    /// Of those, merged from the Pi's history.
    pub backfilled: u64,
    /// Live packets: how long after the Pi received them they arrived (ms).
    pub live_packets: u64,
    pub latency_p50_ms: f64,
    pub latency_p99_ms: f64,
    /// Stream batches missed live, recovered from history, and no longer held by the Pi.
    pub stream_gaps: u64,
    pub recovered: u64,
    pub not_held: u64,
    /// Times the link was lost.
    pub dropouts: u64,
    /// For each dropout, the seconds from the link's return until the session was whole
    /// again.
    pub catch_up_s: Vec<f64>,
    /// Seconds followed.
    pub followed_s: f64,
    /// How far behind the Pi's gate saw this client at worst, by its status each second
    /// (ms), and the live messages it dropped for it (the newest were sent instead).
    pub gate_lag_max_ms: u64,
    pub gate_dropped: u64,
}

/// Follows the car `config` describes until `packets` are held and nothing is being caught
/// up, or `timeout`.
pub async fn follow(config: &Config, packets: usize, timeout: Duration) -> Report {
    let started = Instant::now();
    let mut model = Dashboard::new(config);
    let mut updates = Box::pin(link::stream(Settings::from_config(config)));
    let mut report = Report::default();
    let mut latencies: Vec<f64> = Vec::new();
    let mut lost_at: Option<Instant> = None;
    // The link's return after a dropout, and whether the history has started catching up.
    let mut back_at: Option<Instant> = None;
    let mut caught_gap = false;
    let deadline = tokio::time::Instant::now() + timeout;
    loop {
        let event = match tokio::time::timeout_at(deadline, updates.next()).await {
            Ok(Some(event)) => event,
            Ok(None) | Err(_) => break,
        };
        let Event::Update(at, update) = event else {
            continue;
        };
        match &update {
            Update::Telemetry(sample) => {
                let now = SystemTime::now()
                    .duration_since(SystemTime::UNIX_EPOCH)
                    .map_or(0.0, |d| d.as_secs_f64());
                latencies.push((now - sample.ts) * 1_000.0);
            }
            Update::Disconnected(_) if lost_at.is_none() => {
                lost_at = Some(at);
                report.dropouts += 1;
            }
            Update::Connected if lost_at.take().is_some() => back_at = Some(at),
            _ => {}
        }
        model.apply(update, at);
        model.settle(at);
        if let Some(served) = model.health().served() {
            report.gate_lag_max_ms = report.gate_lag_max_ms.max(served.lag_ms);
            report.gate_dropped = report.gate_dropped.max(served.dropped);
        }
        let catching_up = model.health().backfill.is_some_and(|b| b.catching_up);
        if let Some(back) = back_at {
            if catching_up {
                caught_gap = true;
            } else if caught_gap {
                report
                    .catch_up_s
                    .push(at.saturating_duration_since(back).as_secs_f64());
                back_at = None;
                caught_gap = false;
            }
        }
        let held = model.session_record().map_or(0, |record| record.len());
        if held >= packets && !catching_up && lost_at.is_none() {
            report.whole = true;
            break;
        }
    }
    // What waits is merged before counting.
    model.settle(Instant::now() + Duration::from_secs(60));
    let health = model.health();
    report.packets = model.session_record().map_or(0, |record| record.len());
    report.backfilled = health.backfilled;
    report.live_packets = latencies.len() as u64;
    latencies.sort_by(f64::total_cmp);
    report.latency_p50_ms = percentile(&latencies, 0.50);
    report.latency_p99_ms = percentile(&latencies, 0.99);
    report.stream_gaps = health.stream_gaps;
    if let Some(progress) = health.backfill {
        report.recovered = progress.recovered;
        report.not_held = progress.not_held;
    }
    report.followed_s = started.elapsed().as_secs_f64();
    report
}

fn percentile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return 0.0;
    }
    let at = ((sorted.len() - 1) as f64 * q).round() as usize;
    sorted.get(at).copied().unwrap_or_default()
}

#[cfg(test)]
mod tests {
    #[test]
    fn percentiles_pick_the_nearest_rank() {
        let values: Vec<f64> = (1..=100).map(f64::from).collect();
        assert_eq!(super::percentile(&values, 0.5), 51.0);
        assert_eq!(super::percentile(&values, 0.99), 99.0);
        assert_eq!(super::percentile(&[], 0.5), 0.0);
    }
}
