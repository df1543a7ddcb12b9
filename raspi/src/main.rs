//! aer-raspi: the Pi's ingest service. CAN (or a recorded log, or a synthetic car) -> ISO-TP
//! and DBC decoding -> typed MQTT topics on an embedded broker + a durable local store ->
//! TDengine.

use aer_raspi::config::Config;
use aer_raspi::export::{self, Format};
use aer_raspi::service::{Job, serve};
use aer_raspi::store;
use aer_raspi::store::session::{self, Changes};
use aer_raspi::store::session_messages;
use anyhow::{Context, Result, bail};
use clap::{Args, Parser, Subcommand};
use std::path::{Path, PathBuf};

/// Where the demo records (without a config file or AER_STORE_PATH), and `export --demo` reads.
const DEMO_STORE: &str = "aer-demo.sqlite";

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
    /// Configuration file (TOML; every key optional, see raspi/config/aer-raspi.toml).
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
        /// The log file, or a segment of the raw log (`raw-*.aerraw`).
        file: PathBuf,
        /// As fast as possible instead of at recorded speed.
        #[arg(long)]
        fast: bool,
    },
    /// Run the closed-loop car model (the CCM's own logic driving a simulated car round an
    /// autocross course) as a live source: every frame on both buses.
    Synthetic {
        /// Packets per second.
        #[arg(long, default_value_t = 100.0)]
        rate: f64,
        /// Stop after this many packets (default: until Ctrl-C).
        #[arg(long)]
        packets: Option<u64>,
    },
    /// Replay the bundled session at recorded speed, looping until Ctrl-C, with the embedded
    /// broker on 127.0.0.1:1883, the local store aer-demo.sqlite and the raw log in
    /// aer-demo-raw/.
    Demo,
    /// Sessions in the local store: list them, change the open one's metadata (or another's
    /// with --id), or start the next one while the service runs.
    Session {
        #[command(subcommand)]
        action: SessionAction,
    },
    /// Export a session (or a time range) from the local store, or a recorded log, as MCAP
    /// (Foxglove, PlotJuggler), Parquet (pandas, polars) and CSV.
    Export(ExportArgs),
    /// Compact every closed session in the local store now (the running service does it by
    /// itself, a block at a time): before copying the store off the car, or after a
    /// `compact = false` season.
    Compact,
    /// Print raw log segments as candump -l text (every frame, losslessly), oldest first; a
    /// folder means every segment in it.
    RawExport {
        /// Segment files or raw log folders.
        #[arg(required = true)]
        paths: Vec<PathBuf>,
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
    New,
    /// Each CAN message of the open session (or of session --id) per bus: frames, measured
    /// and declared rate, checksum failures, counter repeats and jumps, late frames.
    Messages {
        #[arg(long)]
        id: Option<i64>,
    },
}

