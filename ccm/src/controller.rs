//! The whole CCM as one hardware-free value: the firmware feeds it samples, frames and the
//! clock, and sends what it returns. Tests and the Cortex-M7 check drive it the same way.

use crate::apps::{Apps, AppsCalibration, AppsReading};
use crate::brakes::{BrakeReading, Brakes};
use crate::bus::BusState;
use crate::chassis::{WheelSpeed, shock_travel_mm};
use crate::config::{ADC_PERIOD_MS, CONTROL_PERIOD_MS, GEAR_RATIO, WHEEL_TEETH};
use crate::drive::{TorqueCommand, TorqueInputs, TorquePath};
use crate::faults::{Fault, FaultMap, FaultMonitor, PackReadings};
use crate::inverter::{DriveCommand, Vcu1Builder, bms1_frame, bms2_frame};
use crate::power::PowerLimits;
use crate::telemetry::TelemetryLink;
use crate::thermal::{Cooling, cooling};
use crate::vehicle::{State, Vehicle, VehicleInputs, VehicleOutputs};
use aer::can::{Bms1, Bms2, CcmStatus, PrechargeState, SCHEMA_FINGERPRINT, Vcu1};
use aer::runtime::EncodeError;
use aer::telemetry::Telemetry;
use embedded_can::Frame;

/// One 1 kHz sensor sample.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SensorSample {
    /// ADS1115 counts of APPS1 and APPS2.
    pub apps_raw: (i16, i16),
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
    /// Brake light.
    pub brake_light: bool,
    /// Pump and fan duty.
    pub cooling: Cooling,
}

/// A frame the CCM sends: id and 8 payload bytes.
pub type OutFrame = (u32, [u8; 8]);

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
    last: Option<ControlOutputs>,
    driver: DriverCounters,
}

