//! The CCM in the loop: the car model feeds it samples, wheel pulses and frames through the
//! same `Ccm` API the firmware uses, applies its commands, and the rules watch every
//! millisecond. Every frame on either bus can be tapped (the demo session's log).

use crate::car::Car;
use crate::chassis::Mode;
use crate::driver::Cycle;
use crate::faults::{Fault, FaultPlan};
use crate::nodes::{CAN1, CAN2};
use crate::params::{ModelParams, ccm};
use crate::rules::Rules;
use aer::can::PccStatus;
use aer::telemetry::Telemetry;
use aer_ccm::calibration::Calibration;
use aer_ccm::constants::{CONTROL_PERIOD_MS, TELEMETRY_PERIOD_MS};
use aer_ccm::own_frames::OwnFrames;
use aer_ccm::stop::StopFrames;
use aer_ccm::{BusHealth, Ccm, ControlOutputs, DriverCounters, DriverInputs, OutFrame};
use aer_flexcan::CanFrame;
use aer_isotp::{Config, Received, Receiver};
use embedded_can::{ExtendedId, Frame, Id, StandardId};

/// Sees every frame put on a bus.
pub trait BusTap {
    /// `frame` went out on `bus` (0 = CAN1, 1 = CAN2) at `at_us` since the start.
    fn frame(&mut self, at_us: u64, bus: usize, frame: &CanFrame);
}

/// A tap that looks at nothing.
#[derive(Debug, Clone, Copy, Default)]
pub struct NoTap;

impl BusTap for NoTap {
    fn frame(&mut self, _: u64, _: usize, _: &CanFrame) {}
}

/// Microseconds one ISO-TP frame takes on the bus in the model.
const FRAME_US: u64 = 250;

/// The CCM, the car and the rules, one millisecond at a time.
#[derive(Debug, Clone)]
pub struct ClosedLoop {
    /// The CCM under test.
    pub ccm: Ccm,
    /// The car around it.
    pub car: Car,
    /// The rules, checked throughout.
    pub rules: Rules,
    pi: Receiver<128>,
    now_ms: u32,
    last: ControlOutputs,
    bus_off_events: [u32; 2],
    was_off: [bool; 2],
    /// What a panic sends: the firmware's published stop frames.
    stop: StopFrames,
    /// The CCM is down (a panic or a hang) and runs again at this time.
    down_until_ms: Option<u32>,
}

impl ClosedLoop {
    /// A car at rest with its tractive system off, a CCM at reset, a driver who will start
    /// the car and drive `cycle`, and the faults in `plan`.
    pub fn new(params: ModelParams, mode: Mode, cycle: Cycle, plan: FaultPlan) -> Self {
        Self {
            ccm: Ccm::with_limits(Calibration::DEFAULT, params.inverter, params.limits),
            car: Car::new(params, mode, cycle, plan),
            rules: Rules::new(params.frame_jitter_ms),
            pi: Receiver::new(Config::CAR),
            now_ms: 0,
            last: ControlOutputs::RESET,
            bus_off_events: [0; 2],
            was_off: [false; 2],
            stop: StopFrames::new(),
            down_until_ms: None,
        }
    }

    /// Continues from the current state with other `params` and the faults in `plan` (for
    /// runs that share a start-up: the precharge alone takes 9 s).
    pub fn retune(&mut self, params: ModelParams, plan: FaultPlan) {
        self.car.retune(params, plan);
        self.rules = self.rules.restart(params.frame_jitter_ms);
    }

    /// Runs until the driver is on the drive cycle (start-up done), at most `limit_ms`;
    /// true if it got there.
    pub fn start_up(&mut self, limit_ms: u32) -> bool {
        self.run_until_state(limit_ms, &mut NoTap, |run| run.car.driver.driving())
    }

    /// Time since the start (ms).
    pub fn now_ms(&self) -> u32 {
        self.now_ms
    }

    /// The last control step's outputs.
    pub fn last_outputs(&self) -> ControlOutputs {
        self.last
    }

    /// Runs until `end_ms`.
    pub fn run_until(&mut self, end_ms: u32, tap: &mut impl BusTap) {
        while self.now_ms < end_ms {
            self.step(tap);
        }
    }

