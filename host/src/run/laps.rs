//! The lap timer, one rule for the driver's display and the Pi's run report. The schema has no
//! lap beacon, so a lap ends when the car has covered the
//! configured lap length (distance integrated from its speed), when someone marks it (key
//! `L`), or when the run ends: the car leaves DRIVING, or stands still for [`STOP_S`]. An
//! autocross, acceleration or skidpad run is timed from the car's first movement to its stop
//! (the demo's session is one such run, so each loop of the demo closes a lap); an endurance
//! stint needs the lap length. Times are packet times, so a replay times laps as they were
//! driven.

use super::derived::MAX_STEP_S;

/// Below this speed the car stands still (m/s, 1.8 km/h).
const MOVING_M_S: f64 = 0.5;
/// Standing still this long ends the run; the run's time ends when the car stopped (s).
pub const STOP_S: f64 = 3.0;

/// A completed lap: when it started and ended (s, packet time).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lap {
    pub start: f64,
    pub end: f64,
}

impl Lap {
    /// Its time (s).
    pub fn time(&self) -> f64 {
        self.end - self.start
    }
}

/// Lap times so far and the lap in progress.
#[derive(Debug, Clone, PartialEq)]
pub struct LapTimer {
    lap_length_m: Option<f64>,
    /// Start of the lap in progress (s), while a run is on.
    start: Option<f64>,
    /// When the car last came to a standstill during the run.
    stopped_at: Option<f64>,
    distance_m: f64,
    last_ts: Option<f64>,
    laps: Vec<Lap>,
}

impl LapTimer {
    /// A timer that ends laps every `lap_length_m` metres (with `None`: at the end of a run
    /// or by hand).
    pub fn new(lap_length_m: Option<f64>) -> Self {
        Self {
            lap_length_m,
            start: None,
            stopped_at: None,
            distance_m: 0.0,
            last_ts: None,
            laps: Vec::new(),
        }
    }

    /// Takes one packet: its time (s), the car's speed (m/s) and whether it is in DRIVING. A
    /// run (and its first lap) starts when the car first moves in DRIVING.
    pub fn update(&mut self, ts: f64, speed_m_s: f64, driving: bool) {
        let previous = self.last_ts.replace(ts);
        let moving = speed_m_s.is_finite() && speed_m_s >= MOVING_M_S;
        let Some(start) = self.start else {
            if driving && moving {
                self.start = Some(ts);
                self.stopped_at = None;
                self.distance_m = 0.0;
            }
            return;
        };
        if ts < start {
            // Time went backwards: a replay restarted.
            let laps = std::mem::take(&mut self.laps);
            *self = Self::new(self.lap_length_m);
            self.laps = laps;
            return self.update(ts, speed_m_s, driving);
        }
        if !driving {
            self.end_run(ts);
            return;
        }
        if moving {
            self.stopped_at = None;
        } else {
            let stopped = *self.stopped_at.get_or_insert(ts);
            if ts - stopped >= STOP_S {
                self.end_run(stopped);
                return;
            }
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
        self.stopped_at = None;
        self.distance_m = 0.0;
    }

    fn complete(&mut self, ts: f64) {
        if let Some(start) = self.start.replace(ts) {
            self.laps.push(Lap { start, end: ts });
        }
    }

    /// The run ended at `ts`: its last lap is complete, and the next starts with the next run.
    fn end_run(&mut self, ts: f64) {
        self.complete(ts);
        self.start = None;
        self.stopped_at = None;
        self.distance_m = 0.0;
    }

    /// The lap in progress: its number (from 1) and time so far at `ts`.
    pub fn current(&self, ts: f64) -> Option<(usize, f64)> {
        self.start
            .map(|start| (self.laps.len() + 1, (ts - start).max(0.0)))
    }

    /// Laps completed so far.
    pub fn completed(&self) -> usize {
        self.laps.len()
    }

    /// The last completed lap's time.
    pub fn last(&self) -> Option<f64> {
        self.laps.last().map(Lap::time)
    }

    /// The fastest completed lap's time.
    pub fn best(&self) -> Option<f64> {
        self.laps.iter().map(Lap::time).reduce(f64::min)
    }

    /// The laps completed so far, in order.
    pub fn laps(&self) -> &[Lap] {
        &self.laps
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
        // Moving from 1.0 s: 10 m/s for 10 s = 100 m, the lap ends at 11.0 s.
        timer.update(1.0, 10.0, true);
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
    fn a_run_ends_when_the_car_leaves_driving_or_stands_still() {
        let mut timer = LapTimer::new(None);
        timer.update(0.0, 0.0, true);
        assert_eq!(timer.current(0.0), None, "ready but not moving: no run yet");
        timer.update(2.0, 5.0, true);
        timer.update(30.0, 5.0, true);
        timer.update(32.0, 5.0, false);
        assert_eq!(timer.last(), Some(30.0), "left DRIVING at 32 s");
        assert_eq!(timer.current(33.0), None, "the next run has not started");
        // The second run stops at 50 s and stands: it ended when it stopped.
        timer.update(40.0, 3.0, true);
        timer.update(50.0, 0.0, true);
        timer.update(52.0, 0.0, true);
        assert_eq!(timer.completed(), 1, "2 s standing is a pause, not the end");
        timer.update(53.0, 0.0, true);
        assert_eq!(timer.last(), Some(10.0));
        assert_eq!(timer.best(), Some(10.0));
    }

    #[test]
    fn gaps_in_the_data_are_not_counted_as_distance() {
        let mut timer = LapTimer::new(Some(100.0));
        timer.update(0.0, 10.0, true);
        timer.update(60.0, 10.0, true);
        assert!(timer.laps.is_empty());
    }
}
