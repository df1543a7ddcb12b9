//! What the report says about a run: each lap's and the whole session's figures, and every
//! field that crossed its schema threshold (the pit view's warning and critical levels), with
//! when and for how long.

use super::run::Run;
use aer::telemetry::{Level, Telemetry};

/// The temperatures a lap's row shows at their highest, by field.
pub const TEMPERATURES: [(&str, &str); 3] = [
    ("motor_temp", "motor"),
    ("inverter_temp", "inverter"),
    ("pack_temp", "pack"),
];

/// One stretch of the run: a lap, or the whole session.
#[derive(Debug, Clone, PartialEq)]
pub struct Stretch {
    /// When it started and ended (s since the session began).
    pub start: f64,
    pub end: f64,
    pub distance_m: f64,
    pub top_speed_kmh: f64,
    /// Energy drawn from the battery less energy regenerated (Wh).
    pub energy_wh: f64,
    pub peak_power_kw: f64,
    pub peak_torque_nm: f64,
    /// The highest of each of [`TEMPERATURES`] (degC; NaN without packets).
    pub max_temps: [f64; 3],
}

impl Stretch {
    pub fn time(&self) -> f64 {
        self.end - self.start
    }
}

/// The figures of the packets from `start` to `end` of `run`.
pub fn stretch(run: &Run, start: f64, end: f64) -> Stretch {
    let span = run.span(start, end);
    let samples = run.derived.get(span.clone()).unwrap_or_default();
    let max = |values: &mut dyn Iterator<Item = f64>| {
        values.filter(|v| v.is_finite()).fold(f64::NAN, f64::max)
    };
    let delta =
        |value: fn(&aer_host::run::derived::Sample) -> f64| match (samples.first(), samples.last())
        {
            (Some(first), Some(last)) => value(last) - value(first),
            _ => 0.0,
        };
    let field_max = |name: &str| {
        max(&mut run
            .field(name)
            .get(span.clone())
            .unwrap_or_default()
            .iter()
            .copied())
    };
    Stretch {
        start,
        end,
        distance_m: delta(|s| s.distance_m),
        top_speed_kmh: max(&mut samples.iter().map(|s| s.speed_m_s * 3.6)),
        energy_wh: delta(|s| s.energy_j) / 3_600.0,
        peak_power_kw: max(&mut samples.iter().map(|s| s.power_w / 1_000.0)),
        peak_torque_nm: field_max("motor_torque"),
        max_temps: TEMPERATURES.map(|(name, _)| field_max(name)),
    }
}

/// Each completed lap's figures, in order.
pub fn laps(run: &Run) -> Vec<Stretch> {
    run.laps
        .iter()
        .map(|lap| stretch(run, lap.start, lap.end))
        .collect()
}

/// The whole session's figures, from its start to its end.
pub fn session(run: &Run) -> Stretch {
    stretch(run, 0.0, run.length_s())
}

/// A field that reached a warning or critical level.
#[derive(Debug, Clone, PartialEq)]
pub struct Alarm {
    pub field: &'static str,
    pub label: &'static str,
    pub unit: &'static str,
    pub level: Level,
    /// When it first reached that level (s since the session began).
    pub first: f64,
    /// How long it stayed at that level or above, in all (s).
    pub duration_s: f64,
    /// How often it reached it.
    pub times: usize,
    /// Its most extreme value at that level.
    pub worst: f64,
}

/// Every field with thresholds that reached a warning or critical level, worst first.
pub fn alarms(run: &Run) -> Vec<Alarm> {
    let mut alarms = Vec::new();
    for (meta, display) in Telemetry::FIELDS.iter().zip(Telemetry::DISPLAY) {
        if !display.has_thresholds() {
            continue;
        }
        let values = run.field(meta.name);
        for level in [Level::Critical, Level::Warn] {
            let mut alarm: Option<Alarm> = None;
            let mut was = false;
            for (i, &value) in values.iter().enumerate() {
                let at = display.level(value) >= level;
                if at {
                    let t = run.t.get(i).copied().unwrap_or(f64::NAN);
                    let next = run.t.get(i + 1).copied().unwrap_or(t);
                    let step = (next - t).clamp(0.0, aer_host::run::derived::MAX_STEP_S);
                    let found = alarm.get_or_insert(Alarm {
                        field: meta.name,
                        label: display.label,
                        unit: meta.unit,
                        level,
                        first: t,
                        duration_s: 0.0,
                        times: 0,
                        worst: value,
                    });
                    found.duration_s += step;
                    found.times += usize::from(!was);
                    let below = display.critical_below.or(display.warn_below);
                    let lower_is_worse = below.is_some_and(|b| value < b);
                    if (lower_is_worse && value < found.worst)
                        || (!lower_is_worse && value > found.worst)
                    {
                        found.worst = value;
                    }
                }
                was = at;
            }
            if let Some(alarm) = alarm {
                alarms.push(alarm);
                // A field that went critical is listed once, at that level.
                break;
            }
        }
    }
    alarms.sort_by(|a, b| b.level.cmp(&a.level).then(a.first.total_cmp(&b.first)));
    alarms
}
