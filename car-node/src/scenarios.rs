//! The calibration engineer's scenarios (`tools/xcp_scenarios.py`), played by pyxcp against
//! the CCM's slave in the closed-loop car: this side drives the car and answers the script.
//!
//! The two talk over the script's stdin and stdout, one JSON object per line: the script
//! writes a request (start_up, drive_until_moving, drive {ms}, restart, corrupt, result
//! {name, value}, done), the harness answers with exactly one line. While a request is
//! outstanding the harness serves no XCP commands, and the script sends none. What the
//! script saw is judged against the car afterwards ([`crate::checks`]).

use crate::expected;
use crate::link::Link;
use aer_car_model::chassis::Mode;
use aer_car_model::driver::Cycle;
use aer_car_model::faults::{Fault, FaultPlan, Injection};
use aer_car_model::{ClosedLoop, ModelParams, NoTap, XcpCar};
use aer_ccm::calibration::Calibration;
use aer_ccm::calibration::store::{RamFlash, Slot, Startup};
use aer_ccm::launch::LaunchState;
use aer_ccm::xcp::SECRET_LEN;
use aer_xcp::MAX_CTO;
use anyhow::{Context, Result, anyhow, bail, ensure};
use serde_json::{Value, json};
use std::collections::HashMap;
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc::{Receiver, TryRecvError, channel};

/// The secret the scenarios unlock with (the script gets it in its environment).
pub const SECRET: [u8; SECRET_LEN] = *b"the pyxcp test's secret (32 B)!!";

/// Model time a start-up may take.
const START_UP_LIMIT_MS: u32 = 60_000;
/// Model time the launch may take to reach 5 m/s.
const MOVING_LIMIT_MS: u32 = 20_000;

/// Where the script and its inputs are.
pub struct Script {
    /// A Python with pyxcp (and pya2ldb for the A2L's EPK).
    pub python: PathBuf,
    /// `tools/xcp_scenarios.py`.
    pub path: PathBuf,
    /// `generated/aer.a2l`.
    pub a2l: PathBuf,
    /// The master reaches the slave through an XCP gateway at this TCP address (the Pi's)
    /// rather than on the link itself.
    pub through: Option<std::net::SocketAddr>,
    /// The script runs in this network namespace (`ip netns exec`): the pit's, behind its
    /// radio.
    pub netns: Option<String>,
}

impl Script {
    /// What the script needs to reach the slave: the link's own transport, or the gateway's
    /// TCP, whose packets are the slave's CAN frames (padded to 8 bytes).
    fn env(&self, link: &dyn Link) -> Vec<(String, String)> {
        match self.through {
            None => link.script_env(),
            Some(gateway) => vec![
                ("AER_XCP_TRANSPORT".into(), "tcp".into()),
                ("AER_XCP_HOST".into(), gateway.ip().to_string()),
                ("AER_XCP_PORT".into(), gateway.port().to_string()),
                ("AER_XCP_PADDED".into(), "1".into()),
            ],
        }
    }

    /// The command that starts the script.
    fn command(&self) -> Command {
        let mut command = match &self.netns {
            None => Command::new(&self.python),
            Some(namespace) => {
                let mut command = Command::new("ip");
                command.args(["netns", "exec", namespace]).arg(&self.python);
                command
            }
        };
        command.arg(&self.path);
        command
    }
}

/// What the control events measured, by the telemetry packet's sequence number (one per
/// control step), and the torque of every launch-control step.
#[derive(Default)]
pub struct Recorded {
    /// The internals at each control step.
    pub by_sequence: HashMap<u16, aer::calibration::Internals>,
    /// Torque commanded while launch control was active, with the script's calibration.
    pub launch_torque: Vec<f32>,
}

/// Everything a run leaves for the checks.
pub struct Outcome {
    /// The script's results by name.
    pub results: HashMap<String, Value>,
    /// What the CCM measured.
    pub recorded: Recorded,
    /// The same run from ready-to-drive with the defaults, driven as far as the tuned one.
    pub twin_launch_torque: Vec<f32>,
}

/// A CCM and car at power-up with `flash`, parked with the tractive system off (the shutdown
/// circuit held open until `start_up`), after 100 ms (the CCM has heard the car).
pub fn power_up(flash: RamFlash) -> XcpCar {
    let parked = FaultPlan::NONE.with(Injection {
        fault: Fault::ShutdownOpen,
        from_ms: 0,
        until_ms: u32::MAX,
    });
    let run = ClosedLoop::new(
        ModelParams::NOMINAL,
        Mode::Road,
        Cycle::Acceleration,
        parked,
    );
    let mut car = XcpCar::new(run, flash, Some(SECRET), &[0x5E; 32]);
    for _ in 0..100 {
        car.step(&mut NoTap, &mut |_| true);
    }
    car
}

