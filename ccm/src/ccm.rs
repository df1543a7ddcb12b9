//! The whole CCM as one hardware-free value: the firmware feeds it samples, frames and the
//! clock, and sends what it returns. Tests, the car model and the Cortex-M7 check drive it
//! the same way.
//!
//! Inside, the state is split by who writes it, so the firmware can lock each part at its own
//! priority: the wheel pulse timers (the edge interrupt, lock-free), [`Sensors`] (the 1 kHz
//! sensor task), [`TelemetryLink`] (the CAN receive interrupts and the telemetry task) and
//! [`Control`] (the 100 Hz control step). [`Ccm`] holds one of each for everyone else.

use crate::apps::AppsReading;
use crate::brakes::BrakeReading;
use crate::bus::BusState;
use crate::calibration::Calibration;
use crate::calibration::state::CalibrationState;
use crate::calibration::store::Startup;
use crate::chassis::PulseTimer;
use crate::constants::WHEEL_TEETH;
use crate::control::{Control, Due, HandoverRefusal};
use crate::inverter::{InverterKind, OutFrames};
use crate::io::{ControlOutputs, DriverCounters, DriverInputs, SensorSample};
use crate::power::PowerLimits;
use crate::sensors::Sensors;
use crate::telemetry::TelemetryLink;
use crate::xcp::Measurements;
use aer::calibration::VehicleState;
use aer::can::CcmStatus;
use aer::runtime::EncodeError;
use aer::telemetry::Telemetry;
use embedded_can::Frame;

/// The CCM: its four parts and the calibration they run with, driven together.
#[derive(Debug, Clone)]
pub struct Ccm {
    calibration: CalibrationState,
    wheels: [PulseTimer; 2],
    sensors: Sensors,
    link: TelemetryLink,
    control: Control,
}

impl Ccm {
    /// A CCM at reset (vehicle OFF, no torque) running with `calibration`, driving the car's
    /// configured inverter ([`INVERTER`](crate::constants::INVERTER)).
    pub fn new(calibration: Calibration) -> Self {
        Self::with_inverter(calibration, crate::constants::INVERTER)
    }

    /// A CCM at reset driving the `inverter`.
    pub fn with_inverter(calibration: Calibration, inverter: InverterKind) -> Self {
        Self::with_limits(calibration, inverter, PowerLimits::CAR)
    }

    /// A CCM at reset driving the `inverter` within `limits` (a lower power cap, say).
    pub fn with_limits(
        calibration: Calibration,
        inverter: InverterKind,
        limits: PowerLimits,
    ) -> Self {
        Self {
            calibration: CalibrationState::new(calibration, Startup::NoneSaved),
            wheels: [PulseTimer::new(), PulseTimer::new()],
            sensors: Sensors::new(),
            link: TelemetryLink::new(),
            control: Control::with_limits(inverter, limits),
        }
    }

    /// The calibration it runs with now.
    pub fn calibration(&self) -> Calibration {
        *self.calibration.active()
    }

    /// Runs with `calibration` from the next sensor sample and control step on, whole, as
    /// start-up would have loaded it (`startup` says from where).
    pub fn set_calibration(&mut self, calibration: Calibration, startup: Startup) {
        self.calibration = CalibrationState::new(calibration, startup);
    }

    /// The live calibration: what a calibration tool reads and changes (each change takes
    /// effect whole at the next sensor sample and control step).
    pub fn calibration_state(&self) -> &CalibrationState {
        &self.calibration
    }

    /// See [`Ccm::calibration_state`].
    pub fn calibration_state_mut(&mut self) -> &mut CalibrationState {
        &mut self.calibration
    }

    /// Whether the car moves and the tractive system is live, as the last control step saw
    /// it: what calibration changes and saving are checked against.
    pub fn vehicle_state(&self) -> VehicleState {
        self.control.vehicle_state()
    }

    /// What XCP measures: the telemetry packet as last sent and the last control step's
    /// internals.
    pub fn measurements(&self) -> Measurements {
        Measurements {
            telemetry: *self.link.last_packet(),
            internals: self.internals().to_bytes(),
        }
    }

