//! The driver view: full screen on the car's display, a few large values. Stale data turns
//! grey under an amber banner; a lost broker connection is a red banner across the top.

use super::{Message, style};
use crate::model::{Dashboard, Freshness, Reading};
use crate::ui::status_banner;
use aer::can::VehicleState;
use aer::telemetry::Level;
use aer_host::run::laps::format_lap;
use iced::widget::{column, container, progress_bar, row, space, text};
use iced::{Alignment, Color, Element, Fill, FillPortion};
use std::time::Instant;

/// The driver view at `now`.
pub fn view(model: &Dashboard, now: Instant) -> Element<'_, Message> {
    let freshness = model.freshness(now);
    let stale = freshness != Freshness::Fresh;
    let value_color = |level| style::level_color(level, stale);

    let state = model.vehicle_state();
    let state_text = state.map_or("—".to_owned(), |s| {
        s.label()
            .map_or_else(|| format!("STATE {}", s.into_raw()), str::to_owned)
    });
    let state_color = match state {
        _ if stale => style::STALE,
        Some(VehicleState::Driving) => style::GOOD,
        Some(VehicleState::Fault) => style::CRITICAL,
        _ => style::TEXT,
    };
    let ready: Element<'_, Message> = if model.ready_to_drive() && !stale {
        container(text("READY TO DRIVE").size(30))
            .padding([4, 14])
            .style(style::banner(style::GOOD))
            .into()
    } else {
        text("NOT READY").size(30).color(style::DIM).into()
    };
    let top = row![
        text(state_text).size(34).color(state_color),
        space::horizontal(),
        ready,
    ]
    .align_y(Alignment::Center);

    let speed = model
        .speed_kmh()
        .map_or("--".to_owned(), |v| format!("{:.0}", v.max(0.0)));
    let speed = column![
        text(speed).size(170).color(value_color(Level::Normal)),
        text("km/h").size(30).color(style::DIM),
    ]
    .align_x(Alignment::Center)
    .width(FillPortion(3));

    let soc = model.reading("soc");
    let soc_panel = column![
        text("SOC").size(26).color(style::DIM),
        text(
            soc.as_ref()
                .map_or("--".to_owned(), |r| format!("{:.0} %", r.value))
        )
        .size(64)
        .color(value_color(soc.as_ref().map_or(Level::Normal, |r| r.level))),
        progress_bar(0.0..=100.0, soc.as_ref().map_or(0.0, |r| r.value as f32))
            .girth(18)
            .style(style::bar(value_color(
                soc.as_ref().map_or(Level::Normal, |r| r.level)
            ))),
        space::vertical().height(10),
        lap(model, now, stale),
    ]
    .spacing(4)
    .width(FillPortion(2));

    let power = model.power();
    let limit = Dashboard::power_limit_kw();
    let power_level = power.as_ref().map_or(Level::Normal, |p| p.level);
    let power_kw = power.as_ref().map_or(0.0, |p| p.value);
    let power_text = match &power {
        Some(p) => format!("{:.0} / {limit:.0} kW", p.value),
        None => "-- kW".to_owned(),
    };
    let power_panel = column![
        row![
            text("POWER").size(26).color(style::DIM),
            space::horizontal(),
            text(power_text).size(34).color(value_color(power_level)),
        ]
        .align_y(Alignment::Center),
        progress_bar(0.0..=limit as f32, power_kw.max(0.0) as f32)
            .girth(18)
            .style(style::bar(value_color(power_level))),
    ]
    .spacing(4)
    .width(FillPortion(3));

    let hottest = model.hottest();
    let temperature = column![
        text(
            hottest
                .as_ref()
                .map_or("TEMP".to_owned(), |r| r.label.to_uppercase())
        )
        .size(26)
        .color(style::DIM),
        text(hottest.as_ref().map_or("--".to_owned(), reading_text))
            .size(52)
            .color(value_color(
                hottest.as_ref().map_or(Level::Normal, |r| r.level)
            )),
    ]
    .width(FillPortion(2));

    let body = column![
        top,
        row![speed, soc_panel]
            .align_y(Alignment::Center)
            .height(Fill),
        row![power_panel, temperature]
            .spacing(24)
            .align_y(Alignment::End),
        faults(model, stale),
    ]
    .spacing(12);

    let mut screen = column![].spacing(8);
    if let Some(banner) = status_banner(model, freshness, now) {
        screen = screen.push(banner);
    }
    container(screen.push(body))
        .padding(16)
        .width(Fill)
        .height(Fill)
        .style(style::screen)
        .into()
}

fn reading_text(reading: &Reading) -> String {
    format!("{:.0} {}", reading.value, reading.unit)
}

fn lap(model: &Dashboard, now: Instant, stale: bool) -> Element<'_, Message> {
    let laps = model.laps();
    let current = model.car_time(now).and_then(|ts| laps.current(ts));
    let color = if stale { style::STALE } else { style::TEXT };
    // Between runs the next lap's number waits with no time.
    let heading = format!("LAP {}", current.map_or(laps.completed() + 1, |(n, _)| n));
    let time = current.map_or("-:--.-".to_owned(), |(_, t)| format_lap(t));
    let last = laps.last().map_or("-:--.-".to_owned(), format_lap);
    let best = laps.best().map_or("-:--.-".to_owned(), format_lap);
    column![
        row![
            text(heading).size(26).color(style::DIM),
            space::horizontal(),
            text(time).size(34).color(color),
        ]
        .align_y(Alignment::Center),
        text(format!("last {last}   best {best}"))
            .size(22)
            .color(style::DIM),
    ]
    .into()
}

fn faults(model: &Dashboard, stale: bool) -> Element<'_, Message> {
    let active = model.active_alarms();
    if active.is_empty() {
        return text("NO FAULTS").size(26).color(style::DIM).into();
    }
    let names = active.into_iter().map(|(label, level)| {
        let color: Color = style::level_color(level, stale);
        container(text(label).size(28).color(Color::BLACK))
            .padding([2, 10])
            .style(style::banner(color))
            .into()
    });
    row(names).spacing(8).wrap().into()
}
