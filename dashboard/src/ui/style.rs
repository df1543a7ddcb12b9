//! Colours and sizes: white on black, with amber and red reserved for warnings and faults, so
//! the driver reads the screen at a glance in sunlight.

use aer::telemetry::Level;
use iced::widget::{button, container, progress_bar};
use iced::{Background, Border, Color, Theme};

pub const BACKGROUND: Color = Color::BLACK;
pub const PANEL: Color = Color::from_rgb(0.09, 0.09, 0.10);
pub const TEXT: Color = Color::WHITE;
pub const DIM: Color = Color::from_rgb(0.62, 0.62, 0.65);
/// Values that are no longer current.
pub const STALE: Color = Color::from_rgb(0.45, 0.45, 0.47);
pub const GOOD: Color = Color::from_rgb(0.19, 0.82, 0.35);
pub const WARN: Color = Color::from_rgb(1.0, 0.69, 0.0);
pub const CRITICAL: Color = Color::from_rgb(1.0, 0.23, 0.19);
pub const PLOT: Color = Color::from_rgb(0.35, 0.78, 1.0);

/// The colour of a value at `level` (grey when stale).
pub fn level_color(level: Level, stale: bool) -> Color {
    if stale {
        return STALE;
    }
    match level {
        Level::Normal => TEXT,
        Level::Warn => WARN,
        Level::Critical => CRITICAL,
    }
}

/// The whole screen.
pub fn screen(_: &Theme) -> container::Style {
    container::Style {
        background: Some(BACKGROUND.into()),
        text_color: Some(TEXT),
        ..container::Style::default()
    }
}

/// A framed section.
pub fn panel(_: &Theme) -> container::Style {
    container::Style {
        background: Some(PANEL.into()),
        text_color: Some(TEXT),
        border: Border::default().rounded(6),
        ..container::Style::default()
    }
}

/// A solid banner in `color` (link lost, stale data, ready to drive).
pub fn banner(color: Color) -> impl Fn(&Theme) -> container::Style {
    move |_| container::Style {
        background: Some(color.into()),
        text_color: Some(Color::BLACK),
        border: Border::default().rounded(6),
        ..container::Style::default()
    }
}

/// A bar filled in `color` on a dark track.
pub fn bar(color: Color) -> impl Fn(&Theme) -> progress_bar::Style {
    move |_| progress_bar::Style {
        background: Background::Color(Color::from_rgb(0.2, 0.2, 0.22)),
        bar: Background::Color(color),
        border: Border::default().rounded(4),
    }
}

/// A field row that can be clicked to plot it: flat, lit when plotted.
pub fn field_row(plotted: bool) -> impl Fn(&Theme, button::Status) -> button::Style {
    move |_, status| {
        let background = match (plotted, status) {
            (true, _) => Some(Color::from_rgb(0.10, 0.20, 0.28).into()),
            (false, button::Status::Hovered) => Some(Color::from_rgb(0.16, 0.16, 0.18).into()),
            (false, _) => None,
        };
        button::Style {
            background,
            text_color: TEXT,
            border: Border::default().rounded(3),
            ..button::Style::default()
        }
    }
}

/// A command button: lit while it can be pressed, dim and flat while it cannot (so the Tune
/// page shows what the session allows now).
pub fn command(_: &Theme, status: button::Status) -> button::Style {
    let (background, text_color) = match status {
        button::Status::Disabled => (Color::from_rgb(0.16, 0.16, 0.18), STALE),
        button::Status::Hovered | button::Status::Pressed => {
            (Color::from_rgb(0.22, 0.36, 0.62), TEXT)
        }
        button::Status::Active => (Color::from_rgb(0.17, 0.29, 0.52), TEXT),
    };
    button::Style {
        background: Some(background.into()),
        text_color,
        border: Border::default().rounded(4),
        ..button::Style::default()
    }
}
