//! aer-raspi: the Pi's ingest service. CAN (or a recorded log) -> ISO-TP
//! and DBC decoding -> typed MQTT topics on an embedded broker + a durable local store ->
//! TDengine.

use aer_raspi::commands::{self, Located, export::Wanted};
use aer_raspi::config::{self, Config, Origin};
use aer_raspi::export::Format;
use aer_raspi::service::{Job, serve};
use aer_raspi::store::session::Changes;
use anyhow::{Context, Result};
use clap::{Args, Parser, Subcommand};
use std::path::{Path, PathBuf};

#[derive(Parser)]
#[command(
    name = "aer-raspi",
    version,
    about = "Raspberry Pi ingest: CAN/ISO-TP -> typed MQTT (embedded broker) + local store + TDengine",
    long_about = "Decodes the car's CAN traffic and the CCM's ISO-TP telemetry with the code generated \
from schema/, publishes every packet and frame as JSON on aer/<car>/telemetry and aer/<car>/can/<message>, \
appends it to a local SQLite store and (optionally) forwards the store to TDengine.\n\n\
Watch it: mosquitto_sub -h 127.0.0.1 -t 'aer/#' -v"
)]
struct Cli {
    /// Configuration file (TOML; every key optional, see raspi/config/aer-raspi.toml). The
    /// store commands (session, export, compact, clock) read /etc/aer/aer-raspi.toml, the
    /// installed service's, when neither this nor AER_CONFIG is given.
    #[arg(long, short, global = true, env = "AER_CONFIG")]
    config: Option<PathBuf>,
    /// Session metadata for this start (overrides `[session]` in the config).
    #[command(flatten)]
    session: SessionArgs,
    #[command(subcommand)]
    command: Command,
}

/// Who drives, where, which run: stored with the session and carried into every export.
#[derive(Args, Debug, Clone, Default)]
struct SessionArgs {
    /// Driver's name.
    #[arg(long, global = true)]
    driver: Option<String>,
    /// Track or event (`Skidpad`, `Endurance`, `Lot B autocross`).
    #[arg(long, global = true)]
    track: Option<String>,
    /// Run number.
    #[arg(long, global = true)]
    run: Option<u32>,
    /// Free notes (set-up, weather, what went wrong).
    #[arg(long, global = true)]
    notes: Option<String>,
}

impl SessionArgs {
    fn changes(&self) -> Changes {
        Changes {
            driver: self.driver.clone(),
            track: self.track.clone(),
            run: self.run,
            notes: self.notes.clone(),
        }
    }
}

#[derive(Subcommand)]
enum Command {
    /// Live: read the configured SocketCAN interfaces (ISO-TP telemetry and every DBC frame).
    Run,
    /// Replay a candump log (`candump -l` / `-L` format) or a raw log segment through the
    /// pipeline.
    Replay {
        /// The log file, or a segment of the raw log (`raw-*.aerraw`); with `--loop` and no
        /// file, the bundled session.
        #[arg(required_unless_present = "looping")]
        file: Option<PathBuf>,
        /// As fast as possible instead of at recorded speed.
        #[arg(long)]
        fast: bool,
        /// A candump log again and again until Ctrl-C, each frame stamped with the time it is
        /// replayed: a live-like source into the configured store, raw log and broker (the
        /// bundled session, or a log `cargo xtask session-log` wrote from the car model).
        #[arg(long = "loop", conflicts_with = "fast")]
        looping: bool,
    },
    /// Replay the bundled session at recorded speed, looping until Ctrl-C, with the embedded
    /// broker on 127.0.0.1:1883, the local store aer-demo.sqlite and the raw log in
    /// aer-demo-raw/.
    Demo,
    /// Sessions in the local store: list them (times in UTC), change the open one's metadata
    /// (or another's with --id), or start the next one while the service runs.
    Session {
        #[command(subcommand)]
        action: SessionAction,
        #[command(flatten)]
        store: StoreChoice,
    },
    /// Export a session (or a time range) from the local store, or a recorded log, as MCAP
    /// (Foxglove, PlotJuggler), Parquet (pandas, polars) and CSV, into a folder or as one tar
    /// archive with the session's raw log.
    Export(ExportArgs),
    /// A session's run report: per lap its time, distance, top speed, energy, peak power and
    /// temperatures; the fields beyond their thresholds; the problems, drops and counts as they
    /// came; the calibration in force; plots against distance. Printed, and written as
    /// report.txt and report.html (one page, plots inline) into --out.
    Report(ReportArgs),
    /// The Pi's clock as the sessions record it: the time in UTC, whether network time
    /// synchronized it, the open session's clock steps.
    Clock(StoreChoice),
    /// Compact every closed session in the local store now (the running service does it by
    /// itself, a block at a time): before copying the store off the car, or after a
    /// `compact = false` season.
    Compact(StoreChoice),
    /// Print raw log segments as candump -l text (every frame, losslessly), oldest first; a
    /// folder means every segment in it. With --format, write them as BLF, ASC or MF4 to --out.
    RawExport {
        /// Segment files or raw log folders.
        #[arg(required = true)]
        paths: Vec<PathBuf>,
        /// blf, asc or mf4 (CANalyzer, CANoe, CANape, asammdf) instead of candump text.
        #[arg(long, value_enum, requires = "out")]
        format: Option<FrameFormat>,
        /// The file to write with --format.
        #[arg(long, requires = "format")]
        out: Option<PathBuf>,
    },
}

