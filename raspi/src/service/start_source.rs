//! Starting a job's source: the SocketCAN interfaces, a log replayed (once, or looping), the
//! bundled session looping (the demo), or nothing for a fed pipeline (its caller sends).

use super::{Job, demo_log};
use crate::config::Config;
use crate::health::Health;
use crate::source::replay::{ReplayOptions, replay, replay_segment};
use crate::source::{self, Input, Replies};
use aer_host::formats::raw_format::SegmentReader;
use aer_host::reports::counters::Counters;
use anyhow::{Context, Result};
use std::io::BufReader;
use std::sync::Arc;
use tokio_util::sync::CancellationToken;
use tracing::{info, warn};

/// Starts `job`'s source on its own task, sending to `inputs`; returns where flow control goes.
pub(super) fn start_source(
    config: &Config,
    job: &Job,
    inputs: source::Sender,
    counters: &Arc<Counters>,
    health: &Arc<Health>,
    cancel: &CancellationToken,
    broker_address: &str,
) -> Result<Replies> {
    let (counters, cancel) = (counters.clone(), cancel.clone());
    match job.clone() {
        // The caller holds the sender this pipeline's own would have been.
        Job::Fed => drop(inputs),
        Job::Live => return start_live(config, inputs, &counters, health, &cancel),
        Job::Replay {
            file,
            looping: true,
            ..
        } => {
            let (log, from) = match file {
                Some(file) => (
                    std::fs::read_to_string(&file).with_context(|| {
                        format!("reading {} (--loop replays a candump log)", file.display())
                    })?,
                    file.display().to_string(),
                ),
                None => demo_log(),
            };
            info!(log = %from, "replaying in a loop, restamped");
            loop_log(log, inputs, counters, cancel);
        }
        Job::Replay {
            file: None,
            looping: false,
            ..
        } => anyhow::bail!("replay needs a file (or --loop for the bundled session)"),
        Job::Replay {
            file: Some(file),
            fast,
            ..
        } => {
            let options = ReplayOptions {
                fast,
                restamp: false,
            };
            let mut log = std::fs::File::open(&file)
                .with_context(|| format!("opening {}", file.display()))?;
            let mut start = [0u8; 8];
            let raw = std::io::Read::read(&mut log, &mut start)
                .is_ok_and(|n| SegmentReader::is_segment(start.get(..n).unwrap_or(&[])));
            let log = std::fs::File::open(&file)
                .with_context(|| format!("opening {}", file.display()))?;
            tokio::spawn(async move {
                let stats = if raw {
                    let data = std::fs::read(&file).unwrap_or_default();
                    replay_segment(&data, inputs, &counters, options, &cancel)
                        .await
                        .unwrap_or_else(|error| {
                            warn!(%error, file = %file.display(), "not a readable raw log segment");
                            Default::default()
                        })
                } else {
                    replay(BufReader::new(log), inputs, &counters, options, &cancel).await
                };
                info!(
                    lines = stats.lines,
                    frames = stats.frames,
                    bad_lines = stats.bad_lines,
                    "replay finished"
                );
            });
        }
        Job::Demo => {
            let (log, from) = demo_log();
            announce_demo(config, broker_address, &from);
            loop_log(log, inputs, counters, cancel);
        }
    }
    Ok(Replies::default())
}

/// Replays `log` (candump text) again and again at recorded speed, each frame stamped with
/// the time it goes in, until `cancel` or the pipeline closes.
fn loop_log(
    log: String,
    inputs: source::Sender,
    counters: Arc<Counters>,
    cancel: CancellationToken,
) {
    let options = ReplayOptions {
        fast: false,
        restamp: true,
    };
    tokio::spawn(async move {
        let mut pass = 1;
        while !cancel.is_cancelled() && !inputs.is_closed() {
            replay(log.as_bytes(), inputs.clone(), &counters, options, &cancel).await;
            if cancel.is_cancelled() {
                break;
            }
            pass += 1;
            if inputs.send(vec![Input::Restart { pass }]).await.is_err() {
                break;
            }
        }
    });
}

#[cfg(target_os = "linux")]
fn start_live(
    config: &Config,
    inputs: source::Sender,
    counters: &Arc<Counters>,
    health: &Arc<Health>,
    cancel: &CancellationToken,
) -> Result<Replies> {
    Ok(source::socketcan::start(
        &config.can.interfaces,
        &config.can.telemetry_interface,
        config.can.isotp,
        inputs,
        counters,
        health,
        cancel,
    ))
}

#[cfg(not(target_os = "linux"))]
fn start_live(
    _: &Config,
    _: source::Sender,
    _: &Arc<Counters>,
    _: &Arc<Health>,
    _: &CancellationToken,
) -> Result<Replies> {
    anyhow::bail!("SocketCAN needs Linux; use `replay` or `demo` here")
}

fn announce_demo(config: &Config, broker_address: &str, from: &str) {
    let (host, port) = broker_address
        .rsplit_once(':')
        .unwrap_or((broker_address, "1883"));
    println!(
        "aer-raspi demo: replaying {from} at recorded speed, looping until Ctrl-C.\n\
         Watch it:   mosquitto_sub -h {host} -p {port} -t 'aer/#' -v\n\
         Dashboard:  cargo run --release -p aer-dashboard (Tab: pit view)\n\
         Plot it:    PlotJuggler > Streaming > MQTT, broker {host}:{port}, topic aer/{car}/telemetry (JSON, timestamp field `ts`)\n\
         Data file:  {file} (SQLite, tables from schema/)\n\
         Export it:  aer-raspi export --demo --session latest --out DIR (MCAP, Parquet, CSV, BLF, ASC, MF4, the layouts and the run report)\n\
         Report:     aer-raspi report --demo (laps, energy, what went wrong, the calibration)",
        car = config.car_id,
        file = std::fs::canonicalize(&config.store.path)
            .unwrap_or_else(|_| config.store.path.clone())
            .display()
    );
}
