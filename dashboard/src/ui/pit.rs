//! The pit view: every telemetry field grouped by subsystem (straight from the schema's
//! tables), any CAN message picked from the bus, plots of the fields picked by clicking them,
//! the fault history and link health.

use super::plot::{MAX_POINTS, Plot};
use super::{Message, status_banner, style};
use crate::model::fields::{Field, heading};
use crate::model::health::{Carried, Connection, SchemaMatch, fingerprint};
use crate::model::{BackfillProgress, Dashboard, Freshness};
use aer::telemetry::Level;
use iced::widget::{
    button, canvas, column, container, responsive, row, scrollable, space, text, tooltip,
};
use iced::{Alignment, Element, Fill, FillPortion, Length};
use std::time::Instant;

/// Below this width (the car's 800x480 display, a small window) the pit view gives the
/// fields and the plots half the screen each, one panel under the other, and puts the link
/// line's schema check on its own line.
const NARROW_WIDTH: f32 = 1100.0;

/// The pit view at `now`, laid out for the space it gets.
pub fn view(model: &Dashboard, now: Instant) -> Element<'_, Message> {
    responsive(move |size| layout(model, now, size.width < NARROW_WIDTH)).into()
}

fn layout(model: &Dashboard, now: Instant, narrow: bool) -> Element<'_, Message> {
    let freshness = model.freshness(now);
    let stale = freshness != Freshness::Fresh;
    let mut screen = column![link(model, now, narrow)].spacing(8);
    if let Some(banner) = status_banner(model, freshness, now) {
        screen = screen.push(banner);
    }
    let body = if narrow {
        // Scrollbars beside the panels, not over their right edge.
        row![
            scrollable(left(model, now, stale, narrow))
                .spacing(4)
                .width(FillPortion(1)),
            scrollable(column![plots(model), fault_history(model, narrow)].spacing(8))
                .spacing(4)
                .width(FillPortion(1)),
        ]
    } else {
        row![
            scrollable(left(model, now, stale, narrow)).width(FillPortion(3)),
            column![plots(model), fault_history(model, narrow)]
                .spacing(8)
                .width(FillPortion(2)),
        ]
    };
    container(screen.push(body.spacing(8).height(Fill)))
        .padding(10)
        .width(Fill)
        .height(Fill)
        .style(style::screen)
        .into()
}