/// Drops the firmware counts outside the library (queues, mailboxes), for telemetry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DriverCounters {
    /// Received frames lost: receive queue or hardware FIFO full.
    pub rx_dropped: u32,
    /// Frames not sent: every mailbox busy.
    pub tx_dropped: u32,
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
            last: None,
            driver: DriverCounters {
                rx_dropped: 0,
                tx_dropped: 0,
            },
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

    /// The last control step's outputs.
    pub fn last_outputs(&self) -> Option<ControlOutputs> {
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

    /// Updates the firmware's drop counters (reported in telemetry).
    pub fn set_driver_counters(&mut self, counters: DriverCounters) {
        self.driver = counters;
    }

    /// Feeds a received CAN frame (either bus).
    pub fn on_frame(&mut self, frame: &impl Frame, now_ms: u32) {
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
        let brakes = self
            .brakes
            .update(sample.brake_v.0, sample.brake_v.1, now_ms);
        self.apps
            .update(sample.apps_raw.0, sample.apps_raw.1, brakes.pressed, now_ms);
        self.shock_mm = sample.shock_raw.map(shock_travel_mm);
    }

    /// The 100 Hz control step.
    pub fn control(&mut self, driver: DriverInputs, now_ms: u32, now_us: u32) -> ControlOutputs {
        let apps = self.apps.reading();
        let brakes = self.brakes.reading();
        let mirror = &self.bus.mirror;
        let pack = PackReadings {
            current_a: mirror.pack_current,
            discharge_limit_a: f32::from(mirror.discharge_limit),
            low_cell_v: mirror.low_cell_volt,
            soc: mirror.soc / 100.0,
            temperatures_degc: (
                f32::from(mirror.motor_temp),
                f32::from(mirror.mcu_temp),
                self.bus.pack_high_temp_degc,
            ),
            bms_seen: self.bus.bms_seen_ms.is_some(),
        };
        let faults = self.fault_monitor.evaluate(
            now_ms,
            &pack,
            apps.sensor_fault(),
            apps.brake_plausibility,
            brakes.sensor_fault,
            brakes.circuits_implausible,
        );
        let vehicle = self.vehicle.step(&VehicleInputs {
            now_ms,
            pcc: self.bus.pcc,
            rtm_button: driver.ready_to_move,
            brake_pressed: brakes.pressed,
            faults,
        });
        let driven_rad_s = mirror.motor_speed * core::f32::consts::TAU / 60.0 / GEAR_RATIO;
        let torque = self.torque_path.step(&TorqueInputs {
            apps,
            torque_enabled: vehicle.torque_enabled,
            faults,
            pack: (pack.soc, mirror.pack_voltage, mirror.pack_current),
            front_rad_s: (
                self.wheels[0].rad_per_s(now_us),
                self.wheels[1].rad_per_s(now_us),
            ),
            driven_rad_s,
            brake_psi: brakes.front_psi,
            launch_button: driver.launch,
        });
        let outputs = ControlOutputs {
            vehicle,
            torque,
            faults,
            brake_light: brakes.light,
            cooling: cooling(
                vehicle.precharge_complete,
                f32::from(mirror.mcu_temp),
                f32::from(mirror.motor_temp),
            ),
        };
        self.last = Some(outputs);
        outputs
    }

    /// VCU1, BMS1 and BMS2 for the inverter (every 20 ms), from the last control step.
    pub fn inverter_frames(&mut self) -> Result<[OutFrame; 3], EncodeError> {
        let last = self.last.unwrap_or(ControlOutputs {
            vehicle: VehicleOutputs {
                state: State::Off,
                torque_enabled: false,
                rtd_sound: false,
                precharge_complete: false,
            },
            torque: TorqueCommand {
                torque_nm: 0.0,
                launch: crate::launch::LaunchState::Off,
                slip: 0.0,
            },
            faults: FaultMap::NONE,
            brake_light: false,
            cooling: Cooling::default(),
        });
        let command = DriveCommand {
            torque_nm: last.torque.torque_nm,
            drive: last.vehicle.torque_enabled,
            main_relay: last.vehicle.precharge_complete,
            brake_pressed: self.brakes.reading().pressed,
        };
        let precharging = matches!(self.bus.pcc, Some((PrechargeState::Precharge, _)));
        Ok([
            (Vcu1::ID, self.vcu1.next_frame(&command)?),
            (
                Bms1::ID,
                bms1_frame(precharging, last.vehicle.precharge_complete)?,
            ),
            (
                Bms2::ID,
                bms2_frame(f32::from(self.bus.mirror.discharge_limit))?,
            ),
        ])
    }

    /// CCM_Status: state, faults, firmware fingerprint, rolling counter.
    pub fn status(&mut self) -> CcmStatus {
        let (state, faults, ready) = self
            .last
            .map_or((State::Off, FaultMap::NONE, false), |last| {
                (last.vehicle.state, last.faults, last.vehicle.torque_enabled)
            });
        let counter = self.status_counter;
        self.status_counter = (self.status_counter + 1) & 0x0F;
        CcmStatus {
            ccm_vehicle_state: state.to_wire(),
            ccm_fault_over_current: faults.has(Fault::OverCurrent),
            ccm_fault_under_voltage: faults.has(Fault::UnderVoltage),
            ccm_fault_over_temperature: faults.has(Fault::OverTemperature),
            ccm_fault_apps: faults.has(Fault::Apps),
            ccm_fault_bse: faults.has(Fault::Bse),
            ccm_fault_bpps: faults.has(Fault::Bpps),
            ccm_fault_apps_brake_plausibility: faults.has(Fault::AppsBrakePlausibility),
            ccm_fault_low_battery_voltage: faults.has(Fault::LowBatteryVoltage),
            ccm_schema_fingerprint: SCHEMA_FINGERPRINT,
            ccm_rolling_counter: counter,
            ccm_ready_to_drive: ready,
        }
    }

    /// The telemetry snapshot: everything mirrored from the buses plus the CCM's own sensors
    /// and state.
    pub fn snapshot(&mut self) -> Telemetry {
        let mut snapshot = self.bus.mirror;
        let status = self.status();
        snapshot.apply(&aer::can::AnyMessage::CcmStatus(status));
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
        snapshot.can_rx_dropped = wrap(self.driver.rx_dropped);
        snapshot.can_tx_dropped = wrap(self.driver.tx_dropped);
        snapshot.can_decode_errors =
            wrap(self.bus.decode_errors.wrapping_add(self.bus.unknown_ids));
        snapshot.telemetry_superseded = wrap(self.link.counters().superseded);
        snapshot
    }

    /// The 10 ms telemetry step: snapshot, pack, start sending.
    pub fn send_telemetry(&mut self, now_us: u32) {
        let snapshot = self.snapshot();
        self.link.send(&snapshot, now_us);
    }
}
