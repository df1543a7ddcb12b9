//! A line plot of one field over the history window, drawn on a canvas.

use super::style;
use crate::model::history::Series;
use iced::widget::canvas::{self, Frame, Geometry, Path, Stroke, Text};
use iced::{Color, Point, Rectangle, Renderer, Size, Theme, mouse};

/// Points a plot draws at most (about one per pixel column of a laptop's plot).
pub const MAX_POINTS: usize = 600;

/// One series over `window_s` seconds, newest at the right edge.
#[derive(Debug)]
pub struct Plot {
    pub series: Series,
    pub window_s: f32,
    pub color: Color,
}

impl<Message> canvas::Program<Message> for Plot {
    type State = ();

    fn draw(
        &self,
        _: &(),
        renderer: &Renderer,
        _: &Theme,
        bounds: Rectangle,
        _: mouse::Cursor,
    ) -> Vec<Geometry> {
        let mut frame = Frame::new(renderer, bounds.size());
        frame.fill_rectangle(Point::ORIGIN, bounds.size(), style::BACKGROUND);
        let label_width = 56.0;
        let area = Rectangle::new(
            Point::new(label_width, 6.0),
            Size::new(
                (bounds.width - label_width - 6.0).max(1.0),
                (bounds.height - 12.0).max(1.0),
            ),
        );
        let grid = Stroke::default()
            .with_color(Color::from_rgb(0.25, 0.25, 0.27))
            .with_width(1.0);
        frame.stroke(&Path::rectangle(area.position(), area.size()), grid);

        let Series { points, min, max } = &self.series;
        if points.is_empty() {
            return vec![frame.into_geometry()];
        }
        // A flat line sits in the middle of a one-unit band.
        let (low, high) = if max > min {
            (*min, *max)
        } else {
            (min - 0.5, max + 0.5)
        };
        let x = |age: f32| area.x + area.width * (1.0 - (age / self.window_s).clamp(0.0, 1.0));
        let y = |v: f32| area.y + area.height * (1.0 - (v - low) / (high - low));
        let line = Path::new(|path| {
            let mut points = points.iter();
            if let Some(&(age, v)) = points.next() {
                path.move_to(Point::new(x(age), y(v)));
            }
            for &(age, v) in points {
                path.line_to(Point::new(x(age), y(v)));
            }
        });
        frame.stroke(
            &line,
            Stroke::default().with_color(self.color).with_width(2.0),
        );
        // Too short for two labels, the plot keeps the top one rather than overlap them.
        let labels = if area.height >= 32.0 {
            vec![(high, area.y), (low, area.y + area.height - 14.0)]
        } else {
            vec![(high, area.y)]
        };
        for (value, at) in labels {
            frame.fill_text(Text {
                content: compact(value),
                position: Point::new(4.0, at),
                color: style::DIM,
                size: 13.0.into(),
                ..Text::default()
            });
        }
        vec![frame.into_geometry()]
    }
}

/// A value in at most about six characters.
fn compact(value: f32) -> String {
    match value.abs() {
        v if v >= 10_000.0 => format!("{:.0}k", value / 1_000.0),
        v if v >= 100.0 => format!("{value:.0}"),
        v if v >= 1.0 => format!("{value:.1}"),
        0.0 => "0".to_owned(),
        _ => format!("{value:.3}"),
    }
}

#[cfg(test)]
mod tests {
    use super::compact;

    #[test]
    fn axis_labels_stay_short() {
        assert_eq!(compact(12_345.0), "12k");
        assert_eq!(compact(-250.4), "-250");
        assert_eq!(compact(2.71), "2.7");
        assert_eq!(compact(0.0123), "0.012");
        assert_eq!(compact(0.0), "0");
    }
}
