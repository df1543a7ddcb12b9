//! The service: a source -> the ingest stage (raw log first) -> the MQTT and store sinks, with
//! the reporter and the forwarder. [`Pipeline`] assembles it and runs it until its source ends
//! or a shutdown signal fires (the one way to start it: the service, the tests and the
//! benchmarks); [`serve`] is the service itself, which alone installs signal handlers.

mod pipeline;
mod start_source;
mod subsystems;

pub use pipeline::Pipeline;

use crate::config::Config;
use anyhow::Result;
use std::future::Future;
use std::path::PathBuf;
use tracing::info;

/// The session the demo replays: recorded from the closed-loop car model with the CCM's own
/// logic, telemetry packer and ISO-TP sender (`cargo xtask session-log`). This copy is compiled
/// in, for an installed service; `demo_log` prefers the repository's file.
pub const DEMO_LOG: &str = include_str!("../../data/session.log");

/// The repository's session log, as `cargo xtask session-log` rewrites it.
pub(crate) const DEMO_LOG_PATH: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/data/session.log");

/// The session the demo replays and where it came from: the repository's file, read now, so a
/// log just re-recorded with `cargo xtask session-log` plays without rebuilding; the compiled-in
/// copy where there is no repository (an installed service).
pub(crate) fn demo_log() -> (String, String) {
    match std::fs::read_to_string(DEMO_LOG_PATH) {
        Ok(text) => (text, DEMO_LOG_PATH.to_owned()),
        Err(_) => (
            DEMO_LOG.to_owned(),
            "the session compiled into this binary".to_owned(),
        ),
    }
}

/// Where the frames come from.
#[derive(Debug, Clone, PartialEq)]
pub enum Job {
    /// The configured SocketCAN interfaces.
    Live,
    /// A candump log (or raw log segment), at recorded speed or flat out; `looping`: a
    /// candump log (the bundled session without a file) again and again, restamped, until
    /// stopped. Without `looping` a file is needed.
    Replay {
        file: Option<PathBuf>,
        fast: bool,
        looping: bool,
    },
    /// The bundled session, looping until stopped.
    Demo,
    /// Inputs the caller sends through [`Pipeline::input`] (tests, benchmarks, a program that
    /// embeds the service): the source ends when the caller drops that sender.
    Fed,
}

impl Job {
    /// What the session records as its source.
    pub(crate) fn source_name(&self) -> &'static str {
        match self {
            Self::Live => "live",
            Self::Replay { .. } => "replay",
            Self::Demo => "demo",
            Self::Fed => "fed",
        }
    }
}

/// Runs `job` until its source ends, SIGINT (Ctrl-C) or SIGTERM (systemd).
pub async fn serve(config: Config, job: Job) -> Result<()> {
    let pipeline = Pipeline::start(config, job).await?;
    let stop = stop_signal()?;
    tell_systemd_ready();
    pipeline.run(stop).await?;
    Ok(())
}

/// Under systemd (`Type=notify`) the unit turns active only now: the broker's listeners are
/// bound and the stop signals handled, so a client started after `systemctl start` returns
/// (a dashboard, `mosquitto_sub`) connects at once instead of racing the service's start.
/// Outside systemd there is no notify socket and this does nothing.
fn tell_systemd_ready() {
    #[cfg(unix)]
    if let Err(error) = sd_notify::notify(true, &[sd_notify::NotifyState::Ready]) {
        tracing::warn!(%error, "could not tell systemd the service is ready");
    }
}

/// Completes on SIGINT (Ctrl-C) or SIGTERM (what systemd sends to stop a service). The
/// handlers are installed now, so a signal from here on is not lost.
#[cfg(unix)]
fn stop_signal() -> Result<impl Future<Output = ()> + Send + 'static> {
    use anyhow::Context;
    use tokio::signal::unix::{SignalKind, signal};
    let mut terminate = signal(SignalKind::terminate()).context("handling SIGTERM")?;
    let mut interrupt = signal(SignalKind::interrupt()).context("handling SIGINT")?;
    Ok(async move {
        let name = tokio::select! {
            _ = terminate.recv() => "SIGTERM",
            _ = interrupt.recv() => "SIGINT",
        };
        info!(signal = name, "flushing and stopping");
    })
}

#[cfg(not(unix))]
fn stop_signal() -> Result<impl Future<Output = ()> + Send + 'static> {
    Ok(async {
        if tokio::signal::ctrl_c().await.is_ok() {
            info!("Ctrl-C: flushing and stopping");
        } else {
            std::future::pending::<()>().await;
        }
    })
}
