//! `aer-car-node`: the car model's CCM as an XCP slave on TCP or SocketCAN.

use aer_car_model::driver::Cycle;
use aer_car_node::{checks, link, masters, scenarios, serve};
use anyhow::{Result, bail};
use clap::{Parser, Subcommand, ValueEnum};
use std::path::PathBuf;

#[derive(Parser)]
#[command(version, about)]
struct Cli {
    #[command(subcommand)]
    command: Job,
}

#[derive(Subcommand)]
enum Job {
    /// Runs the car in real time and serves its XCP slave (Ctrl-C stops).
    Serve {
        /// `tcp:ADDRESS` (the A2L names tcp:127.0.0.1:5555) or `can:INTERFACE`.
        #[arg(long, default_value = "tcp:127.0.0.1:5555")]
        link: String,
        /// What the driver does: `practice` launches, stops, stands 20 s with the tractive
        /// system live, parks 30 s with it off, and again.
        #[arg(long, value_enum, default_value_t = DriveCycle::Practice)]
        cycle: DriveCycle,
        /// The team's secret (64 hex digits, as ccm/xcp-secret.key); without it calibration
        /// stays locked, as on an image built without one.
        #[arg(long)]
        secret_file: Option<PathBuf>,
    },
    /// Plays tools/xcp_scenarios.py (pyxcp) against the slave and checks what it saw;
    /// exits non-zero unless every check passed.
    Scenarios {
        /// `tcp:ADDRESS` (port 0: any) or `can:INTERFACE`.
        #[arg(long, default_value = "tcp:127.0.0.1:0")]
        link: String,
        /// A Python with pyxcp and pya2ldb.
        #[arg(long, default_value = "python3")]
        python: PathBuf,
        /// The scenario script (default: the `tools/xcp_scenarios.py` built into this binary).
        #[arg(long)]
        script: Option<PathBuf>,
        /// The A2L whose EPK must be the slave's (default: the `generated/aer.a2l` built in).
        #[arg(long)]
        a2l: Option<PathBuf>,
        /// The master connects through the Pi's XCP gateway at this address (XCP on TCP)
        /// while the slave serves the link.
        #[arg(long)]
        through: Option<std::net::SocketAddr>,
        /// Run the script in this network namespace (the pit's).
        #[arg(long)]
        netns: Option<String>,
    },
}

#[derive(Clone, Copy, ValueEnum)]
enum DriveCycle {
    Practice,
    Acceleration,
    Skidpad,
    Autocross,
}

impl From<DriveCycle> for Cycle {
    fn from(cycle: DriveCycle) -> Self {
        match cycle {
            DriveCycle::Practice => Cycle::Practice,
            DriveCycle::Acceleration => Cycle::Acceleration,
            DriveCycle::Skidpad => Cycle::Skidpad,
            DriveCycle::Autocross => Cycle::Autocross,
        }
    }
}

fn main() -> Result<()> {
    match Cli::parse().command {
        Job::Serve {
            link,
            cycle,
            secret_file,
        } => {
            let secret = secret_file.as_deref().map(serve::read_secret).transpose()?;
            let transport = masters::open(&link)?;
            let mut entropy = [0u8; 32];
            getrandom::fill(&mut entropy).map_err(|error| {
                anyhow::anyhow!("the operating system's random source: {error}")
            })?;
            eprintln!(
                "aer-car-node: the CCM's XCP slave, {}; calibration {}; one master at a time, \
                 idle sessions end after {} s",
                transport.describe,
                if secret.is_some() {
                    "unlockable"
                } else {
                    "locked (no secret)"
                },
                aer::calibration::xcp::IDLE_TIMEOUT_MS / 1_000,
            );
            serve::serve(&transport, cycle.into(), secret, &entropy, |_| true)?;
            Ok(())
        }
        Job::Scenarios {
            link,
            python,
            script,
            a2l,
            through,
            netns,
        } => {
            let mut link = link::open(&link)?;
            // Whatever is not given comes from the copies built into the binary.
            let built_in = tempfile::tempdir()?;
            let unpack = |given: Option<PathBuf>, name: &str, text: &str| match given {
                Some(path) => Ok::<_, std::io::Error>(path),
                None => {
                    let path = built_in.path().join(name);
                    std::fs::write(&path, text)?;
                    Ok(path)
                }
            };
            let script = scenarios::Script {
                python,
                path: unpack(script, "xcp_scenarios.py", scenarios::SCRIPT)?,
                a2l: unpack(a2l, "aer.a2l", scenarios::A2L)?,
                through,
                netns,
            };
            let outcome = scenarios::play(link.as_mut(), &script)?;
            let checks = checks::judge(&outcome);
            for check in &checks {
                println!("{check}");
            }
            let failed = checks::failed(&checks).len();
            if failed > 0 {
                bail!("{failed} of {} checks failed", checks.len());
            }
            println!("every one of {} checks passed", checks.len());
            Ok(())
        }
    }
}
