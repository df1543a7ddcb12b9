//! aer-dashboard: the driver's display and the pit crew's view of the car's telemetry, fed by
//! the generated typed MQTT topics on the Pi's broker.

use aer_dashboard::config::{Config, StreamFormat, View};
use aer_dashboard::screenshot::{self, DRIVER_SIZE, FONT, PIT_SIZE};
use aer_dashboard::session;
use aer_dashboard::ui::App;
use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use std::path::PathBuf;
use std::time::Instant;

#[derive(Parser)]
#[command(
    name = "aer-dashboard",
    version,
    about = "Driver and pit views of the car's telemetry (MQTT topics aer/<car>/telemetry, status, metrics)",
    long_about = "Driver and pit views of the car's telemetry, read from the typed MQTT topics the Pi \
service publishes (aer/<car>/telemetry, aer/<car>/status, aer/<car>/metrics). Labels, units and \
thresholds come from schema/telemetry.yaml.\n\nKeys: Tab switches view, L marks a lap; in the pit \
view a click on a field plots it."
)]
struct Cli {
    /// Configuration file (TOML; every key optional, see dashboard/config/aer-dashboard.toml).
    #[arg(long, short, global = true, env = "AER_DASHBOARD_CONFIG")]
    config: Option<PathBuf>,
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Subcommand)]
enum Command {
    /// Show the dashboard (the default).
    Run {
        /// The view at start-up (default: the configuration's, driver).
        #[arg(long, value_enum)]
        view: Option<View>,
        /// Fill the screen (the car's display).
        #[arg(long)]
        fullscreen: bool,
        /// What to subscribe to (default: the configuration's, compact). The car's own display
        /// reads the broker on the same Pi: `json` spares it the stream's batching window.
        #[arg(long, value_enum)]
        stream: Option<StreamFormat>,
    },
    /// Render both views, filled from a recorded session, without a display, each at 800x480
    /// and 1280x800 (DIR/driver-800x480.png, DIR/pit-1280x800.png, ...).
    Screenshot {
        /// Where to write the PNG files.
        #[arg(long)]
        out: PathBuf,
        /// A candump log of the car (default: the session the Pi's demo replays).
        #[arg(long)]
        log: Option<PathBuf>,
        /// Seconds into the session to show (default: its end).
        #[arg(long)]
        at: Option<f64>,
    },
    /// Follow the car without a window (the pit view's link and model) until the session is
    /// whole, then print what arrived as JSON: packets held, history merged, stream gaps,
    /// live latency, catch-up time after each dropout. Exit status 1 if it never became
    /// whole. For checking a link.
    Follow {
        /// The session is whole once this many telemetry packets are held and nothing is
        /// being caught up.
        #[arg(long)]
        packets: usize,
        /// Give up after this many seconds.
        #[arg(long, default_value_t = 600)]
        timeout_s: u64,
    },
}

fn main() -> Result<()> {
    aer_host::logging::init("info,wgpu=warn,iced=warn", &[]);
    let cli = Cli::parse();
    let mut config = Config::load(cli.config.as_deref(), |key| std::env::var(key).ok())?;
    match cli.command.unwrap_or(Command::Run {
        view: None,
        fullscreen: false,
        stream: None,
    }) {
        Command::Run {
            view,
            fullscreen,
            stream,
        } => {
            config.display.view = view.unwrap_or(config.display.view);
            config.display.fullscreen |= fullscreen;
            config.link.stream = stream.unwrap_or(config.link.stream);
            run(config)
        }
        Command::Screenshot { out, log, at } => {
            let text = match &log {
                Some(path) => std::fs::read_to_string(path)
                    .with_context(|| format!("reading {}", path.display()))?,
                None => session::BUNDLED_SESSION.to_owned(),
            };
            let session = session::load(&text, &config.car_id);
            let bad_lines = session.metrics.counters.bad_lines;
            if bad_lines > 0 {
                tracing::warn!(
                    lines = bad_lines,
                    "log lines that are not CAN frames were skipped"
                );
            }
            for path in screenshot::both_views(&config, &session, at, &out)? {
                println!("{}", path.display());
            }
            Ok(())
        }
        Command::Follow { packets, timeout_s } => {
            let runtime = tokio::runtime::Builder::new_multi_thread()
                .enable_all()
                .build()
                .context("starting the async runtime")?;
            let report = runtime.block_on(aer_dashboard::link_check::follow(
                &config,
                packets,
                std::time::Duration::from_secs(timeout_s),
            ));
            println!("{}", serde_json::to_string(&report)?);
            if !report.whole {
                anyhow::bail!(
                    "the session was not whole after {timeout_s} s: {} of {packets} packets",
                    report.packets
                );
            }
            Ok(())
        }
    }
}

fn run(config: Config) -> Result<()> {
    let size = match config.display.view {
        View::Driver => DRIVER_SIZE,
        View::Pit | View::Tune => PIT_SIZE,
    };
    let window = iced::window::Settings {
        size,
        fullscreen: config.display.fullscreen,
        ..iced::window::Settings::default()
    };
    tracing::info!(
        broker = format!("{}:{}", config.mqtt.host, config.mqtt.port),
        topics = format!("{}/{{telemetry,status,metrics}}", config.topic_prefix()),
        "aer-dashboard"
    );
    let boot = move || App::new(&config, Instant::now());
    iced::application(boot, App::update, App::view)
        .title(App::title)
        .theme(App::theme)
        .subscription(App::subscription)
        .default_font(FONT)
        .window(window)
        .run()
        .context("the dashboard window")
}
