//! The judgement: what pyxcp saw against what the car did. Each check has a name a report
//! line carries; a run passes when every check does.

use crate::scenarios::Outcome;
use aer::calibration::PARAMETERS;
use aer::calibration::xcp::EPK;
use aer_ccm::calibration::Calibration;
use aer_xcp::protocol::err;
use serde_json::Value;
use std::fmt;

/// XCP error codes the refusals must carry, as JSON numbers.
const ERR_OUT_OF_RANGE: u64 = err::OUT_OF_RANGE as u64;
const ERR_WRITE_PROTECTED: u64 = err::WRITE_PROTECTED as u64;
const ERR_ACCESS_LOCKED: u64 = err::ACCESS_LOCKED as u64;
/// DAQ samples the 300 ms drive and the launch must deliver at least.
const MIN_DAQ_SAMPLES: usize = 30;
/// How much less torque the written launch slip target must command, on average, than the
/// defaults (Nm): the 0.03 target is well below the default curve.
const LAUNCH_TORQUE_MARGIN_NM: f32 = 5.0;

/// One named check's verdict.
pub struct Check {
    /// What it checks.
    pub name: &'static str,
    /// `None`: passed; otherwise what was wrong.
    pub failure: Option<String>,
    /// Figures worth reporting either way.
    pub detail: Option<String>,
}

/// The checks that failed, each as its line.
pub fn failed(checks: &[Check]) -> Vec<String> {
    checks
        .iter()
        .filter(|c| c.failure.is_some())
        .map(ToString::to_string)
        .collect()
}

impl fmt::Display for Check {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.failure {
            None => write!(f, "ok: {}", self.name)?,
            Some(why) => write!(f, "FAILED: {} ({why})", self.name)?,
        }
        match &self.detail {
            Some(detail) => write!(f, " [{detail}]"),
            None => Ok(()),
        }
    }
}

struct Judge<'o> {
    outcome: &'o Outcome,
    checks: Vec<Check>,
}

impl Judge<'_> {
    fn check(&mut self, name: &'static str, verdict: Result<(), String>) {
        self.checks.push(Check {
            name,
            failure: verdict.err(),
            detail: None,
        });
    }

    /// Adds figures to the last check.
    fn detail(&mut self, detail: String) {
        if let Some(check) = self.checks.last_mut() {
            check.detail = Some(detail);
        }
    }

    fn result(&self, name: &str) -> Result<&Value, String> {
        self.outcome
            .results
            .get(name)
            .ok_or_else(|| format!("the script reported no {name}"))
    }
}

fn equal<T: PartialEq + fmt::Debug>(what: &str, got: T, want: T) -> Result<(), String> {
    if got == want {
        Ok(())
    } else {
        Err(format!("{what}: got {got:?}, want {want:?}"))
    }
}

fn floats(value: &Value) -> Result<Vec<f64>, String> {
    value
        .as_array()
        .ok_or_else(|| format!("{value} is not a list"))?
        .iter()
        .map(|v| v.as_f64().ok_or_else(|| format!("{v} is not a number")))
        .collect()
}

fn f32s(values: &[f32]) -> Vec<f64> {
    values.iter().map(|&v| f64::from(v)).collect()
}

fn mean(values: &[f32]) -> f32 {
    values.iter().sum::<f32>() / values.len().max(1) as f32
}

