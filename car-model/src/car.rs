//! The whole car around the CCM: driver, chassis, inverter and motor, accumulator, the PCC
//! and its circuit, the other nodes, the sensors, and the faults planned for the run.

use crate::chassis::{Chassis, Mode};
use crate::driver::{Cycle, Driver, DriverCommand, Seen};
use crate::faults::{Fault, FaultPlan, Node};
use crate::nodes::{CAN1, Measured, Nodes};
use crate::pack::Pack;
use crate::params::ModelParams;
use crate::powertrain::{Inverter, efficiency};
use crate::precharge::PccNode;
use crate::sensors::{PedalSignals, Sensors};
use aer::can::AnyMessage;
use aer_ccm::calibration::AppsCalibration;
use aer_ccm::vehicle::State;
use aer_ccm::{InverterKind, SensorSample};
use aer_flexcan::CanFrame;
use aer_pcc::TASK_PERIOD_MS;
use embedded_can::{Frame, Id};

/// The torque the IFL100 reports it can deliver (the VCU1 frame's full scale, Nm).
const INVERTER_MAX_TORQUE_NM: f32 = 259.896;
/// Below this motor speed (rad/s) the DTI's DC current limit is not modelled as a torque
/// limit (the DC current is small there anyway).
const DC_LIMIT_MIN_RAD_S: f32 = 10.0;

/// The car.
#[derive(Debug, Clone)]
pub struct Car {
    /// The run's parameters.
    pub params: ModelParams,
    /// The faults planned for the run.
    pub plan: FaultPlan,
    /// Chassis and tyres.
    pub chassis: Chassis,
    /// Inverter and motor.
    pub inverter: Inverter,
    /// Accumulator.
    pub pack: Pack,
    /// Precharge controller and circuit.
    pub pcc: PccNode,
    nodes: Nodes,
    /// The CCM's sensors.
    pub sensors: Sensors,
    /// The driver.
    pub driver: Driver,
    /// What the driver does this millisecond.
    pub command: DriverCommand,
    /// The pedal sensors' signals this millisecond.
    pub pedal: PedalSignals,
    /// Power drawn from the accumulator this millisecond (W): what the energy meter sees.
    pub power_w: f32,
    /// Drivetrain efficiency this millisecond.
    pub efficiency: f32,
}

impl Car {
    /// A car at rest, tractive system off, driven by a driver who will start it and follow
    /// `cycle`.
    pub fn new(params: ModelParams, mode: Mode, cycle: Cycle, plan: FaultPlan) -> Self {
        let pack = Pack::new(0.9, 28.0);
        let calibration = AppsCalibration::DEFAULT;
        let mut sensors = Sensors::new(calibration, params.seed);
        let pedal = sensors.pedal_signals(0.0, &plan, 0);
        Self {
            params,
            plan,
            chassis: Chassis::new(mode),
            inverter: Inverter::new(params.inverter),
            pcc: PccNode::new(0, pack.voltage_v),
            pack,
            nodes: Nodes::new(
                params.measurement_lag_ms,
                params.bms_delay_periods,
                params.frame_jitter_ms,
                params.seed,
            ),
            sensors,
            driver: Driver::new(cycle, params.seed),
            command: DriverCommand::default(),
            pedal,
            power_w: 0.0,
            efficiency: params.efficiency,
        }
    }

    /// Runs on with `params` (efficiency, measurement lag, the BMS's delay, jitter) and the
    /// faults in `plan`, from the state the car is in; the inverter and the CCM's limits stay
    /// the ones the run started with.
    pub fn retune(&mut self, params: ModelParams, plan: FaultPlan) {
        self.params = ModelParams {
            inverter: self.params.inverter,
            limits: self.params.limits,
            ..params
        };
        self.plan = plan;
        self.nodes.retune(
            params.measurement_lag_ms,
            params.bms_delay_periods,
            params.frame_jitter_ms,
        );
    }

    /// One millisecond ending at `now_ms`: the driver reacts to what the dashboard shows
    /// (`vehicle`), then the powertrain, chassis, accumulator and precharge circuit move on.
    pub fn advance(&mut self, now_ms: u32, vehicle: State) {
        self.command = self.driver.command(&Seen {
            now_ms,
            vehicle,
            speed_m_s: self.chassis.speed_m_s,
            stopped: self.chassis.speed_m_s < 0.1 || matches!(self.chassis.mode, Mode::Dyno { .. }),
            distance_m: self.chassis.distance_m,
        });
        self.pedal = self
            .sensors
            .pedal_signals(self.command.pedal, &self.plan, now_ms);
        let dc_live = self.pcc.connected();
        let rpm = self.chassis.motor_rpm();
        self.inverter.faulted = self.plan.is_active(now_ms, Fault::InverterFaulted);
        self.inverter.timeout_off = self.plan.is_active(now_ms, Fault::InverterTimeoutOff);
        let rad_s = self.chassis.motor_rad_s();
        // The DTI holds its DC current under the CCM's limit: a shaft torque ceiling.
        let cap_nm = if self.inverter.kind == InverterKind::Dti && rad_s > DC_LIMIT_MIN_RAD_S {
            self.inverter.dc_limit_a * self.pcc.plant.tractive_v * self.efficiency / rad_s
        } else if self.inverter.kind == InverterKind::Dti && self.inverter.dc_limit_a <= 0.0 {
            0.0
        } else {
            f32::INFINITY
        };
        self.inverter.step(now_ms, dc_live, rpm, cap_nm, 1.0);
        self.chassis
            .step(self.inverter.torque_nm, self.command.brake_psi, 0.001);
        self.efficiency = efficiency(self.params.efficiency, self.params.efficiency_droop, rpm);
        self.power_w =
            self.inverter
                .dc_power_w(self.chassis.motor_rad_s(), self.efficiency, dc_live, 0.001);
        self.pack.deliver(self.power_w, 0.001);
        self.pcc_hardware(now_ms);
        self.pcc.advance(now_ms);
    }