    /// Runs until `done` says so or `limit_ms` passes; true if `done` said so.
    pub fn run_until_state(
        &mut self,
        limit_ms: u32,
        tap: &mut impl BusTap,
        done: impl Fn(&Self) -> bool,
    ) -> bool {
        while self.now_ms < limit_ms {
            self.step(tap);
            if done(self) {
                return true;
            }
        }
        false
    }

    /// One millisecond.
    pub fn step(&mut self, tap: &mut impl BusTap) {
        self.now_ms += 1;
        let now = self.now_ms;
        let now_us = u64::from(now) * 1_000;
        self.car.advance(now, self.last.vehicle.state);
        if self.ccm_down(now, tap) {
            // The CCM sends nothing and hears nothing; the car and its nodes go on.
            self.car
                .node_frames(now, |bus, frame| tap.frame(now_us, bus, frame));
            let inverter_nm = self.car.inverter.effective_command(now);
            self.rules.millisecond(now, &self.car, inverter_nm);
            return;
        }

        let ccm = &mut self.ccm;
        self.car
            .wheel_pulses(now, |wheel, at_us| ccm.wheel_pulse(wheel, at_us));
        if let Some(sample) = self.car.sample(now) {
            self.ccm.sample(&sample, now);
        }

        let off = [self.bus_off(0), self.bus_off(1)];
        let ccm = &mut self.ccm;
        let rules = &mut self.rules;
        self.car.node_frames(now, |bus, frame| {
            tap.frame(now_us, bus, frame);
            if off.get(bus).copied().unwrap_or(true) {
                return;
            }
            ccm.on_frame(frame, now);
            if is_pcc_status(frame) {
                if let Ok(status) = PccStatus::decode(frame.data()) {
                    rules.pcc_status(status.pcc_state, now);
                }
            }
        });

        // The rules see the car as it is now, before the CCM acts on it.
        let inverter_nm = self.car.inverter.effective_command(now);
        self.rules.millisecond(now, &self.car, inverter_nm);
        if now % CONTROL_PERIOD_MS == 0 {
            self.control(now, tap);
        }
    }

    /// True while the CCM is down: a panic begins (its handler sends the stop frames the
    /// control task last published, then resets at once) or a hang begins (nothing is sent
    /// until the watchdog resets it); a CCM whose reset is over starts again, cold.
    fn ccm_down(&mut self, now: u32, tap: &mut impl BusTap) -> bool {
        let starts = |fault: Fault| {
            self.car
                .plan
                .injections()
                .any(|injection| injection.fault == fault && injection.from_ms == now)
        };
        if self.down_until_ms.is_none() {
            if starts(Fault::CcmPanic) {
                let now_us = u64::from(now) * 1_000;
                for out in self.stop.latest().iter() {
                    if let Some(frame) = can_frame(out)
                        && !self.was_off[1]
                    {
                        tap.frame(now_us, CAN2, &frame);
                        self.car.receive(&frame, now);
                    }
                }
                self.down_until_ms = Some(now + ccm::RESET_TO_RUNNING_MS);
            } else if starts(Fault::CcmHang) {
                self.down_until_ms = Some(now + ccm::WATCHDOG_MS + ccm::RESET_TO_RUNNING_MS);
            }
        }
        match self.down_until_ms {
            Some(until) if now < until => true,
            Some(_) => {
                let params = self.car.params;
                self.ccm = Ccm::with_limits(Calibration::DEFAULT, params.inverter, params.limits);
                self.last = ControlOutputs::RESET;
                self.down_until_ms = None;
                false
            }
            None => false,
        }
    }

    /// True while the CCM is down after a panic or a hang.
    pub fn ccm_is_down(&self) -> bool {
        self.down_until_ms.is_some()
    }

    fn bus_off(&mut self, bus: usize) -> bool {
        let off = self.car.plan.is_active(self.now_ms, Fault::BusOff(bus));
        if let (Some(was), Some(events)) =
            (self.was_off.get_mut(bus), self.bus_off_events.get_mut(bus))
        {
            if off && !*was {
                *events += 1;
            }
            *was = off;
        }
        off
    }

