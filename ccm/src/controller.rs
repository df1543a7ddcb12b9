//! The whole CCM as one hardware-free value: the firmware feeds it samples, frames and the
//! clock, and sends what it returns. Tests, the car model and the Cortex-M7 check drive it
//! the same way.

use crate::ads1115::Conversions;
use crate::apps::{Apps, AppsCalibration, AppsReading};
use crate::brakes::{BrakeReading, Brakes};
use crate::bus::{BusInputs, BusState};
use crate::chassis::{WheelSpeed, shock_travel_mm};
use crate::config::{ADC_PERIOD_MS, CONTROL_PERIOD_MS, SAMPLE_TIMEOUT_MS, WHEEL_TEETH};
use crate::drive::{TorqueCommand, TorqueInputs, TorquePath};
use crate::faults::{Fault, FaultInputs, FaultMap, FaultMonitor};
use crate::inverter::{DriveCommand, Vcu1Builder, bms1_frame, bms2_frame};
use crate::power::PowerLimits;
use crate::telemetry::TelemetryLink;
use crate::thermal::{Cooling, cooling};
use crate::vehicle::{State, Vehicle, VehicleInputs, VehicleOutputs};
use aer::can::{AnyMessage, Bms1, Bms2, CcmStatus, PrechargeState, SCHEMA_FINGERPRINT, Vcu1};
use aer::runtime::EncodeError;
use aer::telemetry::Telemetry;
use embedded_can::Frame;

/// One 1 kHz sensor sample.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SensorSample {
    /// New ADS1115 conversions of APPS1 and APPS2 since the last sample (`None` on a channel
    /// with nothing new: the converter is slower than the sample rate, or lost).
    pub apps_raw: Conversions,
    /// Front and rear brake sensor voltages (after the divider).
    pub brake_v: (f32, f32),
    /// Raw 12-bit readings of the four shock potentiometers (FL, FR, RL, RR).
    pub shock_raw: [u16; 4],
}

/// Driver inputs read by the control step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DriverInputs {
    /// Ready-to-move button (raw).
    pub ready_to_move: bool,
    /// Launch-control button.
    pub launch: bool,
}

/// What the control step decided; the firmware applies it to the outputs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ControlOutputs {
    /// Vehicle state machine outputs.
    pub vehicle: VehicleOutputs,
    /// Torque command.
    pub torque: TorqueCommand,
    /// Active faults.
    pub faults: FaultMap,
    /// Brake light: on exactly while the brakes count as engaged.
    pub brake_light: bool,
    /// Pump and fan duty.
    pub cooling: Cooling,
}

impl ControlOutputs {
    /// The outputs before the first control step: OFF, no torque, everything off.
    pub const RESET: Self = Self {
        vehicle: VehicleOutputs {
            state: State::Off,
            torque_enabled: false,
            rtd_sound: false,
            precharge_complete: false,
        },
        torque: TorqueCommand::ZERO,
        faults: FaultMap::NONE,
        brake_light: false,
        cooling: Cooling {
            pump: 0.0,
            fan: 0.0,
        },
    };
}

/// A frame the CCM sends: id and 8 payload bytes.
pub type OutFrame = (u32, [u8; 8]);

/// One CAN controller's health, as the firmware reads it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct BusHealth {
    /// An error counter is above 127: the node only sends passive error flags.
    pub error_passive: bool,
    /// The transmit error counter passed 255: the controller is off the bus until it
    /// recovers by itself.
    pub bus_off: bool,
    /// Times the controller went bus-off (since start-up).
    pub bus_off_events: u32,
}

/// What the firmware counts outside the library (queues, mailboxes, the pedal converter's
/// bus), reported in telemetry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DriverCounters {
    /// Received frames lost: receive queue or hardware FIFO full.
    pub rx_dropped: u32,
    /// Frames that never went out: every mailbox busy, a frame that failed to encode, a
    /// pending frame replaced by a newer one or dropped when the bus went off.
    pub tx_dropped: u32,
    /// Failed I2C transactions with the pedal converter.
    pub pedal_bus_errors: u32,
    /// CAN1 and CAN2.
    pub buses: [BusHealth; 2],
}

/// The CCM.
#[derive(Debug, Clone)]
pub struct Ccm {
    apps: Apps,
    brakes: Brakes,
    shock_mm: [f32; 4],
    wheels: [WheelSpeed; 2],
    vehicle: Vehicle,
    fault_monitor: FaultMonitor,
    torque_path: TorquePath,
    vcu1: Vcu1Builder,
    status_counter: u8,
    bus: BusState,
    link: TelemetryLink,
    last: ControlOutputs,
    driver: DriverCounters,
    /// The first time the CCM was fed (ms): missing nodes are judged from here.
    started_ms: Option<u32>,
    /// When the last sensor sample arrived (ms).
    sampled_ms: Option<u32>,
    /// When the last control step ran (ms).
    stepped_ms: u32,
}

