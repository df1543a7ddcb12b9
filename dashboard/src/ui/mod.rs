//! The iced application: messages, update, the two views and the subscriptions (the MQTT
//! link, a clock for staleness, the keyboard).

pub mod can;
pub mod driver;
pub mod pit;
pub mod plot;
pub mod style;
pub mod tune;

use crate::config::{Config, View};
use crate::link;
use crate::model::health::{Connection, SchemaMatch};
use crate::model::tune::{Session, Tune};
use crate::model::{Dashboard, Freshness, Update};
use crate::tune_worker as worker;
use iced::keyboard::{self, Key, key::Named};
use iced::widget::{container, text};
use iced::{Element, Fill, Subscription, Theme};
use std::time::{Duration, Instant};

/// How often the screens re-check staleness and redraw without new data.
pub const TICK: Duration = Duration::from_millis(50);

/// What the application reacts to.
#[derive(Debug, Clone)]
pub enum Message {
    /// An update from the broker and when it arrived.
    Link(Instant, Update),
    /// The link is running: how to tell it which CAN topics to carry.
    LinkReady(link::Control),
    /// The clock.
    Tick(Instant),
    /// Switch between the driver and pit views (Tab).
    ToggleView,
    /// End the lap in progress (L).
    MarkLap,
    /// Plot field `index`, or stop plotting it (a click on the field).
    TogglePlot(usize),
    /// Show CAN message `index` (of `CanMessages::topics`), or hide it (a click on its name).
    ToggleCan(usize),
    /// Something the tuner did on the Tune page.
    Tune(tune::Action),
    /// What the Tune page's XCP worker reports (its control first).
    TuneWorker(worker::Event),
}

/// The dashboard application.
pub struct App {
    link: link::Settings,
    /// The running link's control, once it has started.
    link_control: Option<link::Control>,
    model: Dashboard,
    view: View,
    now: Instant,
    tune: Tune,
    tune_settings: worker::Settings,
    /// The running XCP worker's control, once it has started.
    tune_control: Option<worker::Control>,
}

impl App {
    /// A dashboard for `config`, before any data, at `now`.
    pub fn new(config: &Config, now: Instant) -> Self {
        Self::with_model(config, Dashboard::new(config), config.display.view, now)
    }

    /// A dashboard showing `model` in `view` at `now` (screenshots, tests).
    pub fn with_model(config: &Config, model: Dashboard, view: View, now: Instant) -> Self {
        Self {
            link: link::Settings::from_config(config),
            link_control: None,
            model,
            view,
            now,
            tune: Tune::new(&config.tune.gateway),
            tune_settings: worker::Settings::from_config(&config.tune),
            tune_control: None,
        }
    }

    /// The Tune page's state.
    pub fn tune(&self) -> &Tune {
        &self.tune
    }

    /// The view shown.
    pub fn current_view(&self) -> View {
        self.view
    }

    /// Takes one message.
    pub fn update(&mut self, message: Message) {
        match message {
            Message::Link(at, update) => {
                self.model.apply(update, at);
                self.now = self.now.max(at);
            }
            Message::LinkReady(control) => {
                // The picks of the moment: made before the link ran, or since it restarted.
                control.show_can(self.model.can().suffixes());
                self.link_control = Some(control);
            }
            Message::Tick(at) => {
                self.now = self.now.max(at);
                self.model.settle(at);
            }
            Message::ToggleView => {
                let next = match self.view {
                    View::Driver => View::Pit,
                    View::Pit => View::Tune,
                    View::Tune => View::Driver,
                };
                self.show(next);
            }
            Message::MarkLap => {
                // The Pi stores it in the running session, for the run report's laps.
                if let (Some(ts), Some(control)) =
                    (self.model.mark_lap(self.now), &self.link_control)
                {
                    let by = if self.view == View::Driver {
                        "driver"
                    } else {
                        "pit"
                    };
                    control.mark(aer_host::link::marks::Mark {
                        ts,
                        by: by.to_owned(),
                    });
                }
            }
            Message::TogglePlot(index) => self.model.toggle_plot(index),
            Message::ToggleCan(index) => {
                self.model.toggle_can(index);
                if let Some(control) = &self.link_control {
                    control.show_can(self.model.can().suffixes());
                }
            }
            Message::Tune(action) => self.tune_action(action),
            Message::TuneWorker(worker::Event::Ready(control)) => {
                self.tune_control = Some(control);
                // A worker (re)started: nothing of an earlier one's session holds.
                self.tune.apply(worker::Event::Disconnected(String::new()));
                // Opened on the Tune page before the worker ran: connect now.
                if self.view == View::Tune && self.tune.session == Session::Closed(String::new()) {
                    self.request(worker::Request::Connect);
                }
            }
            Message::TuneWorker(event) => self.tune.apply(event),
        }
    }

    /// Switches to `view`; the Tune page connects the first time it is shown.
    fn show(&mut self, view: View) {
        self.view = view;
        if view == View::Tune && self.tune.session == Session::Closed(String::new()) {
            self.request(worker::Request::Connect);
        }
    }

