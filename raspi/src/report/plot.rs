//! Line plots as inline SVG (no script, no external file: the report is one page that opens
//! anywhere). A long session is thinned to the lowest and highest value per horizontal pixel,
//! so a peak is never lost and the page stays small.

use crate::markup::escape;
use std::fmt::Write;

const WIDTH: f64 = 960.0;
const HEIGHT: f64 = 240.0;
const LEFT: f64 = 64.0;
const RIGHT: f64 = 16.0;
const TOP: f64 = 28.0;
const BOTTOM: f64 = 40.0;
/// Points kept per series: two per horizontal pixel.
const BUCKETS: usize = 880;

/// One line.
pub struct Series {
    pub label: String,
    pub color: &'static str,
    pub points: Vec<(f64, f64)>,
}

/// A plot of `series` against a shared x axis, with vertical lines at `marks` (lap ends).
pub fn svg(title: &str, x_label: &str, y_label: &str, series: &[Series], marks: &[f64]) -> String {
    let finite = |p: &&(f64, f64)| p.0.is_finite() && p.1.is_finite();
    let all = || series.iter().flat_map(|s| s.points.iter().filter(finite));
    let (mut x0, mut x1, mut y0, mut y1) = all().fold(
        (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ),
        |(a, b, c, d), &(x, y)| (a.min(x), b.max(x), c.min(y), d.max(y)),
    );
    if x0.partial_cmp(&x1) != Some(std::cmp::Ordering::Less) {
        (x0, x1) = (0.0, 1.0);
    }
    if y0.partial_cmp(&y1) != Some(std::cmp::Ordering::Less) {
        (y0, y1) = if y0.is_finite() {
            (y0 - 1.0, y0 + 1.0)
        } else {
            (0.0, 1.0)
        };
    }
    let (y0, y1, y_step) = nice_range(y0.min(0.0_f64.max(y0)), y1);
    let (_, _, x_step) = nice_range(x0, x1);
    let px = |x: f64| LEFT + (x - x0) / (x1 - x0) * (WIDTH - LEFT - RIGHT);
    let py = |y: f64| HEIGHT - BOTTOM - (y - y0) / (y1 - y0) * (HEIGHT - TOP - BOTTOM);
    let mut out = String::new();
    let _ = write!(
        out,
        r#"<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {WIDTH} {HEIGHT}" width="{WIDTH}" height="{HEIGHT}" font-family="sans-serif" font-size="11">"#
    );
    let _ = write!(
        out,
        r#"<text x="{LEFT}" y="16" font-size="13" font-weight="bold">{}</text>"#,
        escape(title)
    );
    // Grid and labels.
    let mut y = y0;
    while y <= y1 + y_step * 1e-9 {
        let _ = write!(
            out,
            "<line x1=\"{LEFT}\" x2=\"{:.1}\" y1=\"{:.1}\" y2=\"{:.1}\" stroke=\"#ddd\"/><text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"end\">{}</text>",
            WIDTH - RIGHT,
            py(y),
            py(y),
            LEFT - 4.0,
            py(y) + 4.0,
            tick(y, y_step)
        );
        y += y_step;
    }
    let mut x = (x0 / x_step).ceil() * x_step;
    while x <= x1 + x_step * 1e-9 {
        let _ = write!(
            out,
            "<line x1=\"{:.1}\" x2=\"{:.1}\" y1=\"{TOP}\" y2=\"{:.1}\" stroke=\"#eee\"/><text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\">{}</text>",
            px(x),
            px(x),
            HEIGHT - BOTTOM,
            px(x),
            HEIGHT - BOTTOM + 14.0,
            tick(x, x_step)
        );
        x += x_step;
    }
    for &mark in marks.iter().filter(|m| (x0..=x1).contains(*m)) {
        let _ = write!(
            out,
            "<line x1=\"{:.1}\" x2=\"{:.1}\" y1=\"{TOP}\" y2=\"{:.1}\" stroke=\"#999\" stroke-dasharray=\"4 3\"/>",
            px(mark),
            px(mark),
            HEIGHT - BOTTOM
        );
    }
    let _ = write!(
        out,
        r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">{}</text><text x="12" y="{:.1}" transform="rotate(-90 12 {:.1})" text-anchor="middle">{}</text>"#,
        (LEFT + WIDTH - RIGHT) / 2.0,
        HEIGHT - 6.0,
        escape(x_label),
        (TOP + HEIGHT - BOTTOM) / 2.0,
        (TOP + HEIGHT - BOTTOM) / 2.0,
        escape(y_label)
    );
    for (n, line) in series.iter().enumerate() {
        let points = thin(&line.points, x0, x1);
        let mut path = String::new();
        let mut pen_down = false;
        for &(x, y) in &points {
            if !(x.is_finite() && y.is_finite()) {
                pen_down = false;
                continue;
            }
            let _ = write!(
                path,
                "{}{:.1},{:.1} ",
                if pen_down { "L" } else { "M" },
                px(x),
                py(y)
            );
            pen_down = true;
        }
        let _ = write!(
            out,
            r#"<path d="{}" fill="none" stroke="{}" stroke-width="1.2"/><text x="{:.1}" y="{:.1}" fill="{}">{}</text>"#,
            path.trim_end(),
            line.color,
            WIDTH - RIGHT - 220.0,
            16.0 + 12.0 * n as f64,
            line.color,
            escape(&line.label)
        );
    }
    out.push_str("</svg>");
    out
}

