//! What the 100 Hz control step owns: the buses' latest values, the fault monitor, the
//! vehicle state machine, the torque path and the frames it sends. It reads the sensors and
//! wheel speeds as inputs, so the firmware locks it only at the control step's priority.

use crate::bus::{BusInputs, BusState};
use crate::calibration::Calibration;
use crate::chassis::WheelSpeed;
use crate::constants::{
    BMS_LIMITS_TIMEOUT_MS, CONTROL_PERIOD_MS, DTI_FLAGS_TIMEOUT_MS, INVERTER,
    MOTOR_TORQUE_PER_PEAK_A, PCC_STATUS_TIMEOUT_MS, SAMPLE_TIMEOUT_MS, STANDSTILL_RAD_S,
    STATUS_PERIOD_MS, TRACTIVE_OFF_V,
};
use crate::faults::{Fault, FaultInputs, FaultMonitor};
use crate::inverter::dti::{self, EnableWatch};
use crate::inverter::ifl100::{self, Vcu1Builder};
use crate::inverter::speed_watch::SpeedWatch;
use crate::inverter::{DriveCommand, InverterKind, OutFrames};
use crate::io::{ControlOutputs, DriverCounters, DriverInputs};
use crate::power::PowerLimits;
use crate::sensors::SensorReading;
use crate::telemetry::LinkCounters;
use crate::thermal::cooling;
use crate::torque_path::{TorqueInputs, TorquePath};
use crate::vehicle::{State, Vehicle, VehicleInputs};
use aer::calibration::{Internals, VehicleState};
use aer::can::{CcmCalibration, CcmStatus, PrechargeState, SCHEMA_FINGERPRINT};
use aer::runtime::EncodeError;
use aer::telemetry::{Telemetry, TelemetryOwnFields, TelemetrySent};
use embedded_can::Frame;

/// What goes out after a control step: the inverter's commands every command period,
/// CCM_Status every [`STATUS_PERIOD_MS`] and CCM_Calibration every its cycle time.
#[derive(Debug, Clone, PartialEq)]
pub struct Due {
    /// The inverter's frames, if due (an encoding failure is the codec's defect: counted).
    pub inverter: Option<Result<OutFrames, EncodeError>>,
    /// CCM_Status, if due (its rolling counter advanced).
    pub status: Option<CcmStatus>,
    /// Whether CCM_Calibration is due (the calibration's owner,
    /// [`crate::calibration::state::CalibrationState::status`], has its content).
    pub calibration: bool,
}

/// Why the CCM keeps running instead of handing the chip to the bootloader.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum HandoverRefusal {
    /// The car is DRIVING (torque enabled).
    Driving,
    /// Torque is still commanded (Nm).
    TorqueCommanded {
        /// The torque asked for.
        torque_nm: f32,
    },
    /// The safe commands could not be encoded (a codec defect): without them the inverter
    /// would be left to its timeout.
    Encode(EncodeError),
}

impl core::fmt::Display for HandoverRefusal {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Driving => f.write_str(
                "the car is DRIVING: stop, press ready-to-move to leave DRIVING, then ask again",
            ),
            Self::TorqueCommanded { torque_nm } => write!(
                f,
                "{torque_nm:.1} Nm is still commanded: wait for zero torque, then ask again"
            ),
            Self::Encode(error) => {
                write!(f, "the safe inverter commands did not encode ({error:?})")
            }
        }
    }
}

/// The control step's state.
#[derive(Debug, Clone)]
pub struct Control {
    vehicle: Vehicle,
    fault_monitor: FaultMonitor,
    torque_path: TorquePath,
    inverter: InverterKind,
    vcu1: Vcu1Builder,
    /// The drive enable last sent to the DTI, and the watch that it is obeyed.
    enable_sent: bool,
    /// The torque the inverter was last asked for (Nm), as its command carried it.
    torque_sent_nm: f32,
    enable_watch: EnableWatch,
    /// The reported motor speed against the front wheels (both inverters).
    speed_watch: SpeedWatch,
    status_counter: u8,
    bus: BusState,
    last: ControlOutputs,
    driver: DriverCounters,
    /// The first time the CCM was fed (ms): missing nodes are judged from here.
    started_ms: Option<u32>,
    /// When the last control step ran (ms).
    stepped_ms: u32,
    /// Whether the car moves and the tractive system is live, as the last step saw it.
    vehicle_state: VehicleState,
}