/// Every check of a run, in the scenarios' order.
pub fn judge(outcome: &Outcome) -> Vec<Check> {
    let mut judge = Judge {
        outcome,
        checks: Vec::new(),
    };
    let defaults = Calibration::DEFAULT;
    let code = |value: &Value| value["code"].as_u64();

    let epk = judge
        .result("epk")
        .and_then(|v| equal("EPK", v.as_str(), Some(EPK)));
    judge.check("GET_ID answers the schema's EPK", epk);
    let a2l = judge
        .result("a2l_epk")
        .and_then(|v| equal("EPK", v.as_str(), Some(EPK)));
    judge.check("the A2L's EPK is the slave's", a2l);

    let read = judge.result("defaults").and_then(|read| {
        let page = defaults.to_page();
        PARAMETERS.iter().try_for_each(|p| {
            let want: Vec<f64> = (0..p.count).filter_map(|i| p.value(&page, i)).collect();
            equal(p.name, floats(&read[p.name])?, want)
        })
    });
    judge.check("every parameter reads its default", read);

    let locked = judge
        .result("locked_write")
        .and_then(|v| equal("error", v.as_u64(), Some(ERR_ACCESS_LOCKED)));
    judge.check(
        "a write before UNLOCK is refused (ERR_ACCESS_LOCKED)",
        locked,
    );
    let unlocked = judge
        .result("unlocked")
        .and_then(|v| equal("unlocked", v.as_bool(), Some(true)));
    judge.check(
        "GET_SEED/UNLOCK with the team's key unlocks calibration",
        unlocked,
    );

    let out_of_range = judge.result("out_of_range").and_then(|v| {
        equal("error", code(v), Some(ERR_OUT_OF_RANGE))?;
        equal(
            "launch_kp after",
            v["after"].as_f64(),
            Some(f64::from(defaults.launch_kp)),
        )
    });
    judge.check(
        "an out-of-range write is refused (ERR_OUT_OF_RANGE), the value kept",
        out_of_range,
    );

    let checksum = judge
        .result("checksum")
        .and_then(|v| equal("CRC-16-CCITT", &v["slave"], &v["computed"]));
    judge.check(
        "BUILD_CHECKSUM equals the CRC of the uploaded page",
        checksum,
    );

    let target = judge
        .result("launch_target")
        .and_then(|v| equal("launch_slip_target", floats(v)?, f32s(&[0.03; 4])));
    judge.check("a curve written as one block reads back", target);
    let stored = judge
        .result("stored")
        .and_then(|v| equal("stored", v.as_bool(), Some(true)));
    judge.check(
        "STORE_CAL_REQ saves while parked with the tractive system off",
        stored,
    );

    let tractive = judge
        .result("tractive_off_write")
        .and_then(|v| equal("error", v.as_u64(), Some(ERR_WRITE_PROTECTED)));
    judge.check(
        "a sensor calibration write with the tractive system on is refused (ERR_WRITE_PROTECTED)",
        tractive,
    );
    let standstill = judge.result("moving_standstill_write").and_then(|v| {
        equal("error", code(v), Some(ERR_WRITE_PROTECTED))?;
        equal(
            "launch_kp after",
            v["after"].as_f64(),
            Some(f64::from(defaults.launch_kp)),
        )
    });
    judge.check(
        "a standstill-only write while moving is refused, the value kept",
        standstill,
    );
    let driving = judge.result("moving_driving_write").and_then(|v| {
        equal("error", code(v), None)?;
        equal("traction_kp after", v["after"].as_f64(), Some(650.0))
    });
    judge.check("a while-driving parameter changes while moving", driving);
    let page_switch = judge
        .result("moving_page_switch")
        .and_then(|v| equal("error", v.as_u64(), Some(ERR_WRITE_PROTECTED)));
    judge.check("SET_CAL_PAGE while moving is refused", page_switch);

    let daq = judge
        .result("daq")
        .and_then(|daq| daq_matches(outcome, daq));
    judge.check(
        "the control-rate DAQ list delivers what the CCM computed at every step, none missing",
        daq,
    );
    if let Ok(Some(samples)) = judge.result("daq").map(Value::as_array) {
        judge.detail(format!("{} samples", samples.len()));
    }
    let (tuned, default) = (
        mean(&outcome.recorded.launch_torque),
        mean(&outcome.twin_launch_torque),
    );
    let launch = if tuned < default - LAUNCH_TORQUE_MARGIN_NM {
        Ok(())
    } else {
        Err(format!(
            "mean launch torque {tuned:.1} Nm with the written target, {default:.1} Nm with the defaults"
        ))
    };
    judge.check(
        "the written launch slip target takes torque away at launch",
        launch,
    );
    judge.detail(format!(
        "mean launch torque {tuned:.1} Nm, {default:.1} Nm with the defaults"
    ));

    let restart = judge.result("restart_startup").and_then(|v| {
        equal(
            "start-up",
            v.as_str(),
            Some("calibration: saved copy A (generation 1)"),
        )
    });
    judge.check("after a power cycle start-up loads the saved copy", restart);
    let restored = judge.result("restored").and_then(|v| {
        equal(
            "launch_slip_target",
            floats(&v["launch_slip_target"])?,
            f32s(&[0.03; 4]),
        )?;
        equal(
            "traction_kp (not saved)",
            v["traction_kp"].as_f64(),
            Some(f64::from(defaults.traction_kp)),
        )
    });
    judge.check(
        "the saved values come back, the unsaved one does not",
        restored,
    );
    let reverted = judge.result("reverted").and_then(|v| {
        equal(
            "launch_slip_target",
            floats(v)?,
            f32s(&defaults.launch_slip_target),
        )
    });
    judge.check(
        "COPY_CAL_PAGE reference -> working restores the defaults",
        reverted,
    );
    let corrupt = judge.result("corrupt_startup").and_then(|v| {
        equal(
            "start-up",
            v.as_str(),
            Some("calibration: the schema's defaults (saved copy corrupt)"),
        )
    });
    judge.check("both copies corrupt: start-up says so", corrupt);
    let after_corrupt = judge.result("after_corrupt").and_then(|v| {
        equal(
            "launch_slip_target",
            floats(v)?,
            f32s(&defaults.launch_slip_target),
        )
    });
    judge.check(
        "both copies corrupt: the defaults are loaded",
        after_corrupt,
    );
    judge.checks
}

