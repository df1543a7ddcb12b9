//! Both views rendered to PNG without a display: the same widgets as on screen, drawn by
//! iced's software renderer (tiny-skia) with the bundled Fira Sans font.

use crate::config::{Config, View};
use crate::model::{Dashboard, Update};
use crate::session::Session;
use crate::ui::App;
use anyhow::{Context, Result, anyhow};
use iced::advanced::renderer::{Headless, Style};
use iced::{Color, Font, Pixels, Renderer, Size, mouse};
use iced_runtime::user_interface::{Cache, UserInterface};
use std::path::Path;
use std::pin::pin;
use std::task::{Context as TaskContext, Poll, Waker};
use std::time::{Duration, Instant};

/// The font of every screen, bundled so the car's display, a laptop and a screenshot look alike.
pub const FONT: Font = Font::with_name("Fira Sans");

/// Screen sizes: the car's 800x480 display and a laptop window.
pub const DRIVER_SIZE: Size = Size::new(800.0, 480.0);
pub const PIT_SIZE: Size = Size::new(1280.0, 800.0);

/// A dashboard that has seen `session` up to `at` seconds into it, as if live: each packet
/// arrived when the Pi stamped it, and the screen is drawn 50 ms after the last one.
pub fn replayed(config: &Config, session: &Session, at: Option<f64>) -> (Dashboard, Instant) {
    let mut model = Dashboard::new(config);
    let start = Instant::now();
    model.apply(Update::Connected, start);
    model.apply(Update::Status(Box::new(session.status.clone())), start);
    model.apply(Update::Metrics(Box::new(session.metrics.clone())), start);
    let first = session.samples.first().map_or(0.0, |s| s.ts);
    let mut last = start;
    for sample in &session.samples {
        let offset = (sample.ts - first).max(0.0);
        if at.is_some_and(|at| offset > at) {
            break;
        }
        last = start + Duration::from_secs_f64(offset);
        model.telemetry(sample, last);
    }
    (model, last + Duration::from_millis(50))
}

/// A renderer that draws views into memory instead of a window.
pub struct Offscreen {
    renderer: Renderer,
}

impl Offscreen {
    /// The software renderer with the dashboard's font.
    pub fn new() -> Result<Self> {
        // The software renderer is ready at once; nothing here needs an executor.
        let mut future = pin!(<Renderer as Headless>::new(FONT, Pixels(16.0), None));
        match future
            .as_mut()
            .poll(&mut TaskContext::from_waker(Waker::noop()))
        {
            Poll::Ready(Some(renderer)) => Ok(Self { renderer }),
            Poll::Ready(None) => Err(anyhow!("the software renderer could not start")),
            Poll::Pending => Err(anyhow!("the renderer needs an executor (a GPU backend?)")),
        }
    }

    /// Lays out and draws `app` at `size` (logical pixels, scale 1); returns RGBA pixels.
    pub fn render(&mut self, app: &App, size: Size) -> Vec<u8> {
        let renderer = &mut self.renderer;
        let mut ui = UserInterface::build(app.view(), size, Cache::default(), renderer);
        // Widgets settle what they show (a button: whether it can be pressed) on the first
        // redraw request, as a window's first frame does.
        let redraw = iced::Event::Window(iced::window::Event::RedrawRequested(Instant::now()));
        let mut ignored = Vec::new();
        let _ = ui.update(
            &[redraw],
            mouse::Cursor::Unavailable,
            renderer,
            &mut iced::advanced::clipboard::Null,
            &mut ignored,
        );
        ui.draw(
            renderer,
            &app.theme(),
            &Style {
                text_color: Color::WHITE,
            },
            mouse::Cursor::Unavailable,
        );
        let physical = Size::new(size.width.round() as u32, size.height.round() as u32);
        renderer.screenshot(physical, 1.0, Color::BLACK)
    }
}

/// Writes RGBA pixels of `size` as a PNG file.
pub fn write_png(path: &Path, rgba: &[u8], size: Size) -> Result<()> {
    let file =
        std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?;
    let mut encoder = png::Encoder::new(
        std::io::BufWriter::new(file),
        size.width.round() as u32,
        size.height.round() as u32,
    );
    encoder.set_color(png::ColorType::Rgba);
    encoder.set_depth(png::BitDepth::Eight);
    let mut writer = encoder
        .write_header()
        .with_context(|| format!("writing {}", path.display()))?;
    writer
        .write_image_data(rgba)
        .with_context(|| format!("writing {}", path.display()))?;
    writer
        .finish()
        .with_context(|| format!("writing {}", path.display()))
}

/// The screens both views must fit: the car's display and a laptop window.
pub const SIZES: [Size; 2] = [DRIVER_SIZE, PIT_SIZE];

/// Renders both views of `session` at `at` seconds into `dir`, each at every size in [`SIZES`]
/// (`driver-800x480.png`, `pit-1280x800.png`, ...); returns the files written.
pub fn both_views(
    config: &Config,
    session: &Session,
    at: Option<f64>,
    dir: &Path,
) -> Result<Vec<std::path::PathBuf>> {
    let (model, now) = replayed(config, session, at);
    let mut offscreen = Offscreen::new()?;
    let mut written = Vec::new();
    for (view, name) in [(View::Driver, "driver"), (View::Pit, "pit")] {
        written.extend(every_size(
            &mut offscreen,
            &App::with_model(config, model.clone(), view, now),
            dir,
            name,
        )?);
    }
    Ok(written)
}

/// Renders `app` at every size in [`SIZES`] into `dir` as `<name>-<width>x<height>.png`;
/// returns the files written.
pub fn every_size(
    offscreen: &mut Offscreen,
    app: &App,
    dir: &Path,
    name: &str,
) -> Result<Vec<std::path::PathBuf>> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut written = Vec::new();
    for size in SIZES {
        let path = dir.join(format!("{name}-{}x{}.png", size.width, size.height));
        write_png(&path, &offscreen.render(app, size), size)?;
        written.push(path);
    }
    Ok(written)
}