struct Harness<'l> {
    car: XcpCar,
    link: &'l mut dyn Link,
    script: Child,
    to_script: ChildStdin,
    from_script: Receiver<String>,
    results: HashMap<String, Value>,
    recorded: Recorded,
    /// The run at ready-to-drive with the defaults, to drive beside the tuned one.
    twin: Option<ClosedLoop>,
    driven_ms: u32,
}

/// Plays the scenarios over `link` and returns what happened (an error if the script or the
/// protocol broke; the judgement is [`crate::checks::judge`]'s).
pub fn play(link: &mut dyn Link, script: &Script) -> Result<Outcome> {
    let dir = tempfile::tempdir().context("a directory for the script's inputs")?;
    let expected_path = dir.path().join("expected.json");
    std::fs::write(
        &expected_path,
        expected::description(&script.a2l).to_string(),
    )
    .context("writing expected.json")?;
    let secret: String = SECRET.iter().map(|b| format!("{b:02x}")).collect();
    let mut child = script
        .command()
        .envs(script.env(link))
        .env("AER_XCP_SECRET", secret)
        .env("AER_XCP_EXPECTED", &expected_path)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .with_context(|| format!("starting {}", script.python.display()))?;
    let to_script = child.stdin.take().context("the script's stdin")?;
    let stdout = child.stdout.take().context("the script's stdout")?;
    let (lines, from_script) = channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines() {
            let Ok(line) = line else { break };
            if lines.send(line).is_err() {
                break;
            }
        }
    });
    let mut harness = Harness {
        car: power_up(RamFlash::default()),
        link,
        script: child,
        to_script,
        from_script,
        results: HashMap::new(),
        recorded: Recorded::default(),
        twin: None,
        driven_ms: 0,
    };
    let played = harness.run();
    if played.is_err() {
        // Whatever broke, the script must not outlive the run.
        let _ = harness.script.kill();
        let _ = harness.script.wait();
    }
    played?;
    let twin_launch_torque = harness.drive_twin()?;
    Ok(Outcome {
        results: harness.results,
        recorded: harness.recorded,
        twin_launch_torque,
    })
}