/// The link panel: connection, packet rate and losses here, and what the Pi reports.
fn link(model: &Dashboard, now: Instant, narrow: bool) -> Element<'_, Message> {
    let health = model.health();
    let (connection, connection_color) = match &health.connection {
        Connection::Connecting => ("connecting".to_owned(), style::WARN),
        Connection::Connected => ("connected".to_owned(), style::GOOD),
        Connection::Lost { .. } => ("LOST".to_owned(), style::CRITICAL),
    };
    let ours = fingerprint(aer::telemetry::TELEMETRY_FINGERPRINT);
    let (schema, schema_color) = match health.schema_match() {
        SchemaMatch::Unknown => (format!("schema {ours}: not confirmed yet"), style::DIM),
        SchemaMatch::Match => (
            format!("schema {ours}: firmware, Pi, dashboard match"),
            style::GOOD,
        ),
        SchemaMatch::FirmwareDiffers => (
            format!(
                "FIRMWARE SCHEMA {} != {ours}: packets rejected, flash the CCM",
                health
                    .status
                    .as_ref()
                    .and_then(|s| s.firmware_fingerprint_seen.clone())
                    .unwrap_or_default()
            ),
            style::CRITICAL,
        ),
        SchemaMatch::PiDiffers => (
            format!(
                "PI SCHEMA {} != dashboard {ours}: rebuild one of them",
                health
                    .status
                    .as_ref()
                    .map(|s| s.telemetry_fingerprint.clone())
                    .unwrap_or_default()
            ),
            style::CRITICAL,
        ),
    };
    let here = format!(
        "{} packets/s   lost {} packets   missed {} stream batches   unreadable {} payloads",
        health.rate(now),
        health.lost,
        health.stream_gaps,
        health.undecodable
    );
    let pi = health.metrics.as_ref().map_or_else(
        || "Pi: no metrics yet".to_owned(),
        |m| {
            format!(
                "Pi: ISO-TP errors {}   decode errors {}   fingerprint rejects {}   MQTT drops {}   stream drops {}   store lag {} rows",
                m.counters.isotp_errors,
                m.counters.decode_errors + m.counters.packet_errors,
                m.counters.fingerprint_mismatches,
                m.counters.publish_dropped,
                m.counters.pit_dropped,
                m.store_lag
            )
        },
    );
    let pi_color = if health.metrics.as_ref().is_some_and(|m| {
        m.counters.isotp_errors
            + m.counters.decode_errors
            + m.counters.packet_errors
            + m.counters.fingerprint_mismatches
            + m.counters.publish_dropped
            + m.counters.pit_dropped
            > 0
    }) {
        style::WARN
    } else {
        style::DIM
    };
    let first = row![
        text("LINK").size(16).color(style::DIM),
        text(connection).size(16).color(connection_color),
        text(here).size(16),
    ]
    .spacing(16);
    let schema = text(schema).size(16).color(schema_color);
    let mut panel = if narrow {
        column![first, schema]
    } else {
        column![row![first, space::horizontal(), schema]]
    }
    .spacing(2);
    panel = panel.push(text(pi).size(14).color(pi_color));
    if let Some((buses, color)) = health.status.as_ref().and_then(bus_traffic) {
        panel = panel.push(text(buses).size(14).color(color));
    }
    if let Some((served, color)) = served(health) {
        panel = panel.push(text(served).size(14).color(color));
    }
    if let Some(status) = &health.status {
        for (part, problem) in status.problems.named() {
            panel = panel.push(
                text(format!("Pi problem, {part}: {problem}"))
                    .size(14)
                    .color(style::CRITICAL),
            );
        }
    }
    if let Some((history, color)) = health.backfill.map(|b| backfill(&b, health.backfilled)) {
        panel = panel.push(text(history).size(14).color(color));
    }
    if let Some(error) = &health.last_error {
        panel = panel.push(
            text(format!("last unreadable payload: {error}"))
                .size(14)
                .color(style::WARN),
        );
    }
    container(panel)
        .padding(8)
        .width(Fill)
        .style(style::panel)
        .into()
}

/// How the Pi's gate serves this dashboard: how far behind it is, and what it dropped for it
/// (in amber once it is a second behind or has lost live data: the radio is slower than the
/// stream), with how many other clients it serves.
fn served(health: &crate::model::health::Health) -> Option<(String, iced::Color)> {
    let served = health.served()?;
    let others = health
        .status
        .as_ref()
        .map_or(0, |status| status.mqtt_clients.len().saturating_sub(1));
    let line = format!(
        "Pi to here: {:.1} s behind   {} live messages dropped   {} kB waiting   MQTT {} on `{}`   {others} other clients",
        served.lag_ms as f64 / 1000.0,
        served.dropped,
        served.queued_bytes / 1000,
        served.protocol,
        served.listener
    );
    let color =
        if served.lag_ms >= aer_host::reports::status::CLIENT_BEHIND_MS || served.dropped > 0 {
            style::WARN
        } else {
            style::DIM
        };
    Some((line, color))
}

/// How complete the pit's copy of the session is: amber while it catches up, red for batches
/// the Pi no longer held.
fn backfill(progress: &BackfillProgress, packets: u64) -> (String, iced::Color) {
    let complete = progress.complete * 100.0;
    let mut line = if progress.catching_up {
        format!(
            "catching up: {:.0} s behind, {complete:.1} %",
            progress.behind_s
        )
    } else {
        format!("session {complete:.1} % complete")
    };
    if progress.recovered > 0 {
        line += &format!(
            "   history: {} batches, {packets} packets merged",
            progress.recovered
        );
    }
    if progress.not_held > 0 {
        line += &format!("   {} batches no longer on the Pi", progress.not_held);
    }
    let color = if progress.not_held > 0 {
        style::CRITICAL
    } else if progress.catching_up {
        style::WARN
    } else {
        style::DIM
    };
    (line, color)
}