impl Default for Control {
    fn default() -> Self {
        Self::new(INVERTER)
    }
}

impl Control {
    /// At reset: vehicle OFF, no torque, driving the `inverter`.
    pub fn new(inverter: InverterKind) -> Self {
        Self::with_limits(inverter, PowerLimits::CAR)
    }

    /// At reset, driving the `inverter` within `limits` (the car's, or a lower power cap).
    pub fn with_limits(inverter: InverterKind, limits: PowerLimits) -> Self {
        Self {
            vehicle: Vehicle::new(),
            fault_monitor: FaultMonitor::default(),
            torque_path: TorquePath::new(limits, CONTROL_PERIOD_MS),
            inverter,
            vcu1: Vcu1Builder::default(),
            enable_sent: false,
            torque_sent_nm: 0.0,
            enable_watch: EnableWatch::default(),
            speed_watch: SpeedWatch::default(),
            status_counter: 0,
            bus: BusState::default(),
            last: ControlOutputs::RESET,
            driver: DriverCounters::default(),
            started_ms: None,
            stepped_ms: 0,
            vehicle_state: VehicleState {
                moving: true,
                tractive_live: true,
            },
        }
    }

    /// The inverter this CCM drives.
    pub fn inverter(&self) -> InverterKind {
        self.inverter
    }

    /// What the buses delivered so far.
    pub fn bus(&self) -> &BusState {
        &self.bus
    }

    /// The last control step's outputs (the reset outputs before the first step).
    pub fn last_outputs(&self) -> ControlOutputs {
        self.last
    }

    /// Updates the firmware's counters (reported in telemetry).
    pub fn set_driver_counters(&mut self, counters: DriverCounters) {
        self.driver = counters;
    }

    /// Feeds a received CAN frame (either bus).
    pub fn on_frame(&mut self, frame: &impl Frame, now_ms: u32) {
        self.started_ms.get_or_insert(now_ms);
        self.bus.on_frame(frame, now_ms);
    }

    /// When the CCM was first fed: the first frame, sample or control step.
    fn started(&mut self, first_sample_ms: Option<u32>, now_ms: u32) -> u32 {
        let earlier = |a: u32, b: u32| if (b.wrapping_sub(a) as i32) < 0 { b } else { a };
        let started = match (self.started_ms, first_sample_ms) {
            (Some(fed), Some(sampled)) => earlier(fed, sampled),
            (Some(at), None) | (None, Some(at)) => at,
            (None, None) => now_ms,
        };
        self.started_ms = Some(started);
        started
    }