/// What rumqttd logs as errors when a client simply leaves. Every client reaches the broker
/// through the service's gate, which logs clients coming and going (at debug) and reports
/// the ones it refuses or disconnects itself.
const BROKER_ROUTINE: &[aer_host::logging::Routine] = &[
    aer_host::logging::Routine {
        target: "rumqttd::server::broker",
        messages: &["router-drop", "disconnected", "connection-stop"],
    },
    aer_host::logging::Routine {
        target: "rumqttd::router",
        messages: &["no-connection id", "Connection is already disconnected"],
    },
];

/// The formats that hold frames, which raw log segments become.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
enum FrameFormat {
    Blf,
    Asc,
    Mf4,
}

impl From<FrameFormat> for Format {
    fn from(format: FrameFormat) -> Self {
        match format {
            FrameFormat::Blf => Self::Blf,
            FrameFormat::Asc => Self::Asc,
            FrameFormat::Mf4 => Self::Mf4,
        }
    }
}

/// Which store a store command reads or changes.
#[derive(Args, Debug, Clone, Copy, Default)]
struct StoreChoice {
    /// The store and raw log the demo records into (aer-demo.sqlite, aer-demo-raw/ in the
    /// current folder) instead of the configured ones.
    #[arg(long, global = true)]
    demo: bool,
}

#[derive(Subcommand)]
enum SessionAction {
    /// Every session: id, times, source, driver, track, run, notes.
    List,
    /// Change the metadata of the open session (or of session --id) to the flags given.
    Set {
        #[arg(long)]
        id: Option<i64>,
    },
    /// Close the open session and start the next one with the flags given; the running
    /// service stores its rows under the new one from its next commit (within a second).
    New {
        /// Start a new, empty store if there is none (otherwise a missing store is an error).
        #[arg(long)]
        create_store: bool,
    },
    /// Each CAN message of the open session (or of session --id) per bus: frames, measured
    /// and declared rate, checksum failures, counter repeats and jumps, late frames.
    Messages {
        #[arg(long)]
        id: Option<i64>,
    },
    /// Ends the lap in progress now (or at --at), in the open session: the report times laps
    /// with these marks as the driver's display does with its L key.
    Mark {
        /// Who marks: `pit` or `driver`.
        #[arg(long, default_value = "pit")]
        by: String,
        /// When (RFC 3339 or Unix seconds); now without it.
        #[arg(long, value_parser = parse_time)]
        at: Option<i64>,
    },
    /// What happened during the open session (or session --id), with when: lap marks, each
    /// `problems` entry of the status as it came and cleared, drops and integrity counts as
    /// they grew, loop points.
    Events {
        #[arg(long)]
        id: Option<i64>,
    },
    /// The calibration record of the open session (or of session --id): every change a pit
    /// master made through the XCP gateway (accepted or refused and why), then the values the
    /// session ended with; with --compare, those values beside another session's.
    Calibration {
        #[arg(long)]
        id: Option<i64>,
        /// The session to compare with.
        #[arg(long)]
        compare: Option<i64>,
    },
}