    fn control(&mut self, now: u32, tap: &mut impl BusTap) {
        let now_us = u64::from(now) * 1_000;
        let health = |bus: usize| BusHealth {
            error_passive: false,
            bus_off: self.was_off.get(bus).copied().unwrap_or(false),
            bus_off_events: self.bus_off_events.get(bus).copied().unwrap_or(0),
        };
        self.ccm.set_driver_counters(DriverCounters {
            buses: [health(0), health(1)],
            ..DriverCounters::default()
        });
        let command = self.car.command;
        self.last = self.ccm.control(
            DriverInputs {
                ready_to_move: command.ready_to_move,
                launch: command.launch,
            },
            now,
            now.wrapping_mul(1_000),
        );
        self.rules.control(now, &self.last);

        // The firmware's own schedule (`Control::due`), on the model's clock.
        let due = self.ccm.due(now / CONTROL_PERIOD_MS);
        if let Ok(frames) = self.ccm.stop_frames() {
            self.stop.publish(&frames);
        }
        if let Some(Ok(frames)) = due.inverter {
            for out in frames.iter() {
                let Some(frame) = can_frame(out) else {
                    continue;
                };
                if !self.was_off[1] {
                    tap.frame(now_us + 100, CAN2, &frame);
                    self.car.receive(&frame, now);
                }
            }
        }
        // The CCM's own messages, as the firmware sends them (`OwnFrames`), on the model's buses.
        let calibration = due
            .calibration
            .then(|| self.ccm.calibration_state().status());
        for (index, own) in OwnFrames::of(&due, calibration).iter().enumerate() {
            let Some(frame) = can_frame(&own.frame) else {
                continue;
            };
            // 10 us apart, in sending order.
            let at_us = now_us + 150 + 10 * index as u64;
            for (bus, on) in [(CAN1, own.buses.vehicle), (CAN2, own.buses.inverter)] {
                if on && !self.was_off.get(bus).copied().unwrap_or(true) {
                    tap.frame(at_us, bus, &frame);
                }
            }
        }
        if now % TELEMETRY_PERIOD_MS == 0 {
            self.telemetry(now, tap);
        }
    }

    /// The telemetry packet over ISO-TP to the Pi's receiver, which answers with flow
    /// control, one frame every 250 us.
    fn telemetry(&mut self, now: u32, tap: &mut impl BusTap) {
        self.ccm.send_telemetry(now.wrapping_mul(1_000));
        if self.was_off[0] {
            return;
        }
        let mut at_us = u64::from(now) * 1_000 + 200;
        let clock = |at_us: u64| (at_us & u64::from(u32::MAX)) as u32;
        while let Some(out) = self.ccm.link().poll(clock(at_us)) {
            self.ccm.link().sent(clock(at_us));
            if let Some(frame) = standard_frame(u32::from(Telemetry::TX_ID), out.as_slice()) {
                tap.frame(at_us, CAN1, &frame);
            }
            at_us += FRAME_US;
            if let Ok(Received::FlowControl(reply)) = self.pi.on_frame(out.as_slice(), clock(at_us))
            {
                if let Some(frame) =
                    standard_frame(u32::from(Telemetry::FLOW_CONTROL_ID), reply.as_slice())
                {
                    tap.frame(at_us, CAN1, &frame);
                }
                self.ccm
                    .link()
                    .on_flow_control(reply.as_slice(), clock(at_us));
                at_us += FRAME_US;
            }
        }
    }
}

fn is_pcc_status(frame: &CanFrame) -> bool {
    matches!(frame.id(), Id::Standard(id) if u32::from(id.as_raw()) == PccStatus::ID)
}

fn can_frame(out: &OutFrame) -> Option<CanFrame> {
    if out.extended {
        CanFrame::new(ExtendedId::new(out.id)?, out.data())
    } else {
        standard_frame(out.id, out.data())
    }
}

fn standard_frame(id: u32, data: &[u8]) -> Option<CanFrame> {
    let id = StandardId::new(u16::try_from(id).ok()?)?;
    CanFrame::new(id, data)
}
