//! A session's telemetry as the report reads it: each packet's time since the session began,
//! every numeric field, the derived channels (speed, power, distance, energy: the tiers' one
//! rule in `aer_host::run::derived`) and the laps, timed by the driver's display's rule with
//! the marks the session recorded.

use super::ReportError;
use crate::export::columns::Values;
use crate::export::load::{self, Selection};
use crate::store::events::{self, Kind};
use crate::store::session::Session;
use aer::tables::TELEMETRY;
use aer::telemetry::Telemetry;
use aer_host::run::derived::{self, Integrator, Sample};
use aer_host::run::laps::{Lap, LapTimer};
use rusqlite::Connection;
use std::collections::BTreeMap;

/// A session's run.
#[derive(Debug, Clone)]
pub struct Run {
    pub session: Session,
    /// Each packet's receive time, seconds since the session began.
    pub t: Vec<f64>,
    /// Every numeric telemetry field, per packet (NaN where the store has none).
    pub fields: BTreeMap<&'static str, Vec<f64>>,
    /// The derived channels, per packet.
    pub derived: Vec<Sample>,
    /// The laps completed.
    pub laps: Vec<Lap>,
    /// The marks the session recorded (s since it began).
    pub marks: Vec<f64>,
    /// The lap length the laps were timed with, if any.
    pub lap_length_m: Option<f64>,
    /// What the times count from (us since the epoch): the session's start, or a replay's
    /// first packet.
    pub origin_us: i64,
}

impl Run {
    /// Field `name`'s values (empty if the telemetry has no such field).
    pub fn field(&self, name: &str) -> &[f64] {
        self.fields.get(name).map_or(&[], Vec::as_slice)
    }

    /// The packets received from `start` to `end` (s), as an index range.
    pub fn span(&self, start: f64, end: f64) -> std::ops::Range<usize> {
        let from = self.t.partition_point(|&t| t < start);
        let to = self.t.partition_point(|&t| t <= end);
        from..to.max(from)
    }

    /// The session's length (s): to its end, or to its last packet while it is open (or for
    /// a replay).
    pub fn length_s(&self) -> f64 {
        match self.session.ended_us {
            Some(end) if self.origin_us == self.session.started_us => {
                (end - self.session.started_us) as f64 / 1e6
            }
            _ => self.t.last().copied().unwrap_or(0.0),
        }
    }
}

/// The raw value of the vehicle state DRIVING, from the schema's value names.
fn driving_state() -> Option<f64> {
    Telemetry::FIELDS
        .iter()
        .find(|f| f.name == "vehicle_state")
        .and_then(|f| f.labels.iter().find(|(_, label)| *label == "DRIVING"))
        .map(|(raw, _)| *raw as f64)
}

/// Reads session `session`'s telemetry and times its laps (every `lap_length_m` metres, at
/// the marks, and at the end of each run).
pub fn load(
    db: &Connection,
    session: &Session,
    lap_length_m: Option<f64>,
) -> Result<Run, ReportError> {
    let data = load::table(
        db,
        &TELEMETRY,
        Selection {
            session: Some(session.id),
            ..Selection::default()
        },
    )?;
    // Times from the session's start; a replay's rows carry the recorded times, from before
    // the session (the replay) began: those count from the first packet.
    let first = data.timestamps().iter().flatten().next().copied();
    let within = |ts: i64| ts >= session.started_us && session.ended_us.is_none_or(|end| ts <= end);
    let origin = match first {
        Some(first) if !within(first) => first,
        _ => session.started_us,
    };
    let t: Vec<f64> = data
        .timestamps()
        .iter()
        .map(|ts| ts.map_or(f64::NAN, |ts| (ts - origin) as f64 / 1e6))
        .collect();
    let mut fields = BTreeMap::new();
    for (column, values) in data.columns() {
        if let Some(numbers) = numbers(values) {
            fields.insert(column.name, numbers);
        }
    }
    let column = |name: &str| fields.get(name).cloned().unwrap_or_default();
    let [rpm, volts, amps] = derived::INPUTS.map(column);
    let state = column("vehicle_state");
    let driving = driving_state();
    let marks: Vec<f64> = events::list(db, session.id)?
        .into_iter()
        .filter(|e| e.kind == Kind::Mark)
        .map(|e| (e.at_us - origin) as f64 / 1e6)
        .collect();
    let mut sorted_marks = marks.clone();
    sorted_marks.sort_by(f64::total_cmp);
    let mut pending = sorted_marks.into_iter().peekable();
    let mut timer = LapTimer::new(lap_length_m);
    let mut integrator = Integrator::default();
    let value = |column: &[f64], i: usize| column.get(i).copied().unwrap_or(f64::NAN);
    let mut samples = Vec::with_capacity(t.len());
    for (i, &ts) in t.iter().enumerate() {
        while let Some(mark) = pending.next_if(|&mark| mark <= ts) {
            timer.mark(mark);
        }
        let speed = derived::road_speed_m_s(value(&rpm, i));
        let power = value(&volts, i) * value(&amps, i);
        samples.push(integrator.step(ts, speed, power));
        let is_driving = driving.is_some_and(|d| value(&state, i) == d);
        timer.update(ts, speed, is_driving);
    }
    pending.for_each(|mark| timer.mark(mark));
    Ok(Run {
        session: session.clone(),
        t,
        fields,
        derived: samples,
        laps: timer.laps().to_vec(),
        marks,
        lap_length_m,
        origin_us: origin,
    })
}

/// A column as numbers (flags as 0 and 1, NaN where empty); `None` for text.
pub(crate) fn numbers(values: &Values) -> Option<Vec<f64>> {
    let or_nan = |v: Option<f64>| v.unwrap_or(f64::NAN);
    Some(match values {
        Values::Bool(v) => v
            .iter()
            .map(|b| or_nan(b.map(|b| f64::from(u8::from(b)))))
            .collect(),
        Values::Int(v) => v.iter().map(|x| or_nan(x.map(|x| x as f64))).collect(),
        Values::UInt(v) => v.iter().map(|x| or_nan(x.map(|x| x as f64))).collect(),
        Values::F32(v) => v.iter().map(|x| or_nan(x.map(f64::from))).collect(),
        Values::F64(v) => v.iter().map(|x| or_nan(*x)).collect(),
        Values::Text(_) => return None,
    })
}
