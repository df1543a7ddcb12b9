//! `aer-raspi report`: a session's run summary, what a data lead opens first after a run. From
//! the store alone: per lap (the driver's display's rule, the session's marks) its time,
//! distance, top speed, energy, peak power and torque and the hottest temperatures; every
//! field that crossed its threshold; every event the session recorded (problems as they came
//! and went, drops and integrity counts as they grew, loop points); the messages whose frames
//! failed their checks; the clock's steps; the calibration in force and its changes; plots of
//! speed, power and torque against distance. `--compare` sets another session beside it:
//! speed against distance, the time delta, and the calibration values that differ.
//!
//! [`run`] reads the telemetry, [`summary`] and [`mod@compare`] compute, [`text`] and [`html`]
//! write (`report.txt`, `report.html` with its plots inline, [`plot`]); [`resample`] puts the
//! run on a 100 Hz grid.

pub mod compare;
pub mod html;
pub mod plot;
pub mod resample;
pub mod run;
pub mod summary;
pub mod text;

use crate::store::calibration::{self, Entry, Kind as CalibrationKind};
use crate::store::events::{self, Event};
use crate::store::session;
use crate::store::session_messages::{self, MessageStats};
use rusqlite::Connection;
use std::path::{Path, PathBuf};
use summary::{Alarm, Stretch};

/// Why a report could not be made.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    #[error("reading the store: {0}")]
    Store(#[from] rusqlite::Error),
    #[error("reading the store: {0}")]
    Export(#[from] crate::export::ExportError),
    #[error("no session {0} in the store (`aer-raspi session list` shows them)")]
    NoSession(i64),
    #[error(
        "session {0} has no telemetry: nothing to report (`aer-raspi session list` shows the sessions with rows)"
    )]
    NoTelemetry(i64),
    #[error("no signal {0}: give table.column as the exports name them (`can_dti_speed.dti_erpm`)")]
    UnknownSignal(String),
    #[error("cannot write {path}: {source}")]
    Write {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

/// Everything the report says about one session.
pub struct SessionReport {
    pub run: run::Run,
    pub laps: Vec<Stretch>,
    pub whole: Stretch,
    pub alarms: Vec<Alarm>,
    pub events: Vec<Event>,
    /// Messages with any checksum failure, counter repeat or jump, or late frame.
    pub flagged_messages: Vec<MessageStats>,
    pub clock_steps: Vec<(i64, i64)>,
    /// The calibration record: its changes (not the values found), and the values at the end.
    pub calibration_changes: Vec<Entry>,
    pub calibration_at_end: Vec<(String, Option<u32>, f64)>,
}

/// The comparison with another session.
pub struct Comparison {
    pub other: SessionReport,
    /// The other's time less this one's, by distance from each run's start.
    pub time_delta: Vec<(f64, f64)>,
    /// Calibration values that differ: parameter (with element), this session's, the other's.
    pub calibration_differences: Vec<(String, Option<f64>, Option<f64>)>,
}

/// Gathers session `id`'s report; laps every `lap_length_m` if given.
pub fn gather(
    db: &Connection,
    id: i64,
    lap_length_m: Option<f64>,
) -> Result<SessionReport, ReportError> {
    let session = session::get(db, id)?.ok_or(ReportError::NoSession(id))?;
    let run = run::load(db, &session, lap_length_m)?;
    if run.t.is_empty() {
        return Err(ReportError::NoTelemetry(id));
    }
    let entries = calibration::list(db, Some(id), None, None)?;
    Ok(SessionReport {
        laps: summary::laps(&run),
        whole: summary::session(&run),
        alarms: summary::alarms(&run),
        events: events::list(db, id)?,
        flagged_messages: session_messages::list(db, id)?
            .into_iter()
            .filter(|m| {
                m.checksum_failures + m.counter_repeats + m.counter_jumps + m.late_frames > 0
            })
            .collect(),
        clock_steps: session::clock_steps(db, id)?,
        calibration_at_end: calibration::values_at_end(&entries),
        calibration_changes: entries
            .into_iter()
            .filter(|e| e.kind != CalibrationKind::Found)
            .collect(),
        run,
    })
}

/// Sets `other` beside `report`.
pub fn compare(report: &SessionReport, other: SessionReport) -> Comparison {
    let key = |(p, e, _): &(String, Option<u32>, f64)| match e {
        Some(i) => format!("{p}[{i}]"),
        None => p.clone(),
    };
    let ours: Vec<(String, f64)> = report
        .calibration_at_end
        .iter()
        .map(|v| (key(v), v.2))
        .collect();
    let theirs: Vec<(String, f64)> = other
        .calibration_at_end
        .iter()
        .map(|v| (key(v), v.2))
        .collect();
    let find = |values: &[(String, f64)], name: &str| {
        values.iter().find(|(n, _)| n == name).map(|(_, v)| *v)
    };
    let mut names: Vec<&String> = ours.iter().chain(&theirs).map(|(n, _)| n).collect();
    names.sort();
    names.dedup();
    let calibration_differences = names
        .into_iter()
        .filter_map(|name| {
            let (a, b) = (find(&ours, name), find(&theirs, name));
            (a != b).then(|| (name.clone(), a, b))
        })
        .collect();
    Comparison {
        time_delta: compare::time_delta(&report.run, &other.run),
        calibration_differences,
        other,
    }
}

/// The files a report wrote.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Written {
    pub text: PathBuf,
    pub html: PathBuf,
    pub derived: PathBuf,
}

