//! The Tune page of the pit view: every calibration parameter from the schema, by section,
//! with the CCM's value, unit, limits, default and when it may change; a field to type a new
//! value, Write, and the value read back or the CCM's refusal with its reason. Above them the
//! session (connect, unlock), revert to the reference page and save to flash.

use super::{Message, style};
use crate::model::tune::{Element, Outcome, Session, Tune, element_name, with_unit};
use aer::calibration::PARAMETERS;
use aer::telemetry::Telemetry;
use aer_host::calibration::{number, when};
use iced::widget::{
    Column, button, column, container, responsive, row, scrollable, text, text_input,
};
use iced::{Alignment, Element as Widget, Fill, FillPortion};

/// What the page asks the application to do.
#[derive(Debug, Clone, PartialEq)]
pub enum Action {
    Connect,
    Disconnect,
    Unlock,
    Revert,
    Save,
    /// The tuner typed into an element's field.
    Edit(Element, String),
    /// Write the element's typed value.
    Write(Element),
    /// Back to the live pit view.
    Live,
}

/// Below this width (the car's 800x480 display) the default and the change condition go
/// under the name instead of into columns of their own.
const NARROW_WIDTH: f32 = 1100.0;

/// The page, with `telemetry` (the latest packet, if fresh) deciding whether saving is offered.
pub fn view<'a>(tune: &'a Tune, telemetry: Option<&'a Telemetry>) -> Widget<'a, Message> {
    responsive(move |size| layout(tune, telemetry, size.width < NARROW_WIDTH)).into()
}

fn layout<'a>(tune: &'a Tune, telemetry: Option<&Telemetry>, narrow: bool) -> Widget<'a, Message> {
    let mut screen = column![session_bar(tune, telemetry)].spacing(8);
    if let Some((good, note)) = &tune.note {
        let color = if *good { style::GOOD } else { style::CRITICAL };
        screen = screen.push(text(note.clone()).size(16).color(color));
    }
    screen = screen.push(scrollable(parameters(tune, narrow)).spacing(4).height(Fill));
    container(screen)
        .padding(10)
        .width(Fill)
        .height(Fill)
        .style(style::screen)
        .into()
}

fn action(label: &str, enabled: bool, action: Action) -> Widget<'_, Message> {
    let mut b = button(text(label.to_owned()).size(15))
        .padding([4, 10])
        .style(style::command);
    if enabled {
        b = b.on_press(Message::Tune(action));
    }
    b.into()
}

/// The session line: where, its state, and the page-wide actions.
fn session_bar<'a>(tune: &'a Tune, telemetry: Option<&Telemetry>) -> Widget<'a, Message> {
    let idle = !tune.busy;
    let (state, color, open, locked) = match &tune.session {
        Session::Closed(why) if why.is_empty() => {
            ("not connected".to_owned(), style::DIM, false, true)
        }
        Session::Closed(why) => (format!("not connected: {why}"), style::WARN, false, true),
        Session::Connecting => ("connecting".to_owned(), style::WARN, false, true),
        Session::Open { locked, ecu_page } => (
            format!(
                "connected, {}, the car runs on the {} page",
                if *locked { "LOCKED" } else { "unlocked" },
                if *ecu_page == 0 {
                    "working"
                } else {
                    "reference"
                }
            ),
            if *locked { style::WARN } else { style::GOOD },
            true,
            *locked,
        ),
    };
    let save_now = Tune::save_allowed(telemetry);
    let connect = if open {
        action("Disconnect", idle, Action::Disconnect)
    } else {
        action("Connect", idle, Action::Connect)
    };
    let actions = row![
        connect,
        action("Unlock", idle && open && locked, Action::Unlock),
        action(
            "Revert to defaults",
            idle && open && !locked,
            Action::Revert
        ),
        action(
            if save_now {
                "Save to flash"
            } else {
                "Save (stop, tractive off)"
            },
            idle && open && !locked && save_now,
            Action::Save,
        ),
        action("Live view", true, Action::Live),
    ]
    .spacing(6);
    container(
        column![
            row![
                text("Tune").size(22),
                text(format!("XCP through {}", tune.gateway))
                    .size(15)
                    .color(style::DIM),
            ]
            .spacing(12)
            .align_y(Alignment::Center),
            text(state).size(15).color(color),
            actions,
        ]
        .spacing(6),
    )
    .padding(8)
    .width(Fill)
    .style(style::panel)
    .into()
}