    /// The 100 Hz control step, from the sensors and front wheel speeds as they are now, with
    /// the `calibration` as it is now (a change takes effect here, whole).
    pub fn step(
        &mut self,
        calibration: &Calibration,
        sensors: &SensorReading,
        wheels: [WheelSpeed; 2],
        driver: DriverInputs,
        now_ms: u32,
        now_us: u32,
    ) -> ControlOutputs {
        let started = self.started(sensors.first_ms, now_ms);
        self.stepped_ms = now_ms;
        let (apps, brakes) = (sensors.apps, sensors.brakes);
        let status = self.inverter.status(&self.bus, now_ms, started);
        let mut bus = self.bus.inputs(now_ms, started, status);
        if self.inverter == InverterKind::Dti {
            let flags = self.bus.dti_flags.fresh(now_ms, DTI_FLAGS_TIMEOUT_MS);
            bus.inverter.fault |=
                self.enable_watch
                    .disobeyed(self.enable_sent, flags.as_ref(), now_ms);
        }
        let [left, right] = wheels;
        let front_rad_s = (left.rad_per_s(now_us), right.rad_per_s(now_us));
        bus.inverter.fault |= self.speed_watch.implausible(
            bus.inverter.motor_rpm.map(aer_params::motor_rad_s),
            front_rad_s,
            self.torque_sent_nm,
            now_ms,
        );
        let sampled = sensors.sampled_ms.unwrap_or(started);
        let sensors_stale = now_ms.wrapping_sub(sampled) > SAMPLE_TIMEOUT_MS;
        let faults = self.fault_monitor.evaluate(&FaultInputs {
            now_ms,
            bus: &bus,
            apps,
            brakes,
            sensors_stale,
        });
        let vehicle = self.vehicle.step(&VehicleInputs {
            now_ms,
            pcc: bus.pcc.map(|status| status.pcc_state),
            rtm_button: driver.ready_to_move,
            brakes_engaged: brakes.engaged,
            faults,
        });
        let torque = self.torque_path.step(
            calibration,
            &TorqueInputs {
                apps,
                brakes_engaged: brakes.engaged,
                sensors_fresh: !sensors_stale,
                torque_enabled: vehicle.torque_enabled,
                faults,
                soc: bus.pack.map(|pack| pack.orion_pack_soc as f32 / 100.0),
                motor_rad_s: bus.inverter.motor_rpm.map(aer_params::motor_rad_s),
                inverter_max_nm: bus.inverter.available_torque_nm,
                dc_power_w: dc_power_w(&bus),
                shaft_power_w: bus
                    .inverter
                    .torque_nm
                    .zip(bus.inverter.motor_rpm)
                    .map(|(torque, rpm)| torque * aer_params::motor_rad_s(rpm)),
                front_rad_s,
                launch_button: driver.launch,
            },
        );
        let standing = |rad_s: f32| rad_s.abs() < STANDSTILL_RAD_S;
        self.vehicle_state = VehicleState {
            moving: !(bus
                .inverter
                .motor_rpm
                .map(aer_params::motor_rad_s)
                .is_some_and(standing)
                && standing(front_rad_s.0)
                && standing(front_rad_s.1)),
            tractive_live: vehicle.torque_enabled
                || !bus.pcc.is_some_and(|pcc| {
                    // A tractive converter that fell silent after reading 60 V or more: the
                    // voltage is unknown, so live.
                    pcc.pcc_state == PrechargeState::Standby
                        && !pcc.pcc_error_tractive_silent
                        && pcc.pcc_tractive_voltage < f64::from(TRACTIVE_OFF_V)
                }),
        };
        let temperatures = bus
            .inverter
            .temperatures_degc
            .unwrap_or((f32::NAN, f32::NAN));
        let outputs = ControlOutputs {
            vehicle,
            torque,
            faults,
            brake_light: brakes.engaged,
            cooling: cooling(
                calibration,
                vehicle.precharge_complete,
                temperatures.0,
                temperatures.1,
            ),
        };
        self.last = outputs;
        outputs
    }

    /// Whether the car moves and the tractive system is live, as the last control step saw it
    /// (both true before the first): what calibration changes and saving are checked against.
    pub fn vehicle_state(&self) -> VehicleState {
        self.vehicle_state
    }

    /// The last control step's intermediate values (launch, traction, the power limiter and
    /// the monitor), what XCP samples at the control event.
    pub fn internals(&self) -> Internals {
        self.torque_path.internals()
    }

    /// The control schedule, in one place for the firmware, the car model and the tests: what
    /// is due after control step `step` (counted from 0 at start-up, one every
    /// [`CONTROL_PERIOD_MS`]).
    pub fn due(&mut self, step: u32) -> Due {
        let every = |period_ms: u32| step % (period_ms / CONTROL_PERIOD_MS).max(1) == 0;
        Due {
            inverter: every(self.inverter.command_period_ms()).then(|| self.inverter_frames()),
            status: every(STATUS_PERIOD_MS).then(|| self.next_status()),
            calibration: every(CcmCalibration::CYCLE_TIME_MS),
        }
    }

    /// The inverter's commands for this period (every
    /// [`InverterKind::command_period_ms`]), from the last control step and the brakes as it
    /// saw them: the IFL100's VCU1, BMS1 and BMS2, or the DTI's current, drive enable and DC
    /// current limits. The torque asked for is reported in telemetry.
    pub fn inverter_frames(&mut self) -> Result<OutFrames, EncodeError> {
        let last = self.last;
        let now = self.stepped_ms;
        let pcc = self.bus.pcc.fresh(now, PCC_STATUS_TIMEOUT_MS);
        let command = DriveCommand {
            torque_nm: last.torque.torque_nm,
            drive: last.vehicle.torque_enabled,
            main_relay: last.vehicle.precharge_complete,
            precharging: pcc.map(|status| status.pcc_state) == Some(PrechargeState::Precharge),
            brakes_engaged: last.brake_light,
            // Without a fresh limit from the BMS the inverter may draw nothing.
            discharge_limit_a: self
                .bus
                .limits
                .fresh(now, BMS_LIMITS_TIMEOUT_MS)
                .map_or(0.0, |limits| f32::from(limits.orion_pack_dcl)),
        };
        self.send(&command)
    }

