//! The report as text (`report.txt`, and what `aer-raspi report` prints): the figures first,
//! then what went wrong and when, then the calibration.

use super::summary::{Stretch, TEMPERATURES};
use super::{Comparison, SessionReport};
use crate::store::calibration::number;
use crate::store::clock::describe_step;
use crate::store::utc;
use aer::telemetry::Level;
use aer_host::run::laps::format_lap;
use std::fmt::Write;

/// A figure with its unit, `-` when there is none.
fn figure(value: f64, decimals: usize, unit: &str) -> String {
    if value.is_finite() {
        format!("{value:.decimals$} {unit}")
    } else {
        "-".to_owned()
    }
}

/// The header of a session: who, where, when.
pub fn heading(report: &SessionReport) -> String {
    let s = &report.run.session;
    let m = &s.metadata;
    let mut who: Vec<String> = Vec::new();
    if !m.driver.is_empty() {
        who.push(format!("driver {}", m.driver));
    }
    if !m.track.is_empty() {
        who.push(m.track.clone());
    }
    if let Some(run) = m.run {
        who.push(format!("run {run}"));
    }
    if !m.notes.is_empty() {
        who.push(format!("notes: {}", m.notes.replace('\n', " ")));
    }
    format!(
        "Session {} ({}): {} to {} ({}), {}{}",
        s.id,
        s.source,
        utc(s.started_us),
        s.ended_us.map_or_else(|| "open".to_owned(), utc),
        format_lap(report.run.length_s()),
        if who.is_empty() {
            "no driver, track or run recorded".to_owned()
        } else {
            who.join(", ")
        },
        if s.clock.is_empty() {
            String::new()
        } else {
            format!("; clock {}", s.clock)
        }
    )
}

/// The column names of a stretch's row.
pub fn stretch_header() -> Vec<String> {
    let mut names: Vec<String> = [
        "start",
        "time",
        "distance",
        "top speed",
        "energy",
        "peak power",
        "peak torque",
    ]
    .map(str::to_owned)
    .to_vec();
    names.extend(TEMPERATURES.map(|(_, name)| format!("{name} max")));
    names
}

/// A stretch's row, as [`stretch_header`] names it.
pub fn stretch_row(s: &Stretch) -> Vec<String> {
    let mut row = vec![
        format_lap(s.start),
        format_lap(s.time()),
        figure(s.distance_m, 0, "m"),
        figure(s.top_speed_kmh, 1, "km/h"),
        figure(s.energy_wh, 1, "Wh"),
        figure(s.peak_power_kw, 1, "kW"),
        figure(s.peak_torque_nm, 0, "Nm"),
    ];
    row.extend(s.max_temps.map(|t| figure(t, 0, "degC")));
    row
}

/// Columns padded to their widest cell.
fn table(out: &mut String, header: &[String], rows: &[Vec<String>]) {
    let mut widths: Vec<usize> = header.iter().map(|h| h.chars().count()).collect();
    for row in rows {
        for (w, cell) in widths.iter_mut().zip(row) {
            *w = (*w).max(cell.chars().count());
        }
    }
    let line = |out: &mut String, cells: &[String]| {
        let padded: Vec<String> = cells
            .iter()
            .zip(&widths)
            .map(|(c, w)| format!("{c:<w$}"))
            .collect();
        let _ = writeln!(out, "  {}", padded.join("  ").trim_end());
    };
    line(out, header);
    for row in rows {
        line(out, row);
    }
}

/// The laps' table: a row per lap, then the whole session's, under their header.
pub fn lap_table(report: &SessionReport) -> (Vec<String>, Vec<Vec<String>>) {
    let mut rows: Vec<Vec<String>> = report
        .laps
        .iter()
        .enumerate()
        .map(|(i, lap)| {
            let mut row = vec![lap_name(report, i)];
            row.extend(stretch_row(lap));
            row
        })
        .collect();
    let mut whole = vec!["session".to_owned()];
    whole.extend(stretch_row(&report.whole));
    rows.push(whole);
    let mut header = vec!["lap".to_owned()];
    header.extend(stretch_header());
    (header, rows)
}

/// Lap `index`'s name: its number, and for a first lap the session began in the middle of
/// (the car already moving at its first packet, a `session new` mid-run), that it is partial.
pub fn lap_name(report: &SessionReport, index: usize) -> String {
    let partial = index == 0
        && report.run.laps.first().is_some_and(|lap| {
            report.run.t.first() == Some(&lap.start)
                && report
                    .run
                    .derived
                    .first()
                    .is_some_and(|s| s.speed_m_s >= 0.5)
        });
    if partial {
        format!("{} (began before the session)", index + 1)
    } else {
        format!("{}", index + 1)
    }
}

/// The laps' rule in words.
pub fn lap_rule(report: &SessionReport) -> String {
    let run = &report.run;
    format!(
        "laps by the driver's display's rule: from the first movement in DRIVING to the stop (3 s standing) or leaving DRIVING{}{}",
        run.lap_length_m
            .map_or(String::new(), |m| format!(", every {m} m")),
        match run.marks.len() {
            0 => ", no marks recorded".to_owned(),
            1 => ", at the mark the session recorded".to_owned(),
            n => format!(", at the {n} marks the session recorded"),
        }
    )
}