/// Every DAQ sample equals what the CCM measured at the control step its telemetry sequence
/// number names, consecutive steps, enough of them, and launch control ran on the written
/// target.
fn daq_matches(outcome: &Outcome, daq: &Value) -> Result<(), String> {
    let samples = daq.as_array().ok_or("the DAQ samples are not a list")?;
    if samples.len() < MIN_DAQ_SAMPLES {
        return Err(format!("{} DAQ samples", samples.len()));
    }
    let mut previous: Option<u64> = None;
    for sample in samples {
        let sequence = sample["sequence"]
            .as_u64()
            .ok_or("a sample without sequence")?;
        let internals = u16::try_from(sequence)
            .ok()
            .and_then(|s| outcome.recorded.by_sequence.get(&s))
            .ok_or_else(|| format!("no control step sent telemetry packet {sequence}"))?;
        equal(
            "launch_slip_target",
            sample["launch_slip_target"].as_f64(),
            Some(f64::from(internals.launch_slip_target)),
        )?;
        equal(
            "torque_command_nm",
            sample["torque_command_nm"].as_f64(),
            Some(f64::from(internals.torque_command_nm)),
        )?;
        if let Some(previous) = previous {
            equal("sequence", sequence, previous + 1)?;
        }
        previous = Some(sequence);
    }
    let aimed = samples
        .iter()
        .any(|s| s["launch_slip_target"].as_f64() == Some(f64::from(0.03f32)));
    if aimed {
        Ok(())
    } else {
        Err("launch control never aimed at the written target".into())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenarios::Recorded;

    /// A script that reported nothing passes nothing: every check names what was missing.
    #[test]
    fn a_run_without_results_fails_every_check() {
        let outcome = Outcome {
            results: Default::default(),
            recorded: Recorded::default(),
            twin_launch_torque: Vec::new(),
        };
        let checks = judge(&outcome);
        assert!(checks.len() >= 20);
        for check in &checks {
            assert!(check.failure.is_some(), "{check}");
        }
    }
}