#[derive(Args)]
#[command(group = clap::ArgGroup::new("destination").required(true).args(["out", "archive"]))]
struct ExportArgs {
    /// Export this session (`aer-raspi session list`), or `latest`: the newest session with
    /// data; without it, every row in the time range.
    #[arg(long)]
    session: Option<String>,
    /// From this time: RFC 3339 (`2026-11-23T10:00:00Z`) or Unix seconds.
    #[arg(long, value_parser = parse_time)]
    from: Option<i64>,
    /// Up to this time (inclusive), as --from.
    #[arg(long, value_parser = parse_time)]
    to: Option<i64>,
    /// Read this candump log or raw log segment instead of the store (decoded as the service
    /// would store it; the session flags label it).
    #[arg(long)]
    log: Option<PathBuf>,
    /// The formats (default: all six; BLF, ASC and MF4 hold the raw log's frames).
    #[arg(long = "format", value_enum)]
    formats: Vec<Format>,
    /// Where to write: DIR/session.mcap, DIR/parquet/<table>.parquet, DIR/csv/<table>.csv,
    /// DIR/session.{blf,asc,mf4}.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Write one tar archive instead (`-`: to standard output, e.g. through ssh): the export
    /// under session-<id>/ and the session's raw log segments under session-<id>/raw/.
    #[arg(long)]
    archive: Option<PathBuf>,
    /// Remove an earlier export found in --out first (without it, such a folder is refused).
    #[arg(long, requires = "out")]
    replace: bool,
    #[command(flatten)]
    store: StoreChoice,
}

#[derive(Args)]
struct ReportArgs {
    /// The session (`aer-raspi session list`), or `latest`: the newest with data.
    #[arg(long, default_value = "latest")]
    session: String,
    /// Another session to set beside it: speed and time delta against distance, the laps, the
    /// calibration values that differ.
    #[arg(long)]
    compare: Option<String>,
    /// Also end a lap every so many metres (an endurance lap); without it a lap is a run from
    /// the first movement to the stop, or ends at a driver's or pit's mark.
    #[arg(long)]
    lap_length: Option<f64>,
    /// The folder for report.txt, report.html and derived.csv (default: report-session-<id>).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Also write resampled_100hz.csv: the run every 10 ms (each value held until the next),
    /// every telemetry field with enum names, the derived channels and the --signal columns.
    #[arg(long)]
    resample: bool,
    /// A CAN signal for the resampled table, as the exports name it (`can_dti_speed.dti_erpm`);
    /// repeat for more. Implies --resample.
    #[arg(long = "signal")]
    signals: Vec<String>,
    #[command(flatten)]
    store: StoreChoice,
}

/// A time as microseconds since the Unix epoch.
fn parse_time(text: &str) -> Result<i64, String> {
    if let Ok(seconds) = text.parse::<f64>() {
        return Ok((seconds * 1e6).round() as i64);
    }
    chrono::DateTime::parse_from_rfc3339(text)
        .map(|t| t.timestamp_micros())
        .map_err(|e| format!("`{text}` is neither RFC 3339 nor Unix seconds: {e}"))
}

/// A failure is the user's to read: what went wrong and why, never a stack trace (which
/// `RUST_BACKTRACE=1`, set for some other program, would otherwise print with every mistyped
/// flag or missing store).
fn main() -> std::process::ExitCode {
    match run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        // A reader that stopped reading (`| head`) is no failure of the command.
        Err(error)
            if error.chain().any(|cause| {
                cause
                    .downcast_ref::<std::io::Error>()
                    .is_some_and(|e| e.kind() == std::io::ErrorKind::BrokenPipe)
            }) =>
        {
            std::process::ExitCode::SUCCESS
        }
        Err(error) => {
            use std::io::Write as _;
            // Written, not printed: a closed standard error is no reason to panic.
            let mut stderr = std::io::stderr().lock();
            let _ = writeln!(stderr, "Error: {error}");
            let causes: Vec<String> = error.chain().skip(1).map(ToString::to_string).collect();
            if !causes.is_empty() {
                let _ = writeln!(stderr, "\nCaused by:");
                for (number, cause) in causes.iter().enumerate() {
                    let _ = writeln!(stderr, "    {number}: {cause}");
                }
            }
            std::process::ExitCode::FAILURE
        }
    }
}

