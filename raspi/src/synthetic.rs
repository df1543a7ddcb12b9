//! A small vehicle model for `synthetic`: laps of a 30 s circuit with a straight (full
//! throttle), a braking zone and corners; speed, power, falling SOC and rising temperatures
//! follow from it. Each step is a real telemetry packet: the generated packer, then the ISO-TP
//! sender, as the CCM does it.

use crate::candump::LoggedFrame;
use aer::can::{McuMainState, MotorMode, MotorRotateDirection, VehicleState};
use aer::telemetry::{Telemetry, TelemetryHeader};
use aer_isotp::{Config, Received, Receiver, Sender};
use embedded_can::{Id, StandardId};

const LAP_S: f64 = 30.0;
const MASS_KG: f64 = 280.0;
const WHEEL_RADIUS_M: f64 = 0.23;
const GEAR_RATIO: f64 = 3.5;
const PACK_AH: f64 = 13.0;

/// The modelled car.
pub struct Vehicle {
    t: f64,
    speed_m_s: f64,
    soc: f64,
    motor_temp: f64,
    inverter_temp: f64,
    sequence: u16,
    sender: Sender<128>,
    receiver: Receiver<128>,
}

impl Default for Vehicle {
    fn default() -> Self {
        Self::new()
    }
}

impl Vehicle {
    /// A car on the grid: full pack, cold.
    pub fn new() -> Self {
        Self {
            t: 0.0,
            speed_m_s: 0.0,
            soc: 0.95,
            motor_temp: 25.0,
            inverter_temp: 25.0,
            sequence: 0,
            sender: Sender::new(Config::CAR),
            receiver: Receiver::new(Config::CAR),
        }
    }

    /// Driver inputs at lap time `s`: throttle 0..1, brake 0..1.
    fn driver(lap_s: f64) -> (f64, f64) {
        match lap_s {
            s if s < 8.0 => (1.0, 0.0),                           // main straight
            s if s < 10.0 => (0.0, 0.9),                          // braking zone
            s if s < 16.0 => (0.35 + 0.1 * (s * 2.0).sin(), 0.0), // hairpin and esses
            s if s < 22.0 => (0.8, 0.0),                          // back straight
            s if s < 23.5 => (0.0, 0.6),
            _ => (0.45, 0.0), // sweepers back to the line
        }
    }

    /// Advances `dt_s` and returns the frames the CCM and the Pi exchange for one packet
    /// (first frame, flow control, consecutive frames), stamped from `now_us`.
    pub fn step(&mut self, dt_s: f64, now_us: u64) -> Vec<LoggedFrame> {
        self.t += dt_s;
        let (throttle, brake) = Self::driver(self.t % LAP_S);
        let torque = throttle * 230.0 * (self.soc / 0.2).min(1.0);
        let wheel_force = torque * GEAR_RATIO / WHEEL_RADIUS_M;
        let drag = 0.6 * self.speed_m_s * self.speed_m_s + 150.0;
        let braking = brake * 9_000.0;
        let accel = (wheel_force - drag - braking) / MASS_KG;
        self.speed_m_s = (self.speed_m_s + accel * dt_s).clamp(0.0, 35.0);
        let motor_rpm = self.speed_m_s / WHEEL_RADIUS_M * GEAR_RATIO * 60.0 / std::f64::consts::TAU;
        let power_w = torque * motor_rpm * std::f64::consts::TAU / 60.0 / 0.92;
        let pack_v = 360.0 + 40.0 * self.soc - power_w / 400.0 * 0.08;
        let current_a = power_w / pack_v;
        self.soc = (self.soc - current_a * dt_s / 3_600.0 / PACK_AH).max(0.0);
        self.motor_temp += (power_w * 6e-5 - (self.motor_temp - 25.0) * 0.01) * dt_s;
        self.inverter_temp += (power_w * 3e-5 - (self.inverter_temp - 25.0) * 0.02) * dt_s;

        let mut t = Telemetry {
            apps_travel: throttle as f32,
            bse_front: (0.5 + brake * 2.5) as f32,
            bse_rear: (0.5 + brake * 2.0) as f32,
            imd_resistance: 2_000,
            pack_voltage: pack_v as f32,
            pack_current: current_a as f32,
            soc: (self.soc * 100.0) as f32,
            discharge_limit: 250,
            charge_limit: 40,
            low_cell_volt: (pack_v / 96.0 - 0.02) as f32,
            high_cell_volt: (pack_v / 96.0 + 0.02) as f32,
            avg_cell_volt: (pack_v / 96.0) as f32,
            motor_speed: motor_rpm as f32,
            motor_torque: torque as f32,
            max_motor_torque: 259.896,
            motor_direction: MotorRotateDirection::Forward,
            motor_state: MotorMode::Drive,
            mcu_main_state: McuMainState::Run,
            mcu_voltage: pack_v as f32,
            mcu_phase_current: (current_a * 1.4) as f32,
            mcu_current: current_a as f32,
            motor_temp: self.motor_temp as i16,
            mcu_temp: self.inverter_temp as i16,
            vehicle_state: VehicleState::Driving,
            ..Telemetry::default()
        };
        let bump = (self.t * 9.0).sin() * 6.0;
        t.shocktravel1 = (30.0 + bump + brake * 12.0) as f32;
        t.shocktravel2 = (30.0 - bump + brake * 12.0) as f32;
        t.shocktravel3 = (28.0 + bump - brake * 8.0) as f32;
        t.shocktravel4 = (28.0 - bump - brake * 8.0) as f32;
        self.packet(&t, now_us)
    }

    fn packet(&mut self, telemetry: &Telemetry, now_us: u64) -> Vec<LoggedFrame> {
        let mut packet = [0u8; Telemetry::LEN];
        let header = TelemetryHeader {
            sequence: self.sequence,
            timestamp_us: now_us as u32,
        };
        self.sequence = self.sequence.wrapping_add(1);
        telemetry.pack(header, &mut packet);
        let mut frames = Vec::with_capacity(12);
        if self.sender.start(&packet).is_err() {
            return frames;
        }
        let (Some(data_id), Some(fc_id)) = (
            StandardId::new(Telemetry::TX_ID),
            StandardId::new(Telemetry::FLOW_CONTROL_ID),
        ) else {
            return frames;
        };
        // 250 us per frame, as on a 500 kbit/s bus.
        let mut at = now_us;
        let mut clock = now_us as u32;
        while let Ok(Some(frame)) = self.sender.poll(clock) {
            self.sender.sent(clock);
            frames.extend(LoggedFrame::new(
                at,
                0,
                Id::Standard(data_id),
                frame.as_slice(),
            ));
            if let Ok(Received::FlowControl(fc)) = self.receiver.on_frame(frame.as_slice(), clock) {
                at += 250;
                clock = clock.wrapping_add(250);
                frames.extend(LoggedFrame::new(at, 0, Id::Standard(fc_id), fc.as_slice()));
                let _ = self.sender.on_flow_control(fc.as_slice(), clock);
            }
            at += 250;
            clock = clock.wrapping_add(250);
        }
        frames
    }
}