    /// The PCC circuit's and sensing's faults planned for `now_ms`.
    fn pcc_hardware(&mut self, now_ms: u32) {
        let plan = &self.plan;
        let plant = &mut self.pcc.plant;
        // The shutdown circuit opens and closes on its own time, not the PCC's period: a
        // contact that chatters for a few milliseconds reaches the relays all the same.
        plant.shutdown_closed = !(plan.is_active(now_ms, Fault::ShutdownOpen) || self.command.park);
        plant.air_plus_welded = plan.is_active(now_ms, Fault::AirPlusWelded);
        plant.air_plus_stuck_open = plan.is_active(now_ms, Fault::AirPlusStuckOpen);
        plant.discharge_failed = plan.is_active(now_ms, Fault::DischargeFailed);
        plant.load_ohm = plan
            .is_active(now_ms, Fault::TractiveLoad)
            .then_some(plant.resistor.ohm);
        let sensing = &mut self.pcc.sensing;
        for (index, silent) in sensing.converter_silent.iter_mut().enumerate() {
            *silent = plan.is_active(now_ms, Fault::ConverterSilent(index));
        }
        for (index, open) in sensing.thermistor_open.iter_mut().enumerate() {
            *open = plan.is_active(now_ms, Fault::ThermistorOpen(index));
        }
    }

    /// The CCM's sensor sample this millisecond, or `None` if its sampling has stopped.
    pub fn sample(&mut self, now_ms: u32) -> Option<SensorSample> {
        if self.plan.is_active(now_ms, Fault::SamplingStopped) {
            return None;
        }
        Some(self.sensors.sample(
            &self.pedal,
            self.command.brake_psi,
            self.chassis.accel_m_s2,
            &self.plan,
            now_ms,
        ))
    }

    /// The front wheel-speed pulses of the last millisecond, as (wheel, time in us).
    pub fn wheel_pulses(&mut self, now_ms: u32, pulse: impl FnMut(usize, u32)) {
        let front = self.chassis.front_rad_s();
        self.sensors.wheel_pulses(front, now_ms, 1, pulse);
    }

    /// The other nodes' frames whose time has come, to `deliver(bus, frame)`; the PCC (on
    /// CAN1) hears the BMS's frames on its own.
    pub fn node_frames(&mut self, now_ms: u32, mut deliver: impl FnMut(usize, &CanFrame)) {
        if now_ms % TASK_PERIOD_MS == 0 {
            let frames = self.pcc.step(now_ms, self.pack.voltage_v);
            for frame in frames.iter().flatten() {
                self.nodes.send(now_ms, CAN1, Node::Pcc, frame, &self.plan);
            }
        }
        let dc_v = self.pcc.plant.tractive_v;
        let dc_a = if dc_v > 1.0 { self.power_w / dc_v } else { 0.0 };
        let measured = Measured {
            inverter: self.inverter.kind,
            drive_enabled: self.inverter.enabled(now_ms),
            inverter_faulted: self.inverter.faulted,
            motor_rpm: self.chassis.motor_rpm(),
            torque_nm: self.inverter.torque_nm,
            max_torque_nm: INVERTER_MAX_TORQUE_NM,
            running: self.pcc.connected(),
            temperatures_degc: (self.inverter.motor_degc, self.inverter.inverter_degc),
            dc: (dc_v, dc_a),
            pack: (
                self.pack.voltage_v,
                self.pack.current_a,
                self.pack.soc,
                self.pack.temperature_degc,
            ),
            cell_v: self.pack.cell_v(),
        };
        let pcc = &mut self.pcc;
        self.nodes
            .step(now_ms, &measured, &self.plan, |bus, frame| {
                if bus == CAN1 {
                    pcc.on_frame(now_ms, frame);
                }
                deliver(bus, frame);
            });
    }

    /// A frame from the CCM reaches the car's nodes: the inverter takes its commands.
    pub fn receive(&mut self, frame: &CanFrame, now_ms: u32) {
        let (id, extended) = match frame.id() {
            Id::Standard(id) => (u32::from(id.as_raw()), false),
            Id::Extended(id) => (id.as_raw(), true),
        };
        let mut data = [0u8; 8];
        if let Some(out) = data.get_mut(..frame.data().len()) {
            out.copy_from_slice(frame.data());
        }
        match AnyMessage::decode(id, extended, frame.data()) {
            Ok(message) => self.inverter.on_message(&message, &data, now_ms),
            // The IFL100 counts a VCU1 it cannot read as refused, as it does a bad checksum.
            Err(_) if !extended && id == aer::can::Vcu1::ID => {
                self.inverter.refused_frames += 1;
            }
            Err(_) => {}
        }
    }
}
