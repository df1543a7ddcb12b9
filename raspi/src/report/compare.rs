//! Two runs against distance: each run's distance and time measured from its start (the first
//! lap's start, the car's first movement in DRIVING; the session's start without laps), so
//! the time delta at each distance says where one run gained on the other.

use super::run::Run;

/// One packet of a run from its start.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FromStart {
    pub distance_m: f64,
    pub time_s: f64,
    pub speed_kmh: f64,
}

/// One run from its start, per packet (distance not decreasing).
pub fn from_start(run: &Run) -> Vec<FromStart> {
    let start = run.laps.first().map_or(0.0, |lap| lap.start);
    let span = run.span(start, f64::INFINITY);
    let samples = run.derived.get(span.clone()).unwrap_or_default();
    let times = run.t.get(span).unwrap_or_default();
    let d0 = samples.first().map_or(0.0, |s| s.distance_m);
    samples
        .iter()
        .zip(times)
        .map(|(s, &t)| FromStart {
            distance_m: s.distance_m - d0,
            time_s: t - start,
            speed_kmh: s.speed_m_s * 3.6,
        })
        .collect()
}

/// The time (s) at which a run from its start reached `distance` (interpolated), if it did.
fn time_at(run: &[(f64, f64)], distance: f64) -> Option<f64> {
    let after = run.partition_point(|&(d, _)| d < distance);
    let &(d1, t1) = run.get(after)?;
    match after.checked_sub(1).and_then(|i| run.get(i)) {
        Some(&(d0, t0)) if d1 > d0 => Some(t0 + (t1 - t0) * (distance - d0) / (d1 - d0)),
        _ => Some(t1),
    }
}

/// `other`'s time less `run`'s at each distance both covered, about 1,000 points: positive
/// where `other` is behind.
pub fn time_delta(run: &Run, other: &Run) -> Vec<(f64, f64)> {
    let path = |run: &Run| -> Vec<(f64, f64)> {
        from_start(run)
            .iter()
            .map(|p| (p.distance_m, p.time_s))
            .collect()
    };
    let (a, b) = (path(run), path(other));
    let total = match (a.last(), b.last()) {
        (Some(&(da, _)), Some(&(db, _))) => da.min(db),
        _ => return Vec::new(),
    };
    if total <= 0.0 {
        return Vec::new();
    }
    let step = (total / 1_000.0).max(0.1);
    (0..=((total / step) as usize))
        .filter_map(|i| {
            let d = i as f64 * step;
            Some((d, time_at(&b, d)? - time_at(&a, d)?))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_time_at_a_distance_is_interpolated_between_packets() {
        let run = [(0.0, 0.0), (10.0, 1.0), (10.0, 1.5), (30.0, 2.5)];
        assert_eq!(time_at(&run, 0.0), Some(0.0));
        assert_eq!(time_at(&run, 5.0), Some(0.5));
        assert_eq!(time_at(&run, 20.0), Some(2.0));
        assert_eq!(time_at(&run, 31.0), None, "never got there");
    }
}