    /// The commands that leave the inverter safe for the CCM to stop (the bootloader): no
    /// torque, drive disabled, main relay open, no current allowed. Refused while the car
    /// drives or torque is commanded, so nothing outside (a console, a USB host) can take the
    /// torque path away mid-run and leave the inverter to its own command timeout.
    pub fn handover(&mut self) -> Result<OutFrames, HandoverRefusal> {
        let state = self.last.vehicle.state;
        if state == State::Driving || self.last.vehicle.torque_enabled {
            return Err(HandoverRefusal::Driving);
        }
        if self.torque_sent_nm != 0.0 || self.last.torque.torque_nm != 0.0 {
            return Err(HandoverRefusal::TorqueCommanded {
                torque_nm: self.torque_sent_nm.max(self.last.torque.torque_nm),
            });
        }
        let safe = DriveCommand {
            torque_nm: 0.0,
            drive: false,
            main_relay: false,
            precharging: false,
            brakes_engaged: self.last.brake_light,
            discharge_limit_a: 0.0,
        };
        self.send(&safe).map_err(HandoverRefusal::Encode)
    }

    /// The frames that stop the inverter, as a panic must send them (`crate::stop`): no
    /// torque, drive disabled, main relay open, no current allowed. Built without sending or
    /// recording anything: the IFL100's rolling counter is the next one, from a copy.
    pub fn stop_frames(&self) -> Result<OutFrames, EncodeError> {
        let stop = DriveCommand {
            torque_nm: 0.0,
            drive: false,
            main_relay: false,
            precharging: false,
            brakes_engaged: self.last.brake_light,
            discharge_limit_a: 0.0,
        };
        match self.inverter {
            InverterKind::Ifl100 => {
                let mut builder = self.vcu1.clone();
                ifl100::frames(&mut builder, &stop).map(|(_, frames)| frames)
            }
            InverterKind::Dti => dti::frames(&stop).map(|(_, frames)| frames),
        }
    }

    /// Builds the inverter's frames for `command` and records what they ask for.
    fn send(&mut self, command: &DriveCommand) -> Result<OutFrames, EncodeError> {
        match self.inverter {
            InverterKind::Ifl100 => {
                let (vcu1, frames) = ifl100::frames(&mut self.vcu1, command)?;
                self.torque_sent_nm = if vcu1.vcu_vehicle_state {
                    vcu1.vcu_torque_req as f32
                } else {
                    0.0
                };
                Ok(frames)
            }
            InverterKind::Dti => {
                let (current, frames) = dti::frames(command)?;
                self.enable_sent = command.drive;
                self.torque_sent_nm = current.dti_current_cmd as f32 * MOTOR_TORQUE_PER_PEAK_A;
                Ok(frames)
            }
        }
    }

    /// CCM_Status as it stands: state, faults, firmware fingerprint, rolling counter. Reading
    /// it changes nothing; [`next_status`](Self::next_status) is what the firmware sends.
    pub fn status(&self) -> CcmStatus {
        let last = &self.last;
        let faults = last.faults;
        CcmStatus {
            ccm_vehicle_state: last.vehicle.state.to_wire(),
            ccm_fault_over_current: faults.has(Fault::OverCurrent),
            ccm_fault_under_voltage: faults.has(Fault::UnderVoltage),
            ccm_fault_over_temperature: faults.has(Fault::OverTemperature),
            ccm_fault_apps: faults.has(Fault::Apps),
            ccm_fault_bse: faults.has(Fault::Bse),
            ccm_fault_bpps: faults.has(Fault::Bpps),
            ccm_fault_apps_brake_plausibility: faults.has(Fault::AppsBrakePlausibility),
            ccm_fault_low_battery_voltage: faults.has(Fault::LowBatteryVoltage),
            ccm_schema_fingerprint: SCHEMA_FINGERPRINT,
            ccm_rolling_counter: self.status_counter,
            ccm_ready_to_drive: last.vehicle.torque_enabled,
            ccm_fault_pedal_signal_lost: faults.has(Fault::PedalSignalLost),
            ccm_fault_sensors_stale: faults.has(Fault::SensorsStale),
            ccm_fault_bms_timeout: faults.has(Fault::BmsTimeout),
            ccm_fault_inverter_timeout: faults.has(Fault::InverterTimeout),
            ccm_fault_pcc_timeout: faults.has(Fault::PccTimeout),
            ccm_fault_inverter_fault: faults.has(Fault::InverterFault),
            ccm_fault_inverter_warning: faults.has(Fault::InverterWarning),
            ccm_fault_pcc_error: faults.has(Fault::PccError),
            ccm_fault_tractive_mismatch: faults.has(Fault::TractiveMismatch),
        }
    }