    /// The last control step's intermediate values (see [`Control::internals`]).
    pub fn internals(&self) -> aer::calibration::Internals {
        self.control.internals()
    }

    /// The inverter this CCM drives.
    pub fn inverter(&self) -> InverterKind {
        self.control.inverter()
    }

    /// What the buses delivered so far.
    pub fn bus(&self) -> &BusState {
        self.control.bus()
    }

    /// The telemetry link (counters, frames to send).
    pub fn link(&mut self) -> &mut TelemetryLink {
        &mut self.link
    }

    /// The last control step's outputs (the reset outputs before the first step).
    pub fn last_outputs(&self) -> ControlOutputs {
        self.control.last_outputs()
    }

    /// The pedal as last sampled.
    pub fn apps(&self) -> AppsReading {
        self.sensors.reading().apps
    }

    /// The brakes as last sampled.
    pub fn brakes(&self) -> BrakeReading {
        self.sensors.reading().brakes
    }

    /// Updates the firmware's counters (reported in telemetry).
    pub fn set_driver_counters(&mut self, counters: DriverCounters) {
        self.control.set_driver_counters(counters);
    }

    /// Feeds a received CAN frame (either bus).
    pub fn on_frame(&mut self, frame: &impl Frame, now_ms: u32) {
        self.control.on_frame(frame, now_ms);
    }

    /// A front wheel-speed pulse (`wheel` 0 = left, 1 = right).
    pub fn wheel_pulse(&mut self, wheel: usize, now_us: u32) {
        if let Some(timer) = self.wheels.get(wheel) {
            timer.on_pulse(now_us);
        }
    }

    /// The 1 kHz sensor step.
    pub fn sample(&mut self, sample: &SensorSample, now_ms: u32) {
        self.sensors
            .sample(self.calibration.active(), sample, now_ms);
    }

    /// The 100 Hz control step.
    pub fn control(&mut self, driver: DriverInputs, now_ms: u32, now_us: u32) -> ControlOutputs {
        let wheels = [
            self.wheels[0].speed(WHEEL_TEETH),
            self.wheels[1].speed(WHEEL_TEETH),
        ];
        self.control.step(
            self.calibration.active(),
            &self.sensors.reading(),
            wheels,
            driver,
            now_ms,
            now_us,
        )
    }

    /// What is due after control step `step` (see [`Control::due`]).
    pub fn due(&mut self, step: u32) -> Due {
        self.control.due(step)
    }

    /// The inverter's commands for this period (see [`Control::inverter_frames`]).
    pub fn inverter_frames(&mut self) -> Result<OutFrames, EncodeError> {
        self.control.inverter_frames()
    }

    /// The frames that stop the inverter now, without sending them ([`Control::stop_frames`]):
    /// what the panic handler sends.
    ///
    /// [`Control::stop_frames`]: crate::control::Control::stop_frames
    pub fn stop_frames(&self) -> Result<OutFrames, EncodeError> {
        self.control.stop_frames()
    }

    /// Whether the CCM may hand the chip to the bootloader now, with the inverter commands to
    /// send first (see [`Control::handover`]).
    pub fn handover(&mut self) -> Result<OutFrames, HandoverRefusal> {
        self.control.handover()
    }

    /// CCM_Status as it stands (see [`Control::status`]).
    pub fn status(&self) -> CcmStatus {
        self.control.status()
    }

    /// The CCM_Status to send now; the rolling counter advances once per call.
    pub fn next_status(&mut self) -> CcmStatus {
        self.control.next_status()
    }

    /// The telemetry snapshot.
    pub fn snapshot(&self) -> Telemetry {
        self.control
            .snapshot(&self.sensors.reading(), self.link.counters())
    }

    /// The 10 ms telemetry step: snapshot, pack, start sending.
    pub fn send_telemetry(&mut self, now_us: u32) {
        let snapshot = self.snapshot();
        self.link.send(&snapshot, now_us);
    }
}
