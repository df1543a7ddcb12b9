//! The pit view's CAN panel: every message of the schema by name (a click shows or hides it),
//! and each shown message's newest signals with the schema's units and value names, greyed and
//! marked STALE once the newest frame is older than the message's generated freshness limit.

use super::{Message, style};
use crate::model::Freshness;
use crate::model::can::{CanMessages, CanSignal};
use crate::model::fields;
use aer::runtime::MessageMeta;
use aer::telemetry::Level;
use iced::widget::{button, column, container, row, space, text, tooltip};
use iced::{Alignment, Element, Fill, Length};
use std::time::Instant;

/// Width of one signal's row: three side by side on a laptop.
const SIGNAL_WIDTH: f32 = 300.0;

/// The panel at `now`.
pub fn panel(can: &CanMessages, now: Instant, narrow: bool) -> Element<'_, Message> {
    let picker = row(CanMessages::topics()
        .iter()
        .enumerate()
        .map(|(index, topic)| {
            let shown = can.shown().contains(&index);
            button(text(topic.meta.name).size(13))
                .padding([1, 6])
                .style(style::field_row(shown))
                .on_press(Message::ToggleCan(index))
                .into()
        }))
    .spacing(4)
    .wrap()
    .vertical_spacing(4);
    let hint = if can.shown().is_empty() {
        "Click a message to show its signals, straight from the CAN bus"
    } else {
        "Click a message to show or hide it"
    };
    let shown = can
        .shown()
        .iter()
        .filter_map(|&index| message(can, index, now, narrow));
    container(
        column![
            text("CAN messages").size(17).color(style::DIM),
            text(hint).size(13).color(style::DIM),
            picker,
        ]
        .extend(shown)
        .spacing(6),
    )
    .padding(8)
    .width(Fill)
    .style(style::panel)
    .into()
}

/// One shown message: its name, id, timing and age, then its signals.
fn message(
    can: &CanMessages,
    index: usize,
    now: Instant,
    narrow: bool,
) -> Option<Element<'_, Message>> {
    let meta = CanMessages::meta(index)?;
    let freshness = can.freshness(index, now);
    let (state, color) = match freshness {
        Freshness::NoData => ("no frame yet".to_owned(), style::DIM),
        Freshness::Fresh => {
            let age = can
                .latest(index)
                .map_or(0, |f| now.saturating_duration_since(f.received).as_millis());
            (format!("{age} ms ago"), style::GOOD)
        }
        Freshness::Stale(age) => (
            format!("STALE: no frame for {:.1} s", age.as_secs_f64()),
            style::WARN,
        ),
    };
    let stale = freshness != Freshness::Fresh;
    let heading = row![
        text(meta.name).size(15),
        text(format!("0x{:X}", meta.id)).size(13).color(style::DIM),
        text(timing(meta)).size(13).color(style::DIM),
        space::horizontal(),
        text(state).size(14).color(color),
    ]
    .spacing(10)
    .align_y(Alignment::Center);
    let signals = can
        .latest(index)
        .map(|frame| frame.signals.as_slice())
        .unwrap_or_default()
        .iter()
        .map(|signal| signal_row(signal, stale, narrow));
    Some(
        column![heading, row(signals).spacing(12).wrap().vertical_spacing(1)]
            .spacing(2)
            .into(),
    )
}

/// How often the message comes and when it counts as lost, from the schema.
fn timing(meta: &MessageMeta) -> String {
    match (meta.cycle_time_ms, meta.timeout_ms) {
        (Some(cycle), Some(limit)) => format!("every {cycle} ms, stale after {limit} ms"),
        (Some(cycle), None) => format!("every {cycle} ms"),
        (None, Some(limit)) => format!("stale after {limit} ms"),
        (None, None) => "sent on demand".to_owned(),
    }
}

fn signal_row<'a>(signal: &CanSignal, stale: bool, narrow: bool) -> Element<'a, Message> {
    let content = row![
        text(signal.meta.name).size(13),
        space::horizontal(),
        text(fields::format(signal.meta, signal.value))
            .size(13)
            .color(style::level_color(Level::Normal, stale)),
        text(fields::unit(signal.meta))
            .size(12)
            .color(style::DIM)
            .width(34),
    ]
    .spacing(6)
    .align_y(Alignment::Center)
    .width(if narrow {
        Length::Fill
    } else {
        Length::Fixed(SIGNAL_WIDTH)
    });
    if signal.meta.comment.is_empty() {
        return content.into();
    }
    tooltip(
        content,
        container(text(signal.meta.comment).size(13))
            .padding(6)
            .max_width(320)
            .style(style::panel),
        tooltip::Position::Bottom,
    )
    .into()
}