/// The derived channels per telemetry packet as CSV: its receive time, the time since the
/// run's origin, each of [`aer_host::run::derived::CHANNELS`] in its unit, and the lap.
pub fn derived_csv(run: &run::Run) -> String {
    use aer_host::run::derived::CHANNELS;
    use std::fmt::Write as _;
    let mut out = String::from("ts_us,t_s");
    for channel in CHANNELS {
        let _ = write!(out, ",{}_{}", channel.name, channel.unit.replace('/', "_"));
    }
    out.push_str(",lap\n");
    for (t, sample) in run.t.iter().zip(&run.derived) {
        let lap = run
            .laps
            .iter()
            .position(|lap| (lap.start..=lap.end).contains(t))
            .map_or(String::new(), |i| (i + 1).to_string());
        let ts_us = run.origin_us + (t * 1e6).round() as i64;
        let _ = write!(out, "{ts_us},{t:.6}");
        for value in sample.values() {
            let _ = write!(out, ",{value:.6}");
        }
        let _ = writeln!(out, ",{lap}");
    }
    out
}

/// Writes `report.txt`, `report.html` and `derived.csv` into `dir` (created if missing).
pub fn write(
    dir: &Path,
    report: &SessionReport,
    comparison: Option<&Comparison>,
) -> Result<Written, ReportError> {
    let io = |path: &Path| {
        let path = path.to_owned();
        move |source| ReportError::Write { path, source }
    };
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    let written = Written {
        text: dir.join("report.txt"),
        html: dir.join("report.html"),
        derived: dir.join("derived.csv"),
    };
    std::fs::write(&written.derived, derived_csv(&report.run)).map_err(io(&written.derived))?;
    std::fs::write(&written.text, text::render(report, comparison)).map_err(io(&written.text))?;
    std::fs::write(&written.html, html::render(report, comparison)).map_err(io(&written.html))?;
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::events::Kind as EventKind;
    use crate::store::{Row, RowData, writer};
    use aer::can::VehicleState;
    use aer::telemetry::{Telemetry, TelemetryHeader};

    const START_US: i64 = 1_764_000_000_000_000;

    /// A session driven by hand: 100 packets a second from its start; the car in DRIVING
    /// throughout, standing for 1 s, then at `rpm` drawing 400 V x 50 A for 10 s, then
    /// standing with no current for 5 s; the motor at 95 degC, over its 100 degC warning for
    /// the last 2 s of the drive.
    fn drive(db: &mut Connection, rpm: f32) -> i64 {
        let id =
            session::begin(db, &session::Metadata::default(), "live", START_US).expect("session");
        let mut rows = Vec::new();
        for i in 0..1_600u16 {
            let t = f64::from(i) / 100.0;
            let mut telemetry = Telemetry::zeroed();
            telemetry.vehicle_state = VehicleState::Driving;
            let moving = (1.0..11.0).contains(&t);
            telemetry.motor_speed = if moving { rpm } else { 0.0 };
            telemetry.pack_voltage = 400.0;
            telemetry.pack_current = if moving { 50.0 } else { 0.0 };
            telemetry.motor_temp = if (9.0..11.0).contains(&t) { 105 } else { 95 };
            rows.push(Row {
                car_id: "car1".into(),
                ts_us: u64::try_from(START_US).expect("positive") + u64::from(i) * 10_000,
                data: RowData::Telemetry {
                    header: TelemetryHeader {
                        sequence: i,
                        timestamp_us: 0,
                    },
                    telemetry,
                },
            });
        }
        writer::commit(db, &rows).expect("commit");
        session::end(db, START_US + 16_000_000).expect("end");
        events::insert(
            db,
            id,
            &[Event {
                at_us: START_US + 5_000_000,
                kind: EventKind::Problem,
                name: "can".into(),
                text: "can1: bus-off".into(),
            }],
        )
        .expect("event");
        id
    }

    #[test]
    fn a_run_driven_by_hand_reports_the_figures_worked_out_by_hand() {
        let dir = tempfile::tempdir().expect("temp dir");
        let mut db = crate::store::open(&dir.path().join("store.sqlite")).expect("store");
        let id = drive(&mut db, 3_500.0);
        let report = gather(&db, id, None).expect("report");
        // 3,500 rpm at the motor is 1,000 rpm at the wheel (gear 3.5), a 0.35 m radius.
        let speed_m_s = std::f64::consts::TAU * 0.35 * 1_000.0 / 60.0;
        assert_eq!(report.laps.len(), 1, "one run: first movement to the stop");
        let lap = &report.laps[0];
        // It moved from 1.00 s; it stood from 11.00 s and the run ended there (3 s standing).
        assert!(
            (lap.start - 1.0).abs() < 1e-9 && (lap.end - 11.0).abs() < 1e-9,
            "{lap:?}"
        );
        // 1,000 packets of 10 ms moving, each value holding until the next packet.
        assert!((lap.distance_m - speed_m_s * 10.0).abs() < 1e-3, "{lap:?}");
        // (the f32 wheel radius of aer-params, 0.35 to 7 digits)
        assert!(
            (lap.top_speed_kmh - speed_m_s * 3.6).abs() < 1e-4,
            "{lap:?}"
        );
        // 20 kW for 10 s = 200 kJ = 55.6 Wh; the power at the stop is 0.
        assert!(
            (lap.energy_wh - 200_000.0 / 3_600.0).abs() < 1e-6,
            "{lap:?}"
        );
        assert!((lap.peak_power_kw - 20.0).abs() < 1e-9, "{lap:?}");
        assert!((lap.max_temps[0] - 105.0).abs() < 1e-9, "{lap:?}");
        assert!((report.whole.time() - 16.0).abs() < 1e-9);

        let motor = report
            .alarms
            .iter()
            .find(|a| a.field == "motor_temp")
            .expect("the motor's warning");
        assert_eq!(motor.times, 1);
        assert!((motor.first - 9.0).abs() < 1e-9 && (motor.duration_s - 2.0).abs() < 0.011);
        assert!((motor.worst - 105.0).abs() < 1e-9);

        let text = text::render(&report, None);
        for expected in [
            "0:10.0",
            "131.9 km/h",
            "55.6 Wh",
            "20.0 kW",
            "105 degC",
            "can1: bus-off",
            "Motor (motor_temp): first at 0:09.0",
        ] {
            assert!(text.contains(expected), "no {expected:?} in:\n{text}");
        }
        let csv = derived_csv(&report.run);
        assert!(csv.starts_with(
            "ts_us,t_s,speed_km_h,battery_power_kW,distance_m,battery_energy_Wh,lap\n"
        ));
        let last = csv.lines().last().expect("rows");
        assert!(
            last.starts_with("1764000015990000,15.990000,0.000000,0.000000,366.5"),
            "{last}"
        );
        assert_eq!(csv.lines().count(), 1_601);
        let html = html::render(&report, None);
        assert_eq!(
            html.matches("<svg").count(),
            4,
            "speed, power, torque, temperatures"
        );
        assert!(html.contains("can1: bus-off") && html.ends_with("</html>\n"));
    }

    #[test]
    fn the_run_at_100_hz_holds_each_value_and_names_enums() {
        let dir = tempfile::tempdir().expect("temp dir");
        let mut db = crate::store::open(&dir.path().join("store.sqlite")).expect("store");
        let id = drive(&mut db, 3_500.0);
        let report = gather(&db, id, None).expect("report");
        let csv = resample::csv(&report.run, &[]);
        let mut lines = csv.lines();
        let header: Vec<&str> = lines.next().expect("header").split(',').collect();
        let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
        assert_eq!(rows.len(), 1_600, "16 s every 10 ms");
        let column = |name: &str| header.iter().position(|h| *h == name).expect(name);
        let (state, speed, distance) = (
            column("vehicle_state_label"),
            column("speed_km_h"),
            column("distance_m"),
        );
        assert!(rows.iter().all(|r| r[state] == "DRIVING"));
        assert_eq!(
            rows[500][speed].parse::<f64>().expect("speed").round(),
            132.0
        );
        assert_eq!(rows[0][column("ts_us")], START_US.to_string());
        let end: f64 = rows[1_599][distance].parse().expect("distance");
        assert!((end - 366.519).abs() < 1e-2, "{end}");
        assert!(matches!(
            resample::signals(&db, id, &["can_nothing.x".into()]),
            Err(ReportError::UnknownSignal(_))
        ));
    }

    #[test]
    fn a_mark_ends_the_lap_in_progress() {
        let dir = tempfile::tempdir().expect("temp dir");
        let mut db = crate::store::open(&dir.path().join("store.sqlite")).expect("store");
        let id = drive(&mut db, 3_500.0);
        events::insert(
            &db,
            id,
            &[Event {
                at_us: START_US + 6_000_000,
                kind: EventKind::Mark,
                name: "pit".into(),
                text: "lap ends".into(),
            }],
        )
        .expect("mark");
        let report = gather(&db, id, None).expect("report");
        let times: Vec<f64> = report.laps.iter().map(Stretch::time).collect();
        assert_eq!(times.len(), 2, "{times:?}");
        assert!(
            (times[0] - 5.0).abs() < 1e-9 && (times[1] - 5.0).abs() < 1e-9,
            "{times:?}"
        );
        assert!(text::render(&report, None).contains("at the mark the session recorded"));
    }

    #[test]
    fn a_slower_run_is_behind_by_the_time_its_speed_costs() {
        let dir = tempfile::tempdir().expect("temp dir");
        let mut db = crate::store::open(&dir.path().join("store.sqlite")).expect("store");
        let fast = drive(&mut db, 3_500.0);
        let slow = drive(&mut db, 2_800.0);
        let ours = gather(&db, fast, None).expect("report");
        let theirs = gather(&db, slow, None).expect("report");
        let comparison = compare(&ours, theirs);
        // Over the slower run's whole distance (0.8 of the faster's), the slower needs
        // 10 s and the faster 8 s.
        let &(distance, delta) = comparison.time_delta.last().expect("a delta");
        let slow_m = std::f64::consts::TAU * 0.35 * 800.0 / 60.0 * 10.0;
        assert!((distance - slow_m).abs() < 1.0, "{distance}");
        assert!((delta - 2.0).abs() < 0.02, "{delta}");
        assert!(
            comparison
                .time_delta
                .windows(2)
                .all(|w| w[0].1 <= w[1].1 + 1e-6)
        );
        let text = text::render(&ours, Some(&comparison));
        assert!(
            text.contains(&format!("Compared with Session {slow}")),
            "{text}"
        );
        assert!(text.contains("+2.00 s"), "{text}");
    }
}
