//! The closed-loop car with the CCM's XCP slave: what a calibration tool talks to on the
//! desk. Sans-IO: command packets in, answers and DAQ packets out, whatever carries them (XCP
//! on TCP in the host's tests, CAN frames on the emulated Cortex-M7).
//!
//! Start-up loads the calibration from the flash as the firmware does (the newest good copy
//! of this schema, or the defaults); the control event fires after every control step (after
//! the telemetry packet of that step is packed), the sensor event after every millisecond.

use crate::closed_loop::{BusTap, ClosedLoop};
use aer::calibration::xcp::{EVENT_CONTROL, EVENT_SENSORS};
use aer_ccm::calibration::EPK;
use aer_ccm::calibration::store::{CalibrationStore, RamFlash, Startup};
use aer_ccm::constants::CONTROL_PERIOD_MS;
use aer_ccm::xcp::{SECRET_LEN, SeedKey, XcpNode};
use aer_xcp::{DaqReport, MAX_CTO, SessionEnd};

/// The car, its CCM and the CCM's XCP slave.
pub struct XcpCar {
    /// The closed loop (the CCM inside runs the live calibration).
    pub run: ClosedLoop,
    node: XcpNode<RamFlash>,
    startup: Startup,
}

impl XcpCar {
    /// Starts `run`'s CCM with the calibration start-up finds in `flash`, the team's `secret`
    /// (`None`: calibration stays locked) and `entropy` for the seeds (at least 32 bytes from
    /// a true random source: the operating system's; fewer keep calibration locked).
    pub fn new(
        mut run: ClosedLoop,
        mut flash: RamFlash,
        secret: Option<[u8; SECRET_LEN]>,
        entropy: &[u8],
    ) -> Self {
        let (store, loaded) = CalibrationStore::load(&mut flash, EPK);
        run.ccm.set_calibration(loaded.calibration, loaded.startup);
        Self {
            run,
            node: XcpNode::new(
                SeedKey::new(secret, Some(entropy), b"desk car"),
                store,
                flash,
            ),
            startup: loaded.startup,
        }
    }

    /// What start-up loaded.
    pub fn startup(&self) -> Startup {
        self.startup
    }

    /// The flash, to restart from (a power cycle keeps it) or to corrupt in a test.
    pub fn flash_mut(&mut self) -> &mut RamFlash {
        &mut self.node.flash
    }

    /// Whether a master has a session with the slave (CONNECT seen, not ended).
    pub fn is_connected(&self) -> bool {
        self.node.slave.is_connected()
    }

    /// The slave's counters.
    pub fn counters(&self) -> aer_xcp::Counters {
        self.node.slave.counters()
    }

    /// Handles one command packet; the answer (if any) goes into `reply`.
    pub fn command(&mut self, packet: &[u8], reply: &mut [u8; MAX_CTO]) -> Option<usize> {
        self.node.measurements = self.run.ccm.measurements();
        let vehicle = self.run.ccm.vehicle_state();
        let now_us = self.run.now_ms().wrapping_mul(1_000);
        let calibration = self.run.ccm.calibration_state_mut();
        self.node
            .command(calibration, vehicle, packet, now_us, reply)
    }

    /// Runs the slave's clock at the model's time: a session idle past the time-out ends
    /// (or, with DAQ running, is relocked); the event telling the master goes to `send`.
    pub fn poll(&mut self, send: &mut impl FnMut(&[u8]) -> bool) -> Option<SessionEnd> {
        let now_us = self.run.now_ms().wrapping_mul(1_000);
        let calibration = self.run.ccm.calibration_state_mut();
        self.node.poll(calibration, now_us, send)
    }

    /// The master's transport is gone (its TCP connection closed or broke): the session ends.
    pub fn transport_lost(&mut self) -> Option<SessionEnd> {
        let calibration = self.run.ccm.calibration_state_mut();
        self.node.transport_lost(calibration)
    }

    /// One model millisecond, then the sensor event and, after a control step, the control
    /// event: their DAQ packets go to `send` (false: the queue is full, counted as dropped).
    pub fn step(
        &mut self,
        tap: &mut impl BusTap,
        send: &mut impl FnMut(&[u8]) -> bool,
    ) -> DaqReport {
        self.run.step(tap);
        self.node.measurements = self.run.ccm.measurements();
        let now_ms = self.run.now_ms();
        let now_us = now_ms.wrapping_mul(1_000);
        let calibration = self.run.ccm.calibration_state_mut();
        let mut report = self.node.event(calibration, EVENT_SENSORS, now_us, send);
        if now_ms % CONTROL_PERIOD_MS == 0 {
            let calibration = self.run.ccm.calibration_state_mut();
            let control = self.node.event(calibration, EVENT_CONTROL, now_us, send);
            report.sent += control.sent;
            report.dropped += control.dropped;
        }
        report
    }
}
