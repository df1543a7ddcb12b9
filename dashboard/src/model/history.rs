//! The last seconds of every field, for the pit view's plots: one row per packet in a ring, so
//! a field picked for plotting shows its past at once.

use super::fields::FieldValue;
use std::collections::VecDeque;

/// A time jump backwards by more than this starts a new history (a replay restarted).
const RESTART_S: f64 = 1.0;

/// Rows of (time, every field's value) over a sliding window.
#[derive(Debug, Clone)]
pub struct History {
    window_s: f64,
    width: usize,
    times: VecDeque<f64>,
    /// `width` values per row, row after row.
    values: VecDeque<f32>,
}

/// One plotted series, reduced for drawing.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Series {
    /// (seconds before the newest row, value), oldest first.
    pub points: Vec<(f32, f32)>,
    pub min: f32,
    pub max: f32,
}

impl History {
    /// Keeps `window_s` seconds of rows of `width` fields.
    pub fn new(window_s: f64, width: usize) -> Self {
        Self {
            window_s,
            width,
            times: VecDeque::new(),
            values: VecDeque::new(),
        }
    }

    /// Appends a packet's values at time `ts` (s) and forgets rows older than the window.
    pub fn push(&mut self, ts: f64, row: &[FieldValue]) {
        if self.times.back().is_some_and(|&last| ts < last - RESTART_S) {
            self.times.clear();
            self.values.clear();
        }
        self.times.push_back(ts);
        self.values
            .extend((0..self.width).map(|i| row.get(i).map_or(f32::NAN, |v| v.value as f32)));
        while self.times.front().is_some_and(|&t| t < ts - self.window_s) {
            self.times.pop_front();
            self.values.drain(..self.width);
        }
    }

    /// Rows held.
    pub fn len(&self) -> usize {
        self.times.len()
    }

    /// True before the first packet.
    pub fn is_empty(&self) -> bool {
        self.times.is_empty()
    }

    /// The seconds the plots span.
    pub fn window_s(&self) -> f64 {
        self.window_s
    }

    /// Field `field` over the window, reduced to at most `max_points` points (each bucket keeps
    /// its minimum and maximum, so spikes survive the reduction).
    pub fn series(&self, field: usize, max_points: usize) -> Series {
        let Some(&newest) = self.times.back() else {
            return Series::default();
        };
        let rows = self.times.len();
        let bucket = rows.div_ceil(max_points.max(2) / 2).max(1);
        let mut series = Series {
            points: Vec::with_capacity(rows.min(max_points)),
            min: f32::INFINITY,
            max: f32::NEG_INFINITY,
        };
        let value = |row: usize| self.values.get(row * self.width + field).copied();
        let age = |row: usize| self.times.get(row).map_or(0.0, |&t| (newest - t) as f32);
        let mut start = 0;
        while start < rows {
            let end = (start + bucket).min(rows);
            let (mut low, mut high) = (None::<(usize, f32)>, None::<(usize, f32)>);
            for row in start..end {
                let Some(v) = value(row).filter(|v| v.is_finite()) else {
                    continue;
                };
                if low.is_none_or(|(_, l)| v < l) {
                    low = Some((row, v));
                }
                if high.is_none_or(|(_, h)| v > h) {
                    high = Some((row, v));
                }
            }
            if let (Some(low), Some(high)) = (low, high) {
                let (first, second) = if low.0 <= high.0 {
                    (low, high)
                } else {
                    (high, low)
                };
                series.points.push((age(first.0), first.1));
                if second.0 != first.0 {
                    series.points.push((age(second.0), second.1));
                }
                series.min = series.min.min(low.1);
                series.max = series.max.max(high.1);
            }
            start = end;
        }
        series
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(values: &[f64]) -> Vec<FieldValue> {
        values
            .iter()
            .map(|&value| FieldValue { value, label: None })
            .collect()
    }

    #[test]
    fn rows_older_than_the_window_are_forgotten() {
        let mut history = History::new(30.0, 2);
        // Quarter seconds are exact in binary, so the window's edge is exact too.
        for i in 0..400 {
            let t = f64::from(i) * 0.25;
            history.push(t, &row(&[t, -t]));
        }
        // 99.75 s of data, the last 30 s kept (the row exactly 30 s old stays): 69.75..=99.75.
        assert_eq!(history.len(), 121);
        let series = history.series(1, 10_000);
        assert_eq!(series.points.len(), 121);
        assert_eq!(series.max, -69.75);
        assert_eq!(series.min, -99.75);
        assert_eq!(series.points.first().map(|p| p.0), Some(30.0));
        assert_eq!(series.points.last().map(|p| p.0), Some(0.0));
    }

    #[test]
    fn reduction_keeps_spikes_and_the_point_budget() {
        let mut history = History::new(60.0, 1);
        for i in 0..6_000 {
            let v = if i == 4_321 { 500.0 } else { 1.0 };
            history.push(f64::from(i) * 0.01, &row(&[v]));
        }
        let series = history.series(0, 400);
        assert!(series.points.len() <= 400, "{}", series.points.len());
        assert_eq!(series.max, 500.0);
        assert!(series.points.iter().any(|p| p.1 == 500.0));
    }

    #[test]
    fn a_restarted_replay_starts_a_new_history() {
        let mut history = History::new(60.0, 1);
        history.push(100.0, &row(&[1.0]));
        history.push(100.01, &row(&[2.0]));
        history.push(10.0, &row(&[3.0]));
        assert_eq!(history.len(), 1);
    }
}