#[derive(Args)]
struct ExportArgs {
    /// Export this session (`aer-raspi session list`), or `latest`; without it, every row in
    /// the time range.
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
    /// The formats (default: all three).
    #[arg(long = "format", value_enum)]
    formats: Vec<Format>,
    /// Where to write: DIR/session.mcap, DIR/parquet/<table>.parquet, DIR/csv/<table>.csv.
    #[arg(long)]
    out: PathBuf,
    /// Read the store the demo records into (aer-demo.sqlite) instead of the configured one.
    #[arg(long, conflicts_with = "log")]
    demo: bool,
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

fn main() -> Result<()> {
    aer_host::logging::init("info,rumqttd=warn", BROKER_ROUTINE);
    let cli = Cli::parse();
    if let Command::RawExport { paths } = &cli.command {
        return aer_raspi::rawlog::export::candump(paths, std::io::stdout().lock());
    }
    let mut config = Config::load(cli.config.as_deref(), |key| std::env::var(key).ok())?;
    config.session = cli.session.changes().apply(config.session);
    match &cli.command {
        Command::Session { action } => return session_command(&config, action, &cli.session),
        Command::Export(args) => return export_command(&config, args),
        Command::Compact => return compact_command(&config),
        _ => {}
    }
    if matches!(cli.command, Command::Demo) && cli.config.is_none() {
        if std::env::var_os("AER_STORE_PATH").is_none() {
            config.store.path = DEMO_STORE.into();
        }
        if std::env::var_os("AER_RAW_LOG_DIR").is_none() {
            config.raw_log.dir = "aer-demo-raw".into();
        }
    }
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    let job = match cli.command {
        Command::Run => Job::Live,
        Command::Replay { file, fast } => Job::Replay { file, fast },
        Command::Synthetic { rate, packets } => Job::Synthetic { rate, packets },
        Command::Demo => Job::Demo,
        Command::RawExport { .. }
        | Command::Session { .. }
        | Command::Export(_)
        | Command::Compact => {
            return Ok(());
        }
    };
    runtime.block_on(serve(config, job))
}

fn session_command(config: &Config, action: &SessionAction, flags: &SessionArgs) -> Result<()> {
    let db = store::open(&config.store.path)?;
    match action {
        SessionAction::List => {
            println!("id\tstarted\tended\tsource\tdriver\ttrack\trun\tnotes");
            for s in session::list(&db)? {
                let time = |us: i64| {
                    chrono::DateTime::from_timestamp_micros(us).map_or_else(
                        || us.to_string(),
                        |t| t.format("%Y-%m-%d %H:%M:%S").to_string(),
                    )
                };
                println!(
                    "{}\t{}\t{}\t{}\t{}\t{}\t{}\t{}",
                    s.id,
                    time(s.started_us),
                    s.ended_us.map_or_else(|| "open".to_owned(), time),
                    s.source,
                    s.metadata.driver,
                    s.metadata.track,
                    s.metadata.run.map(|r| r.to_string()).unwrap_or_default(),
                    s.metadata.notes
                );
            }
        }
        SessionAction::Set { id } => {
            let id = match id {
                Some(id) => *id,
                None => session::current(&db)?.context("no session is open; give --id")?,
            };
            anyhow::ensure!(
                session::change(&db, id, &flags.changes())?,
                "no session {id}"
            );
            println!("session {id} updated");
        }
        SessionAction::Messages { id } => {
            let id = match id {
                Some(id) => *id,
                None => session::current(&db)?.context("no session is open; give --id")?,
            };
            let hz = |rate: Option<f64>| rate.map_or_else(|| "-".to_owned(), |r| format!("{r:.2}"));
            println!(
                "bus\tmessage\tframes\tmeasured_hz\tdeclared_hz\tchecksum_failures\tcounter_repeats\tcounter_jumps\tlate_frames"
            );
            for m in session_messages::list(&db, id)? {
                println!(
                    "{}\t{}\t{}\t{}\t{}\t{}\t{}\t{}\t{}",
                    m.bus,
                    m.message,
                    m.frames,
                    hz(m.measured_hz()),
                    hz(m.declared_hz()),
                    m.checksum_failures,
                    m.counter_repeats,
                    m.counter_jumps,
                    m.late_frames
                );
            }
        }
        SessionAction::New => {
            let now = i64::try_from(aer_host::clock::now_us()).unwrap_or(i64::MAX);
            let id = session::begin(&db, &config.session, "live", now)?;
            println!("session {id} open");
        }
    }
    Ok(())
}

fn compact_command(config: &Config) -> Result<()> {
    let path = &config.store.path;
    let mut db = store::open(path)?;
    let mut compaction = store::Compaction::everything_closed();
    let mut rows = 0;
    loop {
        let step = compaction.step(&mut db)?;
        if step == 0 {
            break;
        }
        rows += step;
    }
    store::space::release_free_pages(&db)?;
    db.query_row("PRAGMA wal_checkpoint(TRUNCATE)", [], |_| Ok(()))?;
    let bytes = std::fs::metadata(path).map(|m| m.len()).unwrap_or(0);
    println!("{rows} rows compacted; {} is {bytes} bytes", path.display());
    Ok(())
}

fn export_command(config: &Config, args: &ExportArgs) -> Result<()> {
    let (db, extra) = match &args.log {
        Some(log) => {
            let (db, counters) = export::load::from_log(log, &config.car_id)?;
            let bad = counters
                .bad_lines
                .load(std::sync::atomic::Ordering::Relaxed);
            if bad > 0 {
                tracing::warn!(bad, log = %log.display(), "lines or blocks that do not parse were skipped");
            }
            let m = &config.session;
            let mut extra = vec![
                ("log".to_owned(), log.display().to_string()),
                ("driver".to_owned(), m.driver.clone()),
                ("track".to_owned(), m.track.clone()),
                (
                    "run".to_owned(),
                    m.run.map(|r| r.to_string()).unwrap_or_default(),
                ),
                ("notes".to_owned(), m.notes.clone()),
            ];
            extra.push(("skipped_lines".to_owned(), bad.to_string()));
            (db, extra)
        }
        None => {
            let path = if args.demo {
                Path::new(DEMO_STORE)
            } else {
                config.store.path.as_path()
            };
            if !path.exists() {
                let hint = if !args.demo && Path::new(DEMO_STORE).exists() {
                    format!("; the demo recorded into {DEMO_STORE}: add --demo")
                } else {
                    String::new()
                };
                bail!("no store at {}{hint}", path.display());
            }
            let db = rusqlite::Connection::open_with_flags(
                path,
                rusqlite::OpenFlags::SQLITE_OPEN_READ_ONLY,
            )
            .with_context(|| format!("opening the store {}", path.display()))?;
            (db, Vec::new())
        }
    };
    let session = match args.session.as_deref() {
        None => None,
        Some("latest") => Some(
            session::list(&db)?
                .last()
                .map(|s| s.id)
                .context("the store has no sessions")?,
        ),
        Some(id) => Some(
            id.parse()
                .with_context(|| format!("--session {id}: a number or `latest`"))?,
        ),
    };
    let formats = if args.formats.is_empty() {
        Format::all()
    } else {
        args.formats.clone()
    };
    let request = export::Request {
        selection: export::load::Selection {
            session,
            from_us: args.from,
            to_us: args.to,
        },
        formats,
        out_dir: args.out.clone(),
        topic_root: format!("{}/{}", config.mqtt.topic_prefix, config.car_id),
        extra,
    };
    let report = export::export(&db, &request)?;
    let rows: usize = report.rows.iter().map(|(_, n)| n).sum();
    println!(
        "{rows} rows from {} tables, read in {:.1} ms",
        report.rows.len(),
        report.load.as_secs_f64() * 1e3
    );
    for format in &report.formats {
        let bytes: u64 = format.files.iter().map(|f| f.bytes).sum();
        println!(
            "{:?}: {} file(s), {bytes} bytes, {:.1} ms",
            format.format,
            format.files.len(),
            format.elapsed.as_secs_f64() * 1e3
        );
    }
    Ok(())
}