fn run() -> Result<()> {
    aer_host::logging::init("info,rumqttd=warn", BROKER_ROUTINE);
    let cli = Cli::parse();
    if let Command::RawExport { paths, format, out } = &cli.command {
        return match (format, out) {
            (Some(format), Some(out)) => {
                let written = aer_raspi::export::raw_log::to_file(paths, (*format).into(), out)?;
                println!(
                    "{} frames to {} ({} bytes)",
                    written.rows,
                    written.path.display(),
                    written.bytes
                );
                Ok(())
            }
            _ => aer_raspi::export::raw_log::candump(paths, std::io::stdout().lock()),
        };
    }
    let store_choice = match &cli.command {
        Command::Session { store, .. } | Command::Compact(store) | Command::Clock(store) => {
            Some(*store)
        }
        Command::Export(args) => Some(args.store),
        Command::Report(args) => Some(args.store),
        _ => None,
    };
    if let Some(choice) = store_choice {
        let origin = if choice.demo {
            Origin::Demo
        } else {
            Origin::for_store_command(cli.config.as_deref(), Path::new(config::INSTALLED))
        };
        let mut located = Located::load(origin, |key| std::env::var(key).ok())?;
        located.config.session = cli.session.changes().apply(located.config.session);
        return store_command(&located, &cli);
    }
    let mut config = Config::load(cli.config.as_deref(), |key| std::env::var(key).ok())?;
    config.session = cli.session.changes().apply(config.session);
    // The demo records into its own store and raw log whatever configuration it is given (a
    // broker file, say), so every store command's `--demo` finds them.
    if matches!(cli.command, Command::Demo) {
        config = config.in_demo_store(|key| std::env::var(key).ok());
    }
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    let job = match cli.command {
        Command::Run => Job::Live,
        Command::Replay {
            file,
            fast,
            looping,
        } => Job::Replay {
            file,
            fast,
            looping,
        },
        Command::Demo => Job::Demo,
        Command::RawExport { .. }
        | Command::Session { .. }
        | Command::Export(_)
        | Command::Report(_)
        | Command::Compact(_)
        | Command::Clock(_) => {
            return Ok(());
        }
    };
    runtime.block_on(serve(config, job))
}

fn now_us() -> i64 {
    i64::try_from(aer_host::clock::now_us()).unwrap_or(i64::MAX)
}

/// The commands that read or change the store: results on stdout, what they did on stderr.
fn store_command(located: &Located, cli: &Cli) -> Result<()> {
    let mut out = std::io::stdout().lock();
    let mut notes = std::io::stderr().lock();
    match &cli.command {
        Command::Session { action, .. } => match action {
            SessionAction::List => commands::session::list(located, &mut out, &mut notes),
            SessionAction::Set { id } => {
                commands::session::set(located, *id, &cli.session.changes(), &mut out, &mut notes)
            }
            SessionAction::New { create_store } => commands::session::new(
                located,
                &located.config.session,
                *create_store,
                now_us(),
                &mut out,
                &mut notes,
            ),
            SessionAction::Messages { id } => {
                commands::session::messages(located, *id, &mut out, &mut notes)
            }
            SessionAction::Mark { by, at } => commands::session::mark(
                located,
                by,
                at.unwrap_or_else(now_us),
                &mut out,
                &mut notes,
            ),
            SessionAction::Events { id } => {
                commands::session::events(located, *id, &mut out, &mut notes)
            }
            SessionAction::Calibration { id, compare } => {
                commands::session::calibration(located, *id, *compare, &mut out, &mut notes)
            }
        },
        Command::Export(args) => {
            let wanted = Wanted {
                session: args.session.clone(),
                from_us: args.from,
                to_us: args.to,
                log: args.log.clone(),
                formats: args.formats.clone(),
                out: args.out.clone(),
                archive: args.archive.clone(),
                replace: args.replace,
            };
            commands::export::run(located, &wanted, &mut out, &mut notes)
        }
        Command::Report(args) => commands::report::run(
            located,
            &commands::report::Wanted {
                session: args.session.clone(),
                compare: args.compare.clone(),
                lap_length_m: args.lap_length,
                out: args.out.clone(),
                resample: args.resample,
                signals: args.signals.clone(),
            },
            &mut out,
            &mut notes,
        ),
        Command::Compact(_) => commands::compact(located, &mut out, &mut notes),
        Command::Clock(_) => commands::clock::show(
            located,
            now_us(),
            &aer_raspi::store::clock::state(),
            &mut out,
            &mut notes,
        ),
        _ => Ok(()),
    }
}