    /// The CCM_Status to send now; the rolling counter advances once per call.
    pub fn next_status(&mut self) -> CcmStatus {
        let status = self.status();
        self.status_counter = (self.status_counter + 1) & 0x0F;
        status
    }

    /// The telemetry snapshot: everything mirrored from the buses, the messages the CCM sends
    /// itself, and its own sensors, state and counters. Every own field and sent message is
    /// named here (the generated `TelemetryOwnFields` and `TelemetrySent` have no `Default`), so
    /// a field added to the schema does not build until it is filled.
    pub fn snapshot(&self, sensors: &SensorReading, link: LinkCounters) -> Telemetry {
        // Counters wrap at 8 bits on the wire; at 100 packets/s the Pi sees every increment.
        let wrap = |count: u32| (count & 0xFF) as u8;
        let driver = &self.driver;
        let [vehicle, inverter] = driver.buses;
        let [fl, fr, rl, rr] = sensors.shock_mm;
        let status = self.inverter.status(
            &self.bus,
            self.stepped_ms,
            self.started_ms.unwrap_or(self.stepped_ms),
        );
        let (inverter_temp, motor_temp) = status.temperatures_degc.unwrap_or((0.0, 0.0));
        let (dc_volts, dc_amps) = status.dc_link.unwrap_or((0.0, 0.0));
        // Whole degrees on the wire; a NaN or out-of-range reading saturates.
        let degrees = |degc: f32| degc.clamp(-40.0, 215.0) as i16;
        Telemetry::from_parts(
            &self.bus.mirror,
            // What the CCM sends itself, built as it goes out (the generated `TelemetrySent`
            // names every message a telemetry field mirrors from the CCM).
            &TelemetrySent {
                ccm_status: self.status(),
            },
            TelemetryOwnFields {
                // Travel is a fraction inside the CCM; people read the throttle in percent.
                apps_travel: sensors.apps.travel * 100.0,
                bse_front: sensors.brakes.front_v,
                bse_rear: sensors.brakes.rear_v,
                shocktravel1: fl,
                shocktravel2: fr,
                shocktravel3: rl,
                shocktravel4: rr,
                motor_speed: status.motor_rpm.unwrap_or(0.0),
                motor_torque: status.torque_nm.unwrap_or(0.0),
                max_motor_torque: status.available_torque_nm.unwrap_or(0.0),
                torque_command: self.torque_sent_nm,
                motor_temp: degrees(motor_temp),
                inverter_temp: degrees(inverter_temp),
                inverter_dc_voltage: dc_volts,
                inverter_dc_current: dc_amps,
                inverter_phase_current: status.phase_current_a.unwrap_or(0.0),
                can_rx_dropped: wrap(driver.rx_dropped),
                can_tx_dropped: wrap(driver.tx_dropped),
                can_decode_errors: wrap(
                    self.bus
                        .decode_errors
                        .wrapping_add(self.bus.integrity_errors)
                        .wrapping_add(self.bus.unknown_ids),
                ),
                telemetry_superseded: wrap(link.superseded),
                pedal_bus_errors: wrap(driver.pedal_bus_errors),
                can_bus_off_events: wrap(
                    vehicle.bus_off_events.wrapping_add(inverter.bus_off_events),
                ),
                vehicle_bus_error_passive: vehicle.error_passive,
                vehicle_bus_bus_off: vehicle.bus_off,
                inverter_bus_error_passive: inverter.error_passive,
                inverter_bus_bus_off: inverter.bus_off,
            },
        )
    }
}

/// DC power into the drivetrain (W): the inverter's DC voltage x current, or the BMS's pack
/// power if that is higher (a cross-check: one wrong or saturated measurement cannot hide the
/// power). `None` without a fresh DC voltage and current from the inverter.
fn dc_power_w(bus: &BusInputs) -> Option<f32> {
    let inverter = bus.inverter.dc_link.map(|(volts, amps)| volts * amps)?;
    let pack = bus
        .pack
        .map(|pack| (pack.orion_pack_inst_voltage * pack.orion_pack_current) as f32);
    Some(pack.map_or(inverter, |pack| inverter.max(pack)))
}
