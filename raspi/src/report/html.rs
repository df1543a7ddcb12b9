//! The report as one HTML page with its plots inline (`report.html`): opens in any browser, on
//! the car or off it, with nothing else beside it.

use super::compare;
use super::plot::{self, Series};
use super::text::{self, heading, lap_rule};
use super::{Comparison, SessionReport};
use crate::markup::escape;
use crate::store::calibration::number;
use crate::store::clock::describe_step;
use crate::store::utc;
use aer::telemetry::Level;
use aer_host::run::laps::format_lap;
use std::fmt::Write;

const OURS: &str = "#1f77b4";
const THEIRS: &str = "#d62728";
const SECOND: &str = "#ff7f0e";

fn table(out: &mut String, header: &[String], rows: &[Vec<String>]) {
    out.push_str("<table><tr>");
    for h in header {
        let _ = write!(out, "<th>{}</th>", escape(h));
    }
    out.push_str("</tr>");
    for row in rows {
        out.push_str("<tr>");
        for cell in row {
            let _ = write!(out, "<td>{}</td>", escape(cell));
        }
        out.push_str("</tr>");
    }
    out.push_str("</table>");
}

/// A field against distance, per packet.
fn by_distance(report: &SessionReport, values: impl Fn(usize) -> f64) -> Vec<(f64, f64)> {
    report
        .run
        .derived
        .iter()
        .enumerate()
        .map(|(i, s)| (s.distance_m, values(i)))
        .collect()
}

/// Where each lap ended, in metres.
fn lap_ends_m(report: &SessionReport) -> Vec<f64> {
    report
        .run
        .laps
        .iter()
        .filter_map(|lap| {
            let i = report.run.span(lap.start, lap.end).end.checked_sub(1)?;
            report.run.derived.get(i).map(|s| s.distance_m)
        })
        .collect()
}