/// The whole report as text.
pub fn render(report: &SessionReport, comparison: Option<&Comparison>) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "{}\n", heading(report));
    let _ = writeln!(out, "Laps ({}):", lap_rule(report));
    let (header, rows) = lap_table(report);
    table(&mut out, &header, &rows);
    if report.laps.is_empty() {
        let _ = writeln!(out, "  (no lap completed)");
    }
    let _ = writeln!(
        out,
        "  (energy: drawn less regenerated; speed from the motor speed, no wheel-speed sensor, so no slip)"
    );

    let _ = writeln!(out, "\nFields beyond their thresholds:");
    if report.alarms.is_empty() {
        let _ = writeln!(out, "  none");
    }
    for a in &report.alarms {
        let _ = writeln!(
            out,
            "  {} {} ({}): first at {}, {} time(s), {:.1} s in all, worst {} {}",
            if a.level == Level::Critical {
                "CRITICAL"
            } else {
                "warning "
            },
            a.label,
            a.field,
            format_lap(a.first),
            a.times,
            a.duration_s,
            number(a.worst),
            a.unit
        );
    }

    let _ = writeln!(
        out,
        "\nEvents (problems as they came and cleared, drops and counts as they grew, loop points, marks):"
    );
    if report.events.is_empty() {
        let _ = writeln!(out, "  none");
    }
    let origin = report.run.origin_us;
    for e in &report.events {
        let _ = writeln!(
            out,
            "  {}  {:<8} {:<22} {}",
            format_lap((e.at_us - origin) as f64 / 1e6),
            e.kind.name(),
            e.name,
            e.text
        );
    }

    let _ = writeln!(out, "\nMessages with frames that failed their checks:");
    if report.flagged_messages.is_empty() {
        let _ = writeln!(out, "  none");
    }
    for m in &report.flagged_messages {
        let _ = writeln!(
            out,
            "  {} {}: {} frames, {} checksum failures, {} counter repeats, {} counter jumps, {} late",
            m.bus,
            m.message,
            m.frames,
            m.checksum_failures,
            m.counter_repeats,
            m.counter_jumps,
            m.late_frames
        );
    }
    let _ = writeln!(out, "\nClock steps:");
    if report.clock_steps.is_empty() {
        let _ = writeln!(out, "  none");
    }
    for &(at, step) in &report.clock_steps {
        let _ = writeln!(out, "  {}", describe_step(at, step));
    }

    let _ = writeln!(out, "\nCalibration changes:");
    if report.calibration_changes.is_empty() {
        let _ = writeln!(out, "  none recorded");
    }
    for e in &report.calibration_changes {
        let _ = writeln!(out, "  {}  {e}", utc(e.at_us));
    }
    let _ = writeln!(out, "\nCalibration in force at the end:");
    if report.calibration_at_end.is_empty() {
        let _ = writeln!(
            out,
            "  unknown (no master connected through the gateway in this session)"
        );
    }
    for (parameter, element, value) in &report.calibration_at_end {
        let name = element.map_or_else(|| parameter.clone(), |i| format!("{parameter}[{i}]"));
        let _ = writeln!(out, "  {name} = {}", number(*value));
    }

    if let Some(c) = comparison {
        let _ = writeln!(out, "\nCompared with {}", heading(&c.other));
        let mut rows = Vec::new();
        for (n, (lap, theirs)) in report.laps.iter().zip(&c.other.laps).enumerate() {
            rows.push(vec![
                format!("{}", n + 1),
                format_lap(lap.time()),
                format_lap(theirs.time()),
                format!("{:+.2} s", theirs.time() - lap.time()),
                figure(lap.top_speed_kmh, 1, "km/h"),
                figure(theirs.top_speed_kmh, 1, "km/h"),
                figure(lap.energy_wh, 1, "Wh"),
                figure(theirs.energy_wh, 1, "Wh"),
            ]);
        }
        let (ours, theirs) = (report.run.session.id, c.other.run.session.id);
        let header: Vec<String> = [
            "lap".to_owned(),
            format!("time {ours}"),
            format!("time {theirs}"),
            "delta".to_owned(),
            format!("top speed {ours}"),
            format!("top speed {theirs}"),
            format!("energy {ours}"),
            format!("energy {theirs}"),
        ]
        .to_vec();
        table(&mut out, &header, &rows);
        if rows.is_empty() {
            let _ = writeln!(
                out,
                "  (no lap completed in one of them: the runs compare by distance only)"
            );
        }
        if let Some(&(d, delta)) = c.time_delta.last() {
            let _ = writeln!(
                out,
                "  time delta over the first {d:.0} m of both runs: {delta:+.2} s (session {theirs} against {ours}; positive: {theirs} behind)"
            );
        }
        let _ = writeln!(out, "\nCalibration values that differ:");
        if c.calibration_differences.is_empty() {
            let _ = writeln!(out, "  none");
        }
        let value = |v: Option<f64>| v.map_or_else(|| "?".to_owned(), number);
        for (name, a, b) in &c.calibration_differences {
            let _ = writeln!(
                out,
                "  {name}: {} in session {ours}, {} in session {theirs}",
                value(*a),
                value(*b)
            );
        }
    }
    out
}