    fn tune_action(&mut self, action: tune::Action) {
        let request = match action {
            tune::Action::Connect => worker::Request::Connect,
            tune::Action::Disconnect => worker::Request::Disconnect,
            tune::Action::Unlock => worker::Request::Unlock,
            tune::Action::Revert => worker::Request::Revert,
            tune::Action::Save => worker::Request::Save,
            tune::Action::Edit(element, typed) => {
                self.tune.set_edit(element, typed);
                return;
            }
            tune::Action::Write(element) => match self.tune.write_request(element) {
                Some(request) => request,
                None => return,
            },
            tune::Action::Live => {
                self.view = View::Pit;
                return;
            }
        };
        self.request(request);
    }

    /// Hands `request` to the XCP worker (one at a time: the page waits for its answer).
    fn request(&mut self, request: worker::Request) {
        if self.tune.busy {
            return;
        }
        match &self.tune_control {
            Some(control) if control.send(request.clone()) => self.tune.sent(&request),
            _ => {
                if request == worker::Request::Connect {
                    // The worker starts with the application; the Ready handler connects.
                    return;
                }
                self.tune.apply(worker::Event::Disconnected(
                    "the XCP worker is not running".into(),
                ));
            }
        }
    }

    /// The current view.
    pub fn view(&self) -> Element<'_, Message> {
        match self.view {
            View::Driver => driver::view(&self.model, self.now),
            View::Pit => pit::view(&self.model, self.now),
            View::Tune => {
                let fresh = self.model.freshness(self.now) == crate::model::Freshness::Fresh;
                let telemetry = self
                    .model
                    .latest()
                    .filter(|_| fresh)
                    .map(|latest| &latest.telemetry);
                tune::view(&self.tune, telemetry)
            }
        }
    }

    /// The window title.
    pub fn title(&self) -> String {
        format!("AER dashboard: {}", self.link.prefix)
    }

    /// Always the dark theme: the views set their own high-contrast colours.
    pub fn theme(&self) -> Theme {
        Theme::Dark
    }

    /// The MQTT link, the clock and the keyboard.
    pub fn subscription(&self) -> Subscription<Message> {
        Subscription::batch([
            Subscription::run_with(self.link.clone(), |settings| link::stream(settings.clone()))
                .map(|event| match event {
                    link::Event::Ready(control) => Message::LinkReady(control),
                    link::Event::Update(at, update) => Message::Link(at, update),
                }),
            Subscription::run_with(self.tune_settings.clone(), |settings| {
                worker::stream(settings.clone())
            })
            .map(Message::TuneWorker),
            iced::time::every(TICK).map(Message::Tick),
            keyboard::listen().filter_map(key_message),
        ])
    }
}

fn key_message(event: keyboard::Event) -> Option<Message> {
    let keyboard::Event::KeyPressed { key, .. } = event else {
        return None;
    };
    match key.as_ref() {
        Key::Named(Named::Tab) => Some(Message::ToggleView),
        Key::Character(c) if c.eq_ignore_ascii_case("l") => Some(Message::MarkLap),
        _ => None,
    }
}

/// The banner both views put on top, most urgent first: a lost link, data that stopped or never
/// became readable (with the reason when the schemas disagree), stale data, a schema mismatch
/// that still lets data through.
pub fn status_banner<'a>(
    model: &Dashboard,
    freshness: Freshness,
    now: Instant,
) -> Option<Element<'a, Message>> {
    let health = model.health();
    let schema = health.schema_match();
    let no_data = freshness != Freshness::Fresh;
    let (message, color) = match (&health.connection, freshness) {
        (Connection::Lost { since, reason }, _) => (
            format!(
                "NO LINK to the broker for {:.0} s: {reason}",
                now.saturating_duration_since(*since).as_secs_f64()
            ),
            style::CRITICAL,
        ),
        _ if no_data && schema == SchemaMatch::FirmwareDiffers => (
            "FIRMWARE ON ANOTHER SCHEMA: the Pi rejects its packets, flash the CCM".to_owned(),
            style::CRITICAL,
        ),
        (_, Freshness::NoData) if health.undecodable > 0 => (
            match schema {
                SchemaMatch::PiDiffers => {
                    "TELEMETRY UNREADABLE: the Pi runs another schema".to_owned()
                }
                _ => "TELEMETRY UNREADABLE: see the pit view's link panel".to_owned(),
            },
            style::CRITICAL,
        ),
        (_, Freshness::Stale(age)) => (
            format!("STALE: no telemetry for {:.1} s", age.as_secs_f64()),
            style::WARN,
        ),
        (Connection::Connecting, Freshness::NoData) => {
            ("CONNECTING to the broker".to_owned(), style::WARN)
        }
        (_, Freshness::NoData) => ("NO DATA from the car yet".to_owned(), style::WARN),
        (_, Freshness::Fresh) if schema == SchemaMatch::PiDiffers => (
            "SCHEMA: the Pi and this dashboard differ, fields may be missing".to_owned(),
            style::WARN,
        ),
        (_, Freshness::Fresh) => return None,
    };
    Some(
        container(text(message).size(26))
            .padding([4, 12])
            .width(Fill)
            .style(style::banner(color))
            .into(),
    )
}
