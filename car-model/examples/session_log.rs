//! Records a session of the closed-loop car model as a candump log, the file the Pi's demo
//! replays and the dashboard's screenshots show: `cargo run -p aer-car-model --example
//! session_log -- raspi/data/session.log` (what `cargo xtask session-log` runs). Everything on the
//! wire comes from the project's own code: the CCM's control logic, its generated telemetry
//! packer and ISO-TP sender, the PCC's state machine; the Pi's flow control from the ISO-TP
//! receiver; the other nodes' frames from the generated encoders, at their DBC cycle times.
//! The car is the comp car (the DTI HV-550 inverter). The model checks the rules on every
//! millisecond; a session that breaks one is refused.

use aer_car_model::chassis::Mode;
use aer_car_model::driver::Cycle;
use aer_car_model::faults::FaultPlan;
use aer_car_model::{BusTap, ClosedLoop, ModelParams};
use aer_flexcan::CanFrame;
use aer_host::formats::candump::LoggedFrame;
use embedded_can::Frame;
use std::fmt::Write as _;
use std::path::Path;

/// Session start (2026-11-21 12:00:00 UTC) and length.
const START_US: u64 = 1_795_348_800_000_000;
const DURATION_MS: u32 = 45_000;
/// Bus names as the Pi names them: can0 = CAN1 (BMS, PCC, Pi), can1 = CAN2 (inverter).
const BUSES: [&str; 2] = ["can0", "can1"];

/// Collects candump lines with their times.
#[derive(Default)]
struct Log {
    lines: Vec<(u64, String)>,
}

impl BusTap for Log {
    fn frame(&mut self, at_us: u64, bus: usize, frame: &CanFrame) {
        let Some(name) = BUSES.get(bus) else {
            return;
        };
        let ts = START_US + at_us;
        let logged = u8::try_from(bus)
            .ok()
            .and_then(|index| LoggedFrame::new(ts, index, frame.id(), frame.data()));
        if let Some(logged) = logged {
            self.lines.push((ts, logged.to_line(name)));
        }
    }
}

fn main() {
    let Some(path) = std::env::args_os().nth(1) else {
        eprintln!("usage: session_log <candump log to write>");
        std::process::exit(2);
    };
    let path = Path::new(&path);
    match write(path) {
        Ok(frames) => println!("{}: {frames} frames", path.display()),
        Err(error) => {
            eprintln!("{error}");
            std::process::exit(1);
        }
    }
}

/// Writes the session to `path`; returns the number of frames.
fn write(path: &Path) -> Result<usize, String> {
    // Start-up (precharge, ready-to-drive), then autocross: straights into the 80 kW limit,
    // braking, corners, now and then a late foot change that trips the APPS/brake check.
    let params = ModelParams {
        efficiency: 0.92,
        efficiency_droop: 0.03,
        measurement_lag_ms: 10.0,
        bms_delay_periods: 1,
        frame_jitter_ms: 1,
        seed: 7,
        ..ModelParams::NOMINAL
    };
    let mut run = ClosedLoop::new(params, Mode::Road, Cycle::Autocross, FaultPlan::NONE);
    let mut log = Log::default();
    run.run_until(DURATION_MS, &mut log);
    if let Some(violation) = run.rules.first_violation() {
        return Err(format!(
            "the session broke a rule ({} times; first {violation:?})",
            run.rules.violations()
        ));
    }
    // A telemetry packet's frames stretch over a few milliseconds: order the log by time, as
    // candump writes it (stable, so frames of one sender keep their order).
    log.lines.sort_by_key(|(ts, _)| *ts);
    let mut text = String::new();
    for (_, line) in &log.lines {
        let _ = writeln!(text, "{line}");
    }
    std::fs::write(path, text).map_err(|error| format!("writing {}: {error}", path.display()))?;
    Ok(log.lines.len())
}