/// The whole page.
pub fn render(report: &SessionReport, comparison: Option<&Comparison>) -> String {
    let mut out = String::new();
    let id = report.run.session.id;
    let _ = write!(
        out,
        "<!DOCTYPE html><html><head><meta charset=\"utf-8\"><title>Session {id}</title><style>\
body{{font-family:sans-serif;margin:24px;max-width:1000px}}table{{border-collapse:collapse;margin:8px 0}}\
td,th{{border:1px solid #ccc;padding:3px 8px;text-align:right;font-size:13px}}th{{background:#f4f4f4}}\
td:first-child,th:first-child{{text-align:left}}.critical{{color:#b00}}.warn{{color:#b60}}\
h2{{margin-top:28px;border-bottom:1px solid #ddd}}</style></head><body>"
    );
    let _ = write!(
        out,
        "<h1>Session {id}</h1><p>{}</p>",
        escape(&heading(report))
    );

    let _ = write!(out, "<h2>Laps</h2><p>{}.</p>", escape(&lap_rule(report)));
    let (header, rows) = text::lap_table(report);
    table(&mut out, &header, &rows);
    out.push_str("<p>Energy: drawn from the battery less regenerated. Speed comes from the motor speed through the gear ratio and wheel radius: the telemetry has no wheel-speed sensor, so wheel slip cannot be shown.</p>");

    let ends = lap_ends_m(report);
    let run = &report.run;
    let field =
        |name: &'static str| move |i: usize| run.field(name).get(i).copied().unwrap_or(f64::NAN);
    out.push_str(&plot::svg(
        "Speed",
        "distance (m)",
        "km/h",
        &[Series {
            label: "speed".into(),
            color: OURS,
            points: by_distance(report, |i| run.derived[i].speed_m_s * 3.6),
        }],
        &ends,
    ));
    out.push_str(&plot::svg(
        "Battery power",
        "distance (m)",
        "kW",
        &[Series {
            label: "battery power".into(),
            color: OURS,
            points: by_distance(report, |i| run.derived[i].power_w / 1_000.0),
        }],
        &ends,
    ));
    out.push_str(&plot::svg(
        "Torque",
        "distance (m)",
        "Nm",
        &[
            Series {
                label: "motor torque".into(),
                color: OURS,
                points: by_distance(report, field("motor_torque")),
            },
            Series {
                label: "torque command".into(),
                color: SECOND,
                points: by_distance(report, field("torque_command")),
            },
        ],
        &ends,
    ));
    out.push_str(&plot::svg(
        "Temperatures",
        "distance (m)",
        "degC",
        &[
            Series {
                label: "motor".into(),
                color: THEIRS,
                points: by_distance(report, field("motor_temp")),
            },
            Series {
                label: "inverter".into(),
                color: SECOND,
                points: by_distance(report, field("inverter_temp")),
            },
            Series {
                label: "pack".into(),
                color: OURS,
                points: by_distance(report, field("pack_temp")),
            },
        ],
        &ends,
    ));

    out.push_str("<h2>Fields beyond their thresholds</h2>");
    if report.alarms.is_empty() {
        out.push_str("<p>None.</p>");
    } else {
        let rows: Vec<Vec<String>> = report
            .alarms
            .iter()
            .map(|a| {
                vec![
                    format!("{} ({})", a.label, a.field),
                    if a.level == Level::Critical {
                        "critical".into()
                    } else {
                        "warning".into()
                    },
                    format_lap(a.first),
                    a.times.to_string(),
                    format!("{:.1} s", a.duration_s),
                    format!("{} {}", number(a.worst), a.unit),
                ]
            })
            .collect();
        let header = ["field", "level", "first at", "times", "in all", "worst"].map(str::to_owned);
        table(&mut out, &header, &rows);
    }

    out.push_str("<h2>Events</h2><p>Problems of the status as they came and cleared, drops and integrity counts as they grew, loop points, lap marks.</p>");
    if report.events.is_empty() {
        out.push_str("<p>None.</p>");
    } else {
        let origin = run.origin_us;
        let rows: Vec<Vec<String>> = report
            .events
            .iter()
            .map(|e| {
                vec![
                    format_lap((e.at_us - origin) as f64 / 1e6),
                    e.kind.name().to_owned(),
                    e.name.clone(),
                    e.text.clone(),
                ]
            })
            .collect();
        let header = ["at", "kind", "what", "said"].map(str::to_owned);
        table(&mut out, &header, &rows);
    }

    out.push_str("<h2>Messages that failed their checks</h2>");
    if report.flagged_messages.is_empty() {
        out.push_str("<p>None.</p>");
    } else {
        let rows: Vec<Vec<String>> = report
            .flagged_messages
            .iter()
            .map(|m| {
                vec![
                    format!("{} {}", m.bus, m.message),
                    m.frames.to_string(),
                    m.checksum_failures.to_string(),
                    m.counter_repeats.to_string(),
                    m.counter_jumps.to_string(),
                    m.late_frames.to_string(),
                ]
            })
            .collect();
        let header = [
            "message",
            "frames",
            "checksum failures",
            "counter repeats",
            "counter jumps",
            "late",
        ]
        .map(str::to_owned);
        table(&mut out, &header, &rows);
    }
    out.push_str("<h2>Clock</h2>");
    if report.clock_steps.is_empty() {
        out.push_str("<p>No step while the session was open.</p>");
    }
    for &(at, step) in &report.clock_steps {
        let _ = write!(out, "<p>{}</p>", escape(&describe_step(at, step)));
    }

    out.push_str("<h2>Calibration</h2>");
    if report.calibration_changes.is_empty() {
        out.push_str("<p>No change recorded.</p>");
    } else {
        let rows: Vec<Vec<String>> = report
            .calibration_changes
            .iter()
            .map(|e| vec![utc(e.at_us), e.to_string()])
            .collect();
        table(&mut out, &["time (UTC)".into(), "change".into()], &rows);
    }
    if report.calibration_at_end.is_empty() {
        out.push_str("<p>The values in force are unknown: no master connected through the gateway in this session.</p>");
    } else {
        out.push_str("<details><summary>In force at the end</summary>");
        let rows: Vec<Vec<String>> = report
            .calibration_at_end
            .iter()
            .map(|(p, e, v)| {
                vec![
                    e.map_or_else(|| p.clone(), |i| format!("{p}[{i}]")),
                    number(*v),
                ]
            })
            .collect();
        table(&mut out, &["parameter".into(), "value".into()], &rows);
        out.push_str("</details>");
    }

    if let Some(c) = comparison {
        compare_section(&mut out, report, c);
    }
    out.push_str("<hr><pre>");
    out.push_str(&escape(&text::render(report, comparison)));
    out.push_str("</pre></body></html>\n");
    out
}

fn compare_section(out: &mut String, report: &SessionReport, c: &Comparison) {
    let (ours, theirs) = (report.run.session.id, c.other.run.session.id);
    let _ = write!(
        out,
        "<h2>Compared with session {theirs}</h2><p>{}</p>",
        escape(&heading(&c.other))
    );
    let speed = |r: &SessionReport| -> Vec<(f64, f64)> {
        compare::from_start(&r.run)
            .iter()
            .map(|p| (p.distance_m, p.speed_kmh))
            .collect()
    };
    out.push_str(&plot::svg(
        "Speed, from each run's start",
        "distance (m)",
        "km/h",
        &[
            Series {
                label: format!("session {ours}"),
                color: OURS,
                points: speed(report),
            },
            Series {
                label: format!("session {theirs}"),
                color: THEIRS,
                points: speed(&c.other),
            },
        ],
        &[],
    ));
    out.push_str(&plot::svg(
        &format!("Time delta: session {theirs} less session {ours} (above 0: {theirs} behind)"),
        "distance (m)",
        "s",
        &[Series {
            label: "delta".into(),
            color: THEIRS,
            points: c.time_delta.clone(),
        }],
        &[],
    ));
    out.push_str("<h3>Calibration values that differ</h3>");
    if c.calibration_differences.is_empty() {
        out.push_str("<p>None (or neither session recorded its calibration).</p>");
    } else {
        let value = |v: Option<f64>| v.map_or_else(|| "?".to_owned(), number);
        let rows: Vec<Vec<String>> = c
            .calibration_differences
            .iter()
            .map(|(name, a, b)| vec![name.clone(), value(*a), value(*b)])
            .collect();
        table(
            out,
            &[
                "parameter".into(),
                format!("session {ours}"),
                format!("session {theirs}"),
            ],
            &rows,
        );
    }
}