/// The Pi's measured bus loads, and the messages slower than their cycle time (fewer than
/// 90 % of the declared frames: a sender struggling, or frames lost), in amber.
fn bus_traffic(status: &aer_host::reports::status::Status) -> Option<(String, iced::Color)> {
    if status.bus_traffic.is_empty() {
        return None;
    }
    let loads: Vec<String> = status
        .bus_traffic
        .iter()
        .map(|(bus, t)| {
            format!(
                "{bus} {:.1} % ({:.0} frames/s)",
                t.load * 100.0,
                t.frames_per_s
            )
        })
        .collect();
    let slow: Vec<String> = status
        .message_rates
        .iter()
        .flat_map(|(bus, messages)| messages.iter().map(move |(name, rate)| (bus, name, rate)))
        .filter_map(|(bus, name, rate)| {
            let (measured, declared) = (rate.measured_hz?, rate.declared_hz?);
            (measured < 0.9 * declared)
                .then(|| format!("{name} on {bus} {measured:.0} of {declared:.0} Hz"))
        })
        .collect();
    let mut line = format!("Pi buses: {}", loads.join("   "));
    let color = if slow.is_empty() {
        style::DIM
    } else {
        line.push_str(&format!("   SLOW: {}", slow.join(", ")));
        style::WARN
    };
    Some((line, color))
}

/// The telemetry's fields, then the CAN messages picked from the bus.
fn left(model: &Dashboard, now: Instant, stale: bool, narrow: bool) -> Element<'_, Message> {
    column![
        fields(model, stale, narrow),
        super::can::panel(model.can(), now, narrow)
    ]
    .spacing(8)
    .into()
}

/// Every field of the schema, one panel per group (side by side when there is room, else
/// one under the other at full width); a click plots the field.
fn fields(model: &Dashboard, stale: bool, narrow: bool) -> Element<'_, Message> {
    let schema = model.schema();
    let values = model.field_values();
    let panels = schema.groups().into_iter().map(|(group, members)| {
        let rows = members
            .into_iter()
            .filter_map(|index| schema.get(index))
            .map(|field| field_row(model, field, values.get(field.index).copied(), stale));
        container(
            column![text(heading(group)).size(17).color(style::DIM)]
                .extend(rows)
                .spacing(1),
        )
        .padding(8)
        .width(if narrow { Fill } else { Length::Fixed(238.0) })
        .style(style::panel)
        .into()
    });
    if narrow {
        column(panels).spacing(8).into()
    } else {
        row(panels).spacing(8).wrap().vertical_spacing(8).into()
    }
}

fn field_row<'a>(
    model: &Dashboard,
    field: Field,
    value: Option<crate::model::fields::FieldValue>,
    stale: bool,
) -> Element<'a, Message> {
    let plotted = model.plots().contains(&field.index);
    // A field mirroring a message this car's buses never carry (the other inverter's) has
    // nothing to show: its zeros would read as a live state.
    let absent = field
        .display
        .mirrors
        .filter(|message| model.health().carries(message) == Carried::No);
    let (shown, level) = match (absent, value) {
        (Some(_), _) => ("not fitted".to_owned(), Level::Normal),
        (None, Some(v)) => (field.format(v), field.level(v.value)),
        (None, None) => ("--".to_owned(), Level::Normal),
    };
    let marker = if plotted { "● " } else { "" };
    let shown = text(shown).size(14);
    let shown = if absent.is_some() {
        shown.color(style::DIM)
    } else {
        shown.color(style::level_color(level, stale))
    };
    let content = row![
        text(format!("{marker}{}", field.display.label)).size(14),
        space::horizontal(),
        shown,
        text(field.unit()).size(12).color(style::DIM).width(34),
    ]
    .spacing(6)
    .align_y(Alignment::Center);
    let row = button(content)
        .padding([1, 4])
        .width(Fill)
        .style(style::field_row(plotted))
        .on_press(Message::TogglePlot(field.index));
    // What the schema says about the field, on hover.
    let about = match absent {
        Some(message) => format!(
            "Mirrors {message}, which this car's buses do not carry (the other inverter's). {}",
            field.description()
        ),
        None => field.description().to_owned(),
    };
    if about.is_empty() {
        return row.into();
    }
    tooltip(
        row,
        container(text(about).size(13))
            .padding(6)
            .max_width(320)
            .style(style::panel),
        tooltip::Position::Bottom,
    )
    .into()
}