impl Ccm {
    /// A CCM at reset (vehicle OFF, no torque) with the pedal `calibration`.
    pub fn new(calibration: AppsCalibration) -> Self {
        Self {
            apps: Apps::new(calibration, ADC_PERIOD_MS),
            brakes: Brakes::new(ADC_PERIOD_MS),
            shock_mm: [0.0; 4],
            wheels: [WheelSpeed::new(WHEEL_TEETH); 2],
            vehicle: Vehicle::new(),
            fault_monitor: FaultMonitor::default(),
            torque_path: TorquePath::new(PowerLimits::CAR, CONTROL_PERIOD_MS),
            vcu1: Vcu1Builder::default(),
            status_counter: 0,
            bus: BusState::default(),
            link: TelemetryLink::new(),
            last: ControlOutputs::RESET,
            driver: DriverCounters::default(),
            started_ms: None,
            sampled_ms: None,
            stepped_ms: 0,
        }
    }

    /// What the buses delivered so far.
    pub fn bus(&self) -> &BusState {
        &self.bus
    }

    /// The telemetry link (counters, frames to send).
    pub fn link(&mut self) -> &mut TelemetryLink {
        &mut self.link
    }

    /// The last control step's outputs (the reset outputs before the first step).
    pub fn last_outputs(&self) -> ControlOutputs {
        self.last
    }

    /// The pedal as last sampled.
    pub fn apps(&self) -> AppsReading {
        self.apps.reading()
    }

    /// The brakes as last sampled.
    pub fn brakes(&self) -> BrakeReading {
        self.brakes.reading()
    }

    /// The torque path (for diagnostics: the power limiter's efficiency estimate).
    pub fn torque_path(&self) -> &TorquePath {
        &self.torque_path
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

    /// A front wheel-speed pulse (`wheel` 0 = left, 1 = right).
    pub fn wheel_pulse(&mut self, wheel: usize, now_us: u32) {
        if let Some(sensor) = self.wheels.get_mut(wheel) {
            sensor.on_pulse(now_us);
        }
    }

    /// The 1 kHz sensor step.
    pub fn sample(&mut self, sample: &SensorSample, now_ms: u32) {
        self.started_ms.get_or_insert(now_ms);
        self.sampled_ms = Some(now_ms);
        let brakes = self
            .brakes
            .update(sample.brake_v.0, sample.brake_v.1, now_ms);
        self.apps.update(sample.apps_raw, brakes.engaged, now_ms);
        self.shock_mm = sample.shock_raw.map(shock_travel_mm);
    }

    /// The 100 Hz control step.
    pub fn control(&mut self, driver: DriverInputs, now_ms: u32, now_us: u32) -> ControlOutputs {
        let started = *self.started_ms.get_or_insert(now_ms);
        self.stepped_ms = now_ms;
        let apps = self.apps.reading();
        let brakes = self.brakes.reading();
        let bus = self.bus.inputs(now_ms, started);
        let sampled = self.sampled_ms.unwrap_or(started);
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
        let torque = self.torque_path.step(&TorqueInputs {
            apps,
            brakes_engaged: brakes.engaged,
            sensors_fresh: !sensors_stale,
            torque_enabled: vehicle.torque_enabled,
            faults,
            soc: bus.pack.map(|pack| pack.orion_pack_soc as f32 / 100.0),
            motor_rad_s: bus
                .motor
                .map(|mcu1| aer_params::motor_rad_s(mcu1.mcu_motor_speed as f32)),
            inverter_max_nm: bus.motor.map(|mcu1| mcu1.mcu_max_motor_torque as f32),
            dc_power_w: dc_power_w(&bus),
            front_rad_s: (
                self.wheels[0].rad_per_s(now_us),
                self.wheels[1].rad_per_s(now_us),
            ),
            launch_button: driver.launch,
        });
        let temperatures = bus.inverter.map_or((f32::NAN, f32::NAN), |mcu2| {
            (
                f32::from(mcu2.mcu_inverter_temp),
                f32::from(mcu2.mcu_motor_temp),
            )
        });
        let outputs = ControlOutputs {
            vehicle,
            torque,
            faults,
            brake_light: brakes.engaged,
            cooling: cooling(vehicle.precharge_complete, temperatures.0, temperatures.1),
        };
        self.last = outputs;
        outputs
    }

    /// VCU1, BMS1 and BMS2 for the inverter (every 20 ms), from the last control step. The
    /// VCU1 sent is mirrored into telemetry (the torque the inverter was asked for).
    pub fn inverter_frames(&mut self) -> Result<[OutFrame; 3], EncodeError> {
        let last = self.last;
        let command = DriveCommand {
            torque_nm: last.torque.torque_nm,
            drive: last.vehicle.torque_enabled,
            main_relay: last.vehicle.precharge_complete,
            brakes_engaged: self.brakes.reading().engaged,
        };
        let (vcu1, vcu1_data) = self.vcu1.next_frame(&command)?;
        self.bus.mirror.apply(&AnyMessage::Vcu1(vcu1));
        let bus = self
            .bus
            .inputs(self.stepped_ms, self.started_ms.unwrap_or(self.stepped_ms));
        let precharging = bus.pcc.map(|status| status.pcc_state) == Some(PrechargeState::Precharge);
        // Without a fresh limit from the BMS the inverter may draw nothing.
        let discharge_limit = bus
            .limits
            .map_or(0.0, |limits| f32::from(limits.orion_pack_dcl));
        Ok([
            (Vcu1::ID, vcu1_data),
            (
                Bms1::ID,
                bms1_frame(precharging, last.vehicle.precharge_complete)?,
            ),
            (Bms2::ID, bms2_frame(discharge_limit)?),
        ])
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
        }
    }