/// Every parameter element, by section.
fn parameters(tune: &Tune, narrow: bool) -> Widget<'_, Message> {
    let mut list = Column::new().spacing(2);
    let mut group = "";
    for (index, parameter) in PARAMETERS.iter().enumerate() {
        if parameter.group != group {
            group = parameter.group;
            list = list.push(text(group.to_uppercase()).size(15).color(style::DIM));
        }
        for element in 0..parameter.count {
            list = list.push(element_row(tune, (index, element), narrow));
        }
    }
    container(list)
        .padding(8)
        .width(Fill)
        .style(style::panel)
        .into()
}

fn element_row(tune: &Tune, at: Element, narrow: bool) -> Widget<'_, Message> {
    let (index, element) = at;
    let Some(p) = PARAMETERS.get(index) else {
        return text("").into();
    };
    let mut name = element_name(p, element);
    if let Some(axis) = p.axis {
        if let Some(point) = axis.points.get(element) {
            name = format!("{name} @ {} {}", number(f64::from(*point)), axis.unit);
        }
    }
    if let Some(label) = p.elements.get(element) {
        name = format!("{name} ({label})");
    }
    let limits = format!("{}-{}", number(p.min), number(p.max));
    let default = with_unit(Tune::default_value(at), p.unit);
    let open = matches!(tune.session, Session::Open { .. });
    let field = text_input(&number_or_dash(tune.value(at)), tune.edit(at))
        .on_input(move |typed| Message::Tune(Action::Edit(at, typed)))
        .on_submit(Message::Tune(Action::Write(at)))
        .size(15)
        .padding(3)
        .width(FillPortion(2));
    let write = action("Write", open && !tune.busy, Action::Write(at));
    let (result, color) = match tune.outcome(at) {
        Some(Outcome::Written(value)) => (
            format!("read back {}", with_unit(*value, p.unit)),
            style::GOOD,
        ),
        Some(Outcome::Refused(why)) => (format!("refused: {why}"), style::CRITICAL),
        Some(Outcome::NotSent(why)) => (format!("not sent: {why}"), style::WARN),
        None => (String::new(), style::DIM),
    };
    let value = text(with_unit(tune.value(at), p.unit))
        .size(16)
        .width(FillPortion(2));
    let described: Widget<'_, Message> = if narrow {
        column![
            text(name).size(15),
            text(format!("{limits}, default {default}, {}", when(p.change)))
                .size(12)
                .color(style::DIM),
        ]
        .width(FillPortion(4))
        .into()
    } else {
        row![
            column![
                text(name).size(15),
                text(p.label).size(12).color(style::DIM)
            ]
            .width(FillPortion(4)),
            text(limits)
                .size(14)
                .color(style::DIM)
                .width(FillPortion(2)),
            text(format!("default {default}"))
                .size(14)
                .color(style::DIM)
                .width(FillPortion(2)),
            text(when(p.change))
                .size(14)
                .color(style::DIM)
                .width(FillPortion(2)),
        ]
        .spacing(6)
        .width(FillPortion(10))
        .into()
    };
    let mut line = row![described, value, field, write]
        .spacing(6)
        .align_y(Alignment::Center);
    if !narrow {
        line = line.push(
            text(result.clone())
                .size(14)
                .color(color)
                .width(FillPortion(4)),
        );
    }
    let mut cell = column![line];
    if narrow && !result.is_empty() {
        cell = cell.push(text(result).size(13).color(color));
    }
    cell.into()
}

fn number_or_dash(value: Option<f64>) -> String {
    value.map_or_else(|| "-".into(), number)
}
