//! The lap timer. The schema has no lap beacon, so a lap ends when the car has covered the
//! configured lap length (distance integrated from its speed) or when someone marks it (key
//! `L`). Times are packet times, so a replay times laps as they were driven.

/// Gaps between packets longer than this are not integrated (the car was not seen).
const MAX_STEP_S: f64 = 0.5;

/// Lap times so far and the lap in progress.
#[derive(Debug, Clone, PartialEq)]
pub struct LapTimer {
    lap_length_m: Option<f64>,
    /// Start of the lap in progress (s), once the car first drove.
    start: Option<f64>,
    distance_m: f64,
    last_ts: Option<f64>,
    laps: Vec<f64>,
}

impl LapTimer {
    /// A timer that ends laps every `lap_length_m` metres (or only by hand with `None`).
    pub fn new(lap_length_m: Option<f64>) -> Self {
        Self {
            lap_length_m,
            start: None,
            distance_m: 0.0,
            last_ts: None,
            laps: Vec::new(),
        }
    }

    /// Takes one packet: its time (s), the car's speed (m/s) and whether it is in DRIVING. The
    /// first lap starts the first time the car is driving.
    pub fn update(&mut self, ts: f64, speed_m_s: f64, driving: bool) {
        let previous = self.last_ts.replace(ts);
        let Some(start) = self.start else {
            if driving {
                self.start = Some(ts);
            }
            return;
        };
        if ts < start {
            // Time went backwards: a replay restarted.
            *self = Self::new(self.lap_length_m);
            return self.update(ts, speed_m_s, driving);
        }
        let step = previous.map_or(0.0, |p| ts - p);
        if (0.0..=MAX_STEP_S).contains(&step) && speed_m_s.is_finite() {
            self.distance_m += speed_m_s.max(0.0) * step;
        }
        if let Some(length) = self.lap_length_m
            && self.distance_m >= length
        {
            self.distance_m -= length;
            self.complete(ts);
        }
    }

    /// Ends the lap in progress at `ts` (s) by hand; starts the first one if none runs.
    pub fn mark(&mut self, ts: f64) {
        if self.start.is_some() {
            self.complete(ts);
        } else {
            self.start = Some(ts);
        }
        self.distance_m = 0.0;
    }

    fn complete(&mut self, ts: f64) {
        if let Some(start) = self.start.replace(ts) {
            self.laps.push(ts - start);
        }
    }

    /// The lap in progress: its number (from 1) and time so far at `ts`.
    pub fn current(&self, ts: f64) -> Option<(usize, f64)> {
        self.start
            .map(|start| (self.laps.len() + 1, (ts - start).max(0.0)))
    }

    /// The last completed lap's time.
    pub fn last(&self) -> Option<f64> {
        self.laps.last().copied()
    }

    /// The fastest completed lap's time.
    pub fn best(&self) -> Option<f64> {
        self.laps.iter().copied().reduce(f64::min)
    }
}

/// A lap time as `m:ss.s`.
pub fn format_lap(seconds: f64) -> String {
    let tenths = (seconds.max(0.0) * 10.0).round() as u64;
    format!("{}:{:02}.{}", tenths / 600, tenths / 10 % 60, tenths % 10)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn laps_end_each_time_the_lap_length_is_covered() {
        let mut timer = LapTimer::new(Some(100.0));
        timer.update(0.0, 0.0, false);
        assert_eq!(timer.current(0.0), None);
        timer.update(1.0, 0.0, true);
        // 10 m/s for 10 s = 100 m: the lap ends at 11.0 s.
        for i in 1..=1_500 {
            timer.update(1.0 + f64::from(i) * 0.01, 10.0, true);
        }
        assert_eq!(timer.laps.len(), 1);
        assert!(
            (timer.last().unwrap() - 10.0).abs() < 0.011,
            "{:?}",
            timer.last()
        );
        let (lap, time) = timer.current(16.0).unwrap();
        assert_eq!(lap, 2);
        assert!((time - 5.0).abs() < 0.011);
    }

    #[test]
    fn marking_by_hand_and_the_best_lap() {
        let mut timer = LapTimer::new(None);
        timer.mark(10.0);
        timer.mark(75.5);
        timer.mark(137.0);
        assert_eq!(timer.last(), Some(61.5));
        assert_eq!(timer.best(), Some(61.5));
        timer.mark(210.0);
        assert_eq!(timer.best(), Some(61.5));
        assert_eq!(timer.last(), Some(73.0));
        assert_eq!(format_lap(61.54), "1:01.5");
        assert_eq!(format_lap(9.96), "0:10.0");
    }

    #[test]
    fn gaps_in_the_data_are_not_counted_as_distance() {
        let mut timer = LapTimer::new(Some(100.0));
        timer.update(0.0, 10.0, true);
        timer.update(60.0, 10.0, true);
        assert!(timer.laps.is_empty());
    }
}
