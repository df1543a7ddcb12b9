//! A CCM session in closed loop on the car model: start-up, precharge, ready-to-drive, an
//! acceleration run with launch control and the 80 kW limit, braking, and injected faults
//! (the BMS falling silent, the pedal converter lost). Every frame on both buses, the
//! telemetry packets through ISO-TP included, is folded into a digest; state and fault
//! changes are printed.

use crate::Digest;
use aer_car_model::chassis::Mode;
use aer_car_model::driver::Cycle;
use aer_car_model::faults::{Fault, FaultPlan, Injection};
use aer_car_model::{BusTap, ClosedLoop, ModelParams, NoTap};
use aer_ccm::Ccm;
use aer_flexcan::CanFrame;
use core::fmt::Write;
use embedded_can::Frame;

/// Session length (ms).
const DURATION_MS: u32 = 25_000;

/// The faults of the session: the BMS silent for 0.5 s during the run, the pedal converter
/// lost for 0.2 s after it.
fn plan() -> FaultPlan {
    FaultPlan::NONE
        .with(Injection {
            fault: Fault::BmsSilent,
            from_ms: 14_000,
            until_ms: 14_500,
        })
        .with(Injection {
            fault: Fault::PedalConverterLost,
            from_ms: 19_000,
            until_ms: 19_200,
        })
}

/// Folds every frame into a digest per bus.
#[derive(Default)]
struct Frames {
    buses: [Digest; 2],
    count: u32,
}

impl BusTap for Frames {
    fn frame(&mut self, at_us: u64, bus: usize, frame: &CanFrame) {
        if let Some(digest) = self.buses.get_mut(bus) {
            digest.bytes(&at_us.to_le_bytes());
            digest.bytes(frame.data());
        }
        self.count += 1;
    }
}

/// A CCM driving on full throttle, `after_ms` after the start of its acceleration run, and
/// the time of its last control step (ms).
pub fn ccm_driving(after_ms: u32) -> (Ccm, u32) {
    let mut run = ClosedLoop::new(
        ModelParams::NOMINAL,
        Mode::Road,
        Cycle::Acceleration,
        FaultPlan::NONE,
    );
    run.start_up(20_000);
    let end = (run.now_ms() + after_ms) / 10 * 10;
    run.run_until(end, &mut NoTap);
    (run.ccm, end)
}

/// Runs the session and prints state and fault changes and digests.
pub fn session(out: &mut impl Write) -> core::fmt::Result {
    let mut run = ClosedLoop::new(
        ModelParams::NOMINAL,
        Mode::Road,
        Cycle::Acceleration,
        plan(),
    );
    let mut frames = Frames::default();
    let mut torque_digest = Digest::default();
    let mut last = None;
    while run.now_ms() < DURATION_MS {
        run.step(&mut frames);
        let t = run.now_ms();
        if t % 10 != 0 {
            continue;
        }
        let outputs = run.last_outputs();
        torque_digest.bytes(&outputs.torque.torque_nm.to_le_bytes());
        let now = (outputs.vehicle.state, outputs.faults.bits());
        if last != Some(now) {
            last = Some(now);
            writeln!(
                out,
                "ccm t={t} {:?} faults={:#06x} torque={:.3} launch={:?} speed={:.3} power={:.1}",
                outputs.vehicle.state,
                outputs.faults.bits(),
                outputs.torque.torque_nm,
                outputs.torque.launch,
                run.car.chassis.speed_m_s,
                run.car.power_w
            )?;
        }
    }
    let counters = run.ccm.link().counters();
    let stats = run.rules.stats();
    writeln!(
        out,
        "ccm end distance={:.3} soc={:.5} torque-digest={:08x} can1-digest={:08x} can2-digest={:08x} frames={} telemetry sent={} superseded={} failed={} worst-100ms-w={:.1} violations={}",
        run.car.chassis.distance_m,
        run.car.pack.soc,
        torque_digest.value(),
        frames.buses[0].value(),
        frames.buses[1].value(),
        frames.count,
        counters.sent,
        counters.superseded,
        counters.failed,
        stats.worst_100ms_w,
        run.rules.violations()
    )
}