/// The picked fields over the history window.
fn plots(model: &Dashboard) -> Element<'_, Message> {
    let schema = model.schema();
    let history = model.history();
    let values = model.field_values();
    if model.plots().is_empty() {
        return container(text("Click a field to plot it").size(16).color(style::DIM))
            .padding(8)
            .width(Fill)
            .style(style::panel)
            .into();
    }
    let charts = model.plots().iter().filter_map(|&index| {
        let field = schema.get(index)?;
        let now = values
            .get(index)
            .map_or("--".to_owned(), |v| field.format(*v));
        let title = row![
            text(field.display.label).size(15),
            space::horizontal(),
            text(format!("{now} {}", field.unit())).size(15),
            text(format!("  last {:.0} s", history.window_s()))
                .size(13)
                .color(style::DIM),
        ];
        let chart = canvas(Plot {
            series: history.series(index, MAX_POINTS),
            window_s: history.window_s() as f32,
            color: style::PLOT,
        })
        .width(Fill)
        .height(110);
        Some(
            container(column![title, chart].spacing(2))
                .padding(6)
                .style(style::panel)
                .into(),
        )
    });
    column(charts).spacing(8).into()
}

/// Raised and cleared faults with their times, newest first; names wrap rather than being cut.
/// Narrow, it is part of a scrolling column and shows the newest 20.
fn fault_history(model: &Dashboard, narrow: bool) -> Element<'_, Message> {
    let entries = model.alarms().history().take(100).map(|event| {
        let (what, color) = match event.level {
            Level::Normal => ("cleared", style::GOOD),
            Level::Warn => ("warning", style::WARN),
            Level::Critical => ("FAULT", style::CRITICAL),
        };
        row![
            text(clock(event.ts)).size(14).color(style::DIM).width(96),
            text(what).size(14).color(color).width(70),
            text(event.label).size(14).width(Fill),
        ]
        .into()
    });
    let list: Element<'_, Message> = if model.alarms().history().next().is_none() {
        text("none").size(14).color(style::DIM).into()
    } else if narrow {
        column(entries.take(20)).spacing(1).into()
    } else {
        scrollable(column(entries).spacing(1)).height(Fill).into()
    };
    container(column![text("Fault history").size(17).color(style::DIM), list].spacing(4))
        .padding(8)
        .width(Fill)
        .height(if narrow { Length::Shrink } else { Fill })
        .style(style::panel)
        .into()
}

/// Time of day (UTC) of a packet time, to the millisecond.
pub fn clock(ts: f64) -> String {
    let ms = (ts.max(0.0) * 1_000.0).round() as u64 % 86_400_000;
    format!(
        "{:02}:{:02}:{:02}.{:03}",
        ms / 3_600_000,
        ms / 60_000 % 60,
        ms / 1_000 % 60,
        ms % 1_000
    )
}

#[cfg(test)]
mod tests {
    #[test]
    fn clock_shows_utc_time_of_day() {
        // 2026-11-21 12:00:00.25 UTC
        assert_eq!(super::clock(1_795_348_800.25), "12:00:00.250");
    }
}
