//! The car on the desk: the closed loop runs in real time (one model millisecond per
//! millisecond) and its CCM's XCP slave answers a calibration tool (CANape, INCA, pyxcp) over
//! the link, as on the car, so a tuner can try the A2L, the DAQ lists and the refusals before
//! the car exists.

use crate::link::Link;
use aer_car_model::chassis::Mode;
use aer_car_model::driver::Cycle;
use aer_car_model::faults::FaultPlan;
use aer_car_model::{ClosedLoop, ModelParams, NoTap, XcpCar};
use aer_ccm::calibration::store::RamFlash;
use aer_ccm::xcp::SECRET_LEN;
use aer_xcp::MAX_CTO;
use anyhow::{Context, Result, bail};
use std::path::Path;
use std::time::{Duration, Instant, SystemTime};

/// Reads the team's secret: 64 hex digits (the format of `ccm/xcp-secret.key`).
pub fn read_secret(path: &Path) -> Result<[u8; SECRET_LEN]> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("reading the XCP secret {}", path.display()))?;
    match aer_xcp::seed_key::parse_secret(&text) {
        Some(secret) => Ok(secret),
        None => bail!(
            "{}: the secret is {} hex digits, nothing else",
            path.display(),
            2 * SECRET_LEN
        ),
    }
}

/// Runs `cycle` in real time and serves the slave on `link` until `running` says stop (or
/// for ever). Returns the model milliseconds run.
pub fn serve(
    link: &mut dyn Link,
    cycle: Cycle,
    secret: Option<[u8; SECRET_LEN]>,
    mut running: impl FnMut(u32) -> bool,
) -> Result<u32> {
    let run = ClosedLoop::new(ModelParams::NOMINAL, Mode::Road, cycle, FaultPlan::NONE);
    let entropy = SystemTime::now()
        .duration_since(SystemTime::UNIX_EPOCH)
        .map_or(0, |t| t.as_nanos() as u64);
    let mut car = XcpCar::new(run, RamFlash::default(), secret, entropy);
    let started = Instant::now();
    let mut ms: u32 = 0;
    let mut malformed_reported = 0;
    while running(ms) {
        // Commands until this millisecond's step is due; a late step runs at once.
        let due = started + Duration::from_millis(u64::from(ms) + 1);
        loop {
            if let Some(packet) = link.receive()? {
                let mut reply = [0u8; MAX_CTO];
                if let Some(len) = car.command(&packet, &mut reply) {
                    link.send(reply.get(..len).unwrap_or_default());
                }
            }
            if Instant::now() >= due {
                break;
            }
        }
        car.step(&mut NoTap, &mut |packet| link.send(packet));
        ms = ms.wrapping_add(1);
        // Said at most once a second, not per packet: a babbling node must not flood the log.
        if ms % 1000 == 0 && link.malformed() != malformed_reported {
            malformed_reported = link.malformed();
            eprintln!("{malformed_reported} malformed XCP packets ignored so far");
        }
    }
    Ok(ms)
}