impl Harness<'_> {
    fn await_master(&mut self) -> Result<()> {
        let script = &mut self.script;
        self.link.await_master(&mut || match script.try_wait()? {
            Some(status) => bail!("the script ended ({status}) before connecting"),
            None => Ok(()),
        })
    }

    /// Answers every command the master has sent by now.
    fn serve(&mut self) -> Result<()> {
        if self.link.take_lost() {
            self.car.transport_lost();
        }
        while let Some(packet) = self.link.receive()? {
            let mut reply = [0u8; MAX_CTO];
            if let Some(len) = self.car.command(&packet, &mut reply) {
                // The master may be gone (after its DISCONNECT): nothing to deliver then.
                let _ = self.link.send(reply.get(..len).unwrap_or_default());
            }
        }
        Ok(())
    }

    /// One model millisecond: DAQ packets to the master, the control events recorded.
    fn step(&mut self) {
        let link = &mut *self.link;
        self.car.step(&mut NoTap, &mut |packet| link.send(packet));
        let now_ms = self.car.run.now_ms();
        if now_ms % 10 == 0 {
            let measured = self.car.run.ccm.measurements();
            let offset = expected::SEQUENCE_OFFSET;
            if let Some(&[low, high]) = measured.telemetry.get(offset..offset + 2) {
                let internals = self.car.run.ccm.internals();
                self.recorded
                    .by_sequence
                    .insert(u16::from_le_bytes([low, high]), internals);
            }
            let torque = self.car.run.last_outputs().torque;
            if torque.launch == LaunchState::Active {
                self.recorded.launch_torque.push(torque.torque_nm);
            }
        }
        if self.twin.is_some() {
            self.driven_ms += 1;
        }
    }

    fn answer(&mut self, answer: Value) -> Result<()> {
        writeln!(self.to_script, "{answer}").context("answering the script")?;
        self.to_script.flush().context("answering the script")
    }

    fn now(&self) -> Value {
        json!({"ok": true, "now_us": self.car.run.now_ms() * 1_000})
    }

    fn restart(&mut self, corrupt: bool) -> Result<()> {
        self.link.drop_master();
        let mut flash = self.car.flash_mut().clone();
        if corrupt {
            for slot in [Slot::A, Slot::B] {
                if let Some(byte) = flash.slot_mut(slot).get_mut(40) {
                    *byte ^= 0x01;
                }
            }
        }
        self.car = power_up(flash);
        let startup = self.car.startup().to_string();
        self.answer(json!({"ok": true, "startup": startup}))?;
        self.await_master()
    }

    /// Handles one request of the script; false at the end.
    fn request(&mut self, line: &str) -> Result<bool> {
        let request: Value =
            serde_json::from_str(line).with_context(|| format!("the script wrote {line:?}"))?;
        match request["cmd"].as_str() {
            Some("start_up") => {
                self.car.run.retune(ModelParams::NOMINAL, FaultPlan::NONE);
                while !self.car.run.car.driver.driving() {
                    ensure!(
                        self.car.run.now_ms() < START_UP_LIMIT_MS,
                        "the car did not start within {START_UP_LIMIT_MS} ms"
                    );
                    self.step();
                }
                let mut twin = self.car.run.clone();
                twin.ccm
                    .set_calibration(Calibration::DEFAULT, Startup::NoneSaved);
                self.twin = Some(twin);
                self.answer(self.now())?;
            }
            Some("drive_until_moving") => {
                while self.car.run.car.chassis.speed_m_s < 5.0 {
                    ensure!(
                        self.driven_ms < MOVING_LIMIT_MS,
                        "the car was not moving within {MOVING_LIMIT_MS} ms"
                    );
                    self.step();
                }
                self.answer(self.now())?;
            }
            Some("drive") => {
                let ms = request["ms"]
                    .as_u64()
                    .ok_or_else(|| anyhow!("drive without ms: {line}"))?;
                for _ in 0..ms.min(u64::from(MOVING_LIMIT_MS)) {
                    self.step();
                }
                self.answer(self.now())?;
            }
            Some("restart") => self.restart(false)?,
            Some("corrupt") => self.restart(true)?,
            Some("result") => {
                let name = request["name"]
                    .as_str()
                    .ok_or_else(|| anyhow!("result without a name: {line}"))?
                    .to_owned();
                self.results.insert(name, request["value"].clone());
                self.answer(json!({"ok": true}))?;
            }
            Some("done") => {
                self.answer(json!({"ok": true}))?;
                return Ok(false);
            }
            other => bail!("unknown request {other:?}"),
        }
        Ok(true)
    }

    fn run(&mut self) -> Result<()> {
        self.await_master()?;
        loop {
            self.serve()?;
            match self.from_script.try_recv() {
                Ok(line) => {
                    if !self.request(&line)? {
                        break;
                    }
                }
                Err(TryRecvError::Empty) => {}
                Err(TryRecvError::Disconnected) => {
                    let status = self.script.wait()?;
                    bail!("the script ended ({status}) before `done`");
                }
            }
        }
        let status = self.script.wait()?;
        ensure!(status.success(), "the script failed: {status}");
        Ok(())
    }

    /// The defaults' run, from the same ready-to-drive moment, for as long as the tuned one
    /// drove: launch control's torque at each control step.
    fn drive_twin(&mut self) -> Result<Vec<f32>> {
        let mut twin = self
            .twin
            .take()
            .ok_or_else(|| anyhow!("the script never asked for start_up"))?;
        let mut torque = Vec::new();
        for _ in 0..self.driven_ms {
            twin.step(&mut NoTap);
            let outputs = twin.last_outputs().torque;
            if twin.now_ms() % 10 == 0 && outputs.launch == LaunchState::Active {
                torque.push(outputs.torque_nm);
            }
        }
        Ok(torque)
    }
}

/// The repository's script and A2L, for a checkout (`root` holds `tools/` and `generated/`).
/// `tools/xcp_scenarios.py` as this binary was built with: `aer-car-node scenarios` plays it
/// when no `--script` is given, so the binary needs no checkout beside it.
pub const SCRIPT: &str = include_str!("../../tools/xcp_scenarios.py");
/// `generated/aer.a2l` as this binary was built with (the EPK the slave reports).
pub const A2L: &str = include_str!("../../generated/aer.a2l");

pub fn in_checkout(root: &Path, python: PathBuf) -> Script {
    Script {
        python,
        path: root.join("tools/xcp_scenarios.py"),
        a2l: root.join("generated/aer.a2l"),
        through: None,
        netns: None,
    }
}