    /// The CCM_Status to send now; the rolling counter advances once per call.
    pub fn next_status(&mut self) -> CcmStatus {
        let status = self.status();
        self.status_counter = (self.status_counter + 1) & 0x0F;
        status
    }

    /// The telemetry snapshot: everything mirrored from the buses plus the CCM's own sensors
    /// and state.
    pub fn snapshot(&self) -> Telemetry {
        let mut snapshot = self.bus.mirror;
        snapshot.apply(&AnyMessage::CcmStatus(self.status()));
        let apps = self.apps.reading();
        let brakes = self.brakes.reading();
        snapshot.apps_travel = apps.travel;
        snapshot.bse_front = brakes.front_v;
        snapshot.bse_rear = brakes.rear_v;
        let [fl, fr, rl, rr] = self.shock_mm;
        snapshot.shocktravel1 = fl;
        snapshot.shocktravel2 = fr;
        snapshot.shocktravel3 = rl;
        snapshot.shocktravel4 = rr;
        // Counters wrap at 8 bits on the wire; at 100 packets/s the Pi sees every increment.
        let wrap = |count: u32| (count & 0xFF) as u8;
        let driver = &self.driver;
        snapshot.can_rx_dropped = wrap(driver.rx_dropped);
        snapshot.can_tx_dropped = wrap(driver.tx_dropped);
        snapshot.can_decode_errors =
            wrap(self.bus.decode_errors.wrapping_add(self.bus.unknown_ids));
        snapshot.telemetry_superseded = wrap(self.link.counters().superseded);
        snapshot.pedal_bus_errors = wrap(driver.pedal_bus_errors);
        let [can1, can2] = driver.buses;
        snapshot.can_bus_off_events = wrap(can1.bus_off_events.wrapping_add(can2.bus_off_events));
        snapshot.can1_error_passive = can1.error_passive;
        snapshot.can1_bus_off = can1.bus_off;
        snapshot.can2_error_passive = can2.error_passive;
        snapshot.can2_bus_off = can2.bus_off;
        snapshot
    }

    /// The 10 ms telemetry step: snapshot, pack, start sending.
    pub fn send_telemetry(&mut self, now_us: u32) {
        let snapshot = self.snapshot();
        self.link.send(&snapshot, now_us);
    }
}

/// DC power into the drivetrain (W): the inverter's DC voltage x current (MCU3), or the BMS's
/// pack power if that is higher (a cross-check: one wrong or saturated measurement cannot
/// hide the power). `None` without a fresh MCU3.
fn dc_power_w(bus: &BusInputs) -> Option<f32> {
    let inverter = bus
        .dc_link
        .map(|mcu3| (mcu3.mcu_dc_voltage * mcu3.mcu_dc_current) as f32)?;
    let pack = bus
        .pack
        .map(|pack| (pack.orion_pack_inst_voltage * pack.orion_pack_current) as f32);
    Some(pack.map_or(inverter, |pack| inverter.max(pack)))
}