/// At most two points per bucket of x: the lowest and the highest value, in x order; a gap
/// (a non-finite value) is kept as a gap.
fn thin(points: &[(f64, f64)], x0: f64, x1: f64) -> Vec<(f64, f64)> {
    if points.len() <= 2 * BUCKETS {
        return points.to_vec();
    }
    let mut out = Vec::with_capacity(2 * BUCKETS + 16);
    let bucket_of = |x: f64| (((x - x0) / (x1 - x0)) * BUCKETS as f64) as i64;
    // The bucket being filled: its number, its lowest point, its highest point.
    type Bucket = (i64, (f64, f64), (f64, f64));
    let mut current: Option<Bucket> = None;
    let flush = |out: &mut Vec<(f64, f64)>, low: (f64, f64), high: (f64, f64)| {
        if low.0 <= high.0 {
            out.extend([low, high]);
        } else {
            out.extend([high, low]);
        }
    };
    for &(x, y) in points {
        if !(x.is_finite() && y.is_finite()) {
            if let Some((_, low, high)) = current.take() {
                flush(&mut out, low, high);
            }
            out.push((x, f64::NAN));
            continue;
        }
        let bucket = bucket_of(x);
        match &mut current {
            Some((b, low, high)) if *b == bucket => {
                if y < low.1 {
                    *low = (x, y);
                }
                if y > high.1 {
                    *high = (x, y);
                }
            }
            _ => {
                if let Some((_, low, high)) = current.take() {
                    flush(&mut out, low, high);
                }
                current = Some((bucket, (x, y), (x, y)));
            }
        }
    }
    if let Some((_, low, high)) = current {
        flush(&mut out, low, high);
    }
    out
}

/// A range from `low` to `high` widened to round ticks, and the tick step.
fn nice_range(low: f64, high: f64) -> (f64, f64, f64) {
    let span = (high - low).max(1e-9);
    let raw = span / 5.0;
    let magnitude = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 2.5, 5.0, 10.0]
        .into_iter()
        .map(|m| m * magnitude)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * magnitude);
    (
        (low / step).floor() * step,
        (high / step).ceil() * step,
        step,
    )
}

fn tick(value: f64, step: f64) -> String {
    if step >= 1.0 {
        format!("{value:.0}")
    } else {
        let decimals = (-step.log10().floor()) as usize;
        format!("{value:.decimals$}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thinning_keeps_every_peak_and_the_order() {
        let points: Vec<(f64, f64)> = (0..100_000)
            .map(|i| {
                (
                    f64::from(i),
                    if i == 54_321 { 1e6 } else { f64::from(i % 7) },
                )
            })
            .collect();
        let thinned = thin(&points, 0.0, 99_999.0);
        assert!(thinned.len() <= 2 * BUCKETS + 2, "{}", thinned.len());
        assert!(thinned.contains(&(54_321.0, 1e6)), "the peak survives");
        assert!(thinned.windows(2).all(|w| w[0].0 <= w[1].0), "in x order");
    }

    #[test]
    fn a_plot_names_its_series_and_escapes_text() {
        let svg = svg(
            "Speed <km/h>",
            "distance (m)",
            "km/h",
            &[Series {
                label: "session 3".into(),
                color: "#1f77b4",
                points: vec![(0.0, 0.0), (100.0, 50.0), (f64::NAN, 1.0), (200.0, 20.0)],
            }],
            &[100.0],
        );
        assert!(svg.starts_with("<svg") && svg.ends_with("</svg>"));
        assert!(svg.contains("Speed &lt;km/h&gt;") && svg.contains("session 3"));
        assert_eq!(svg.matches("<path").count(), 1);
        assert!(svg.contains("stroke-dasharray"), "the lap mark");
    }
}
