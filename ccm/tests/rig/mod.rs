#![allow(dead_code)] // each test binary uses its part of the bench

//! A test bench around the CCM: every 10 ms tick sends the other nodes' frames (each may be
//! withheld), ten 1 kHz sensor samples and the front wheels' pulses, then runs a control step.

use aer::can::{
    DtiAcLimits, DtiCurrents, DtiDriveEnable, DtiFaultCode, DtiFlags, DtiSpeed, DtiTemperatures,
    Mcu1, Mcu2, Mcu3, McuMainState, McuWarningLevel, McuWorkMode, MotorMode, MotorRotateDirection,
    OrionCellVoltages, OrionLimits, OrionPackStatus, PccStatus, PrechargeState,
};
use aer::runtime::{CounterSender, EncodeError};
use aer_ccm::brakes::volts_for;
use aer_ccm::calibration::AppsCalibration;
use aer_ccm::calibration::Calibration;
use aer_ccm::constants::WHEEL_TEETH;
use aer_ccm::vehicle::State;
use aer_ccm::{Ccm, ControlOutputs, DriverInputs, InverterKind, SensorSample};
use aer_flexcan::CanFrame;
use embedded_can::{ExtendedId, Frame, Id, StandardId};

pub const CAL: AppsCalibration = AppsCalibration::DEFAULT;

/// What the BMS reports.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bms {
    /// SOC (%).
    pub soc: f32,
    pub voltage: f32,
    pub current: f32,
    pub dcl: u16,
    pub low_cell: f32,
}

/// What the inverter reports (as MCU1-3 or as the DTI's packets, whichever the CCM drives).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Inverter {
    pub rpm: f32,
    /// DC voltage and current.
    pub dc: (f32, f32),
    /// A fault: an MCU2 fault bit, or the DTI's fault code OVERCURRENT.
    pub fault: bool,
}

/// One 10 ms tick of stimulus.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tick {
    /// Travel of each pedal sensor (may disagree; outside 0..1 is a wiring fault).
    pub pedal: (f32, f32),
    /// The pedal converter delivers conversions.
    pub converter: bool,
    /// Front and rear brake pressure (psi); negative means below the sensor's 0.5 V.
    pub brake_psi: (f32, f32),
    pub rtm: bool,
    pub launch: bool,
    /// PCC state sent this tick, if any.
    pub pcc: Option<u8>,
    /// BMS frames sent this tick, if any.
    pub bms: Option<Bms>,
    /// Inverter frames sent this tick, if any.
    pub inverter: Option<Inverter>,
    /// Front wheel speed (rad/s), as gear-tooth pulses.
    pub wheels_rad_s: f32,
}

impl Tick {
    /// A calm tick: PCC online, BMS and inverter healthy and idle, no pedal, brakes held.
    pub const CALM: Self = Self {
        pedal: (0.0, 0.0),
        converter: true,
        brake_psi: (100.0, 100.0),
        rtm: false,
        launch: false,
        pcc: Some(3),
        bms: Some(Bms {
            soc: 80.0,
            voltage: 380.0,
            current: 2.0,
            dcl: 300,
            low_cell: 3.9,
        }),
        inverter: Some(Inverter {
            rpm: 0.0,
            dc: (380.0, 2.0),
            fault: false,
        }),
        wheels_rad_s: 0.0,
    };

    /// The same tick with both brake circuits at `psi`.
    pub fn with_brakes(self, psi: f32) -> Self {
        Self {
            brake_psi: (psi, psi),
            ..self
        }
    }

    /// Driving with `pedal` travel on both sensors at `rpm`, the front wheels rolling with
    /// the motor (no slip).
    pub fn driving(pedal: f32, rpm: f32) -> Self {
        let wheels = rpm * std::f32::consts::TAU / 60.0 / aer_ccm::constants::GEAR_RATIO;
        Self {
            pedal: (pedal, pedal),
            brake_psi: (0.0, 0.0),
            inverter: Some(Inverter {
                rpm,
                dc: (380.0, 2.0),
                fault: false,
            }),
            wheels_rad_s: wheels,
            ..Self::CALM
        }
    }
}

/// The CCM on the bench.
pub struct Rig {
    pub ccm: Ccm,
    pub now_ms: u32,
    /// When the last ONLINE status was sent.
    pub pcc_online_at: Option<u32>,
    /// SOC (0..1) as the CCM decodes it, once sent.
    pub soc: Option<f32>,
    wheel_teeth: f32,
    /// Each sender's rolling counter, by message id, as the schema declares them.
    counters: std::collections::HashMap<u32, CounterSender>,
}

fn can_frame(id: u32, extended: bool, data: &[u8]) -> CanFrame {
    let id = if extended {
        Id::Extended(ExtendedId::new(id).unwrap())
    } else {
        Id::Standard(StandardId::new(id as u16).unwrap())
    };
    CanFrame::new(id, data).unwrap()
}

/// Both inverters, for tests that must hold with either.
pub const INVERTERS: [InverterKind; 2] = [InverterKind::Dti, InverterKind::Ifl100];

impl Rig {
    /// A CCM driving the car's configured inverter.
    pub fn new() -> Self {
        Self::with_inverter(aer_ccm::constants::INVERTER)
    }

    /// A CCM driving `inverter`; the rig's inverter frames are that inverter's.
    pub fn with_inverter(inverter: InverterKind) -> Self {
        Self {
            ccm: Ccm::with_inverter(Calibration::DEFAULT, inverter),
            now_ms: 0,
            pcc_online_at: None,
            soc: None,
            wheel_teeth: 0.0,
            counters: std::collections::HashMap::new(),
        }
    }

    /// Sends `message` if it encodes (values outside the DBC range do not); true if sent.
    fn send<M>(
        &mut self,
        id: u32,
        message: M,
        encode: fn(&M, &mut [u8]) -> Result<usize, EncodeError>,
    ) -> bool {
        self.send_as(id, false, message, encode)
    }

    fn send_as<M>(
        &mut self,
        id: u32,
        extended: bool,
        message: M,
        encode: fn(&M, &mut [u8]) -> Result<usize, EncodeError>,
    ) -> bool {
        let mut data = [0u8; 8];
        let sent = encode(&message, &mut data);
        if let Ok(len) = sent {
            // Counters and checksums as the sender fills them.
            if let Some(meta) = aer::can::message_meta(id, extended) {
                meta.seal(self.counters.entry(id).or_default(), &mut data[..len]);
            }
            self.ccm
                .on_frame(&can_frame(id, extended, &data[..len]), self.now_ms);
        }
        sent.is_ok()
    }

    pub fn tick(&mut self, tick: &Tick) -> ControlOutputs {
        if let Some(raw) = tick.pcc {
            let state = PrechargeState::from_raw(raw);
            if self.send(PccStatus::ID, pcc_status(state), PccStatus::encode) {
                self.pcc_online_at = (state == PrechargeState::Online).then_some(self.now_ms);
            }
        }
        if let Some(bms) = tick.bms {
            let round = |value: f32, step: f32| f64::from((value / step).round() * step);
            if self.send(
                OrionPackStatus::ID,
                OrionPackStatus {
                    orion_pack_current: round(bms.current, 0.1),
                    orion_pack_inst_voltage: round(bms.voltage, 0.1),
                    orion_pack_soc: round(bms.soc, 0.5),
                    orion_relay_state: 1,
                },
                OrionPackStatus::encode,
            ) {
                self.soc = Some(round(bms.soc, 0.5) as f32 / 100.0);
            }
            self.send(
                OrionLimits::ID,
                OrionLimits {
                    orion_pack_dcl: bms.dcl,
                    orion_pack_ccl: 50,
                    orion_high_temperature: 35,
                    orion_low_temperature: 20,
                },
                OrionLimits::encode,
            );
            self.send(
                OrionCellVoltages::ID,
                OrionCellVoltages {
                    orion_low_cell_voltage: round(bms.low_cell, 0.0001),
                    orion_high_cell_voltage: 4.1,
                    orion_avg_cell_voltage: 3.9,
                    orion_low_cell_id: 7,
                },
                OrionCellVoltages::encode,
            );
        }
        match tick.inverter {
            Some(inverter) if self.ccm.inverter() == InverterKind::Dti => self.dti(&inverter),
            Some(inverter) => self.ifl100(&inverter),
            None => {}
        }
        self.sensors(tick)
    }

    /// The DTI's status packets the CCM acts on.
    fn dti(&mut self, inverter: &Inverter) {
        let (volts, amps) = inverter.dc;
        let speed = DtiSpeed {
            dti_erpm: (inverter.rpm * aer_ccm::constants::MOTOR_POLE_PAIRS).round() as i32,
            dti_duty_cycle: 0.0,
            dti_input_voltage: volts.round() as i16,
        };
        self.send_as(DtiSpeed::ID, true, speed, DtiSpeed::encode);
        let currents = DtiCurrents {
            dti_ac_current: 0.0,
            dti_dc_current: f64::from((amps * 10.0).round() / 10.0),
        };
        self.send_as(DtiCurrents::ID, true, currents, DtiCurrents::encode);
        let temperatures = DtiTemperatures {
            dti_controller_temp: 35.0,
            dti_motor_temp: 40.0,
            dti_fault_code: if inverter.fault {
                DtiFaultCode::Overcurrent
            } else {
                DtiFaultCode::None
            },
        };
        self.send_as(
            DtiTemperatures::ID,
            true,
            temperatures,
            DtiTemperatures::encode,
        );
        self.send_as(DtiFlags::ID, true, dti_flags(), DtiFlags::encode);
        let limits = DtiAcLimits {
            dti_max_ac_current: 346.6,
            dti_available_max_ac_current: 346.6,
            dti_min_ac_current: 0.0,
            dti_available_min_ac_current: 0.0,
        };
        self.send_as(DtiAcLimits::ID, true, limits, DtiAcLimits::encode);
    }

    /// The IFL100's MCU1-3.
    fn ifl100(&mut self, inverter: &Inverter) {
        {
            let mut mcu1 = mcu1();
            mcu1.mcu_motor_speed = f64::from((inverter.rpm * 4.0).round() / 4.0);
            self.send(Mcu1::ID, mcu1, Mcu1::encode);
            self.send(
                Mcu2::ID,
                Mcu2 {
                    mcu_motor_phase_curr_fault: inverter.fault,
                    ..quiet_mcu2()
                },
                Mcu2::encode,
            );
            let (volts, amps) = inverter.dc;
            self.send(
                Mcu3::ID,
                Mcu3 {
                    mcu_dc_voltage: f64::from((volts * 100.0).round() / 100.0),
                    mcu_dc_current: f64::from((amps * 100.0).round() / 100.0),
                    mcu_phase_current: 0.0,
                },
                Mcu3::encode,
            );
        }
    }

    /// Ten sensor samples and wheel pulses, then the control step.
    fn sensors(&mut self, tick: &Tick) -> ControlOutputs {
        let raw = |(rest, full): (f32, f32), t: f32| rest + t * (full - rest);
        let conversions = if tick.converter {
            [
                Some(raw(CAL.apps1, tick.pedal.0)),
                Some(raw(CAL.apps2, tick.pedal.1)),
            ]
        } else {
            [None, None]
        };
        let sample = SensorSample {
            apps_v: conversions,
            brake_v: (volts_for(tick.brake_psi.0), volts_for(tick.brake_psi.1)),
            shock_raw: [4000; 4],
        };
        let teeth_per_ms = tick.wheels_rad_s / std::f32::consts::TAU * WHEEL_TEETH as f32 / 1_000.0;
        for _ in 0..10 {
            self.now_ms += 1;
            self.ccm.sample(&sample, self.now_ms);
            self.wheel_teeth += teeth_per_ms;
            if self.wheel_teeth >= 1.0 {
                self.wheel_teeth -= 1.0;
                self.ccm.wheel_pulse(0, self.now_ms * 1_000);
                self.ccm.wheel_pulse(1, self.now_ms * 1_000);
            }
        }
        self.ccm.control(
            DriverInputs {
                ready_to_move: tick.rtm,
                launch: tick.launch,
            },
            self.now_ms,
            self.now_ms.wrapping_mul(1_000),
        )
    }

    /// Scripted start-up into DRIVING: PCC precharging then online, button with the brake
    /// held, ready-to-drive sound, brake released.
    pub fn drive_away(&mut self) {
        for _ in 0..5 {
            self.tick(&Tick {
                pcc: Some(1),
                ..Tick::CALM
            });
        }
        self.tick(&Tick::CALM);
        for _ in 0..30 {
            self.tick(&Tick {
                rtm: true,
                ..Tick::CALM
            });
        }
        for _ in 0..210 {
            self.tick(&Tick::CALM);
        }
        let state = self
            .tick(&Tick {
                brake_psi: (0.0, 0.0),
                ..Tick::CALM
            })
            .vehicle
            .state;
        assert_eq!(
            state,
            State::Driving,
            "the scripted start-up must reach DRIVING"
        );
    }

    /// Ticks `tick` `count` times; returns the last outputs.
    pub fn hold(&mut self, tick: &Tick, count: usize) -> ControlOutputs {
        let mut outputs = self.tick(tick);
        for _ in 1..count {
            outputs = self.tick(tick);
        }
        outputs
    }
}

pub fn pcc_status(state: PrechargeState) -> PccStatus {
    PccStatus {
        pcc_state: state,
        pcc_error_too_fast: false,
        pcc_error_air_plus_open: false,
        pcc_error_converters_disagree: false,
        pcc_error_bypassed: false,
        pcc_error_resistor_hot: false,
        pcc_accumulator_no_pulses: false,
        pcc_tractive_no_pulses: false,
        pcc_error_accumulator_silent: false,
        pcc_error_tractive_silent: false,
        pcc_error_no_discharge: false,
        pcc_error_too_slow: false,
        pcc_error_bms_timeout: false,
        pcc_error_shutdown: false,
        pcc_error_undefined_state: false,
        pcc_accumulator_voltage: 400.0,
        pcc_tractive_voltage: 399.0,
        pcc_precharge_progress: 99.75,
    }
}

/// DTI packet 0x24 of a healthy DTI on map 2.5 with its drive disabled.
pub fn dti_flags() -> DtiFlags {
    DtiFlags {
        dti_throttle_input: 0,
        dti_brake_input: 0,
        dti_digital_in1: false,
        dti_digital_in2: false,
        dti_digital_in3: false,
        dti_digital_in4: false,
        dti_digital_out1: false,
        dti_digital_out2: false,
        dti_digital_out3: false,
        dti_digital_out4: false,
        dti_drive_enabled: DtiDriveEnable::Disabled,
        dti_limit_capacitor_temp: false,
        dti_limit_dc_current: false,
        dti_limit_drive_enable: true,
        dti_limit_igbt_accel_temp: false,
        dti_limit_igbt_temp: false,
        dti_limit_input_voltage: false,
        dti_limit_motor_accel_temp: false,
        dti_limit_motor_temp: false,
        dti_limit_rpm_min: false,
        dti_limit_rpm_max: false,
        dti_limit_power: false,
        dti_can_map_version: 25,
    }
}

pub fn mcu1() -> Mcu1 {
    Mcu1 {
        mcu_motor_speed: 0.0,
        mcu_actual_torque: 0.0,
        mcu_max_motor_torque: 259.896,
        mcu_max_motor_brake_torque: 0.0,
        mcu_main_state: McuMainState::Run,
        mcu_rotate_direction: MotorRotateDirection::Forward,
        mcu1_rolling_counter: 0,
        mcu_motor_state: MotorMode::Drive,
        mcu_work_mode: McuWorkMode::Torque,
    }
}

pub fn quiet_mcu2() -> Mcu2 {
    Mcu2 {
        mcu_motor_temp: 40,
        mcu_inverter_temp: 35,
        mcu_dc_main_wire_over_curr_fault: false,
        mcu_motor_phase_curr_fault: false,
        mcu_over_hot_fault: false,
        mcu_resolver_fault: false,
        mcu_phase_curr_sensor_fault: false,
        mcu_motor_over_spd_fault: false,
        mcu_drv_motor_over_hot_fault: false,
        mcu_dc_main_wire_over_volt_fault: false,
        mcu_drv_motor_over_cool_fault: false,
        mcu_motor_system_state: false,
        mcu_temp_sensor_state: false,
        mcu_motor_temp_sensor_state: false,
        mcu_dc_volt_sensor_state: false,
        mcu_dc_low_volt_warning: false,
        mcu_12v_low_volt_warning: false,
        mcu2_rolling_counter: 0,
        mcu_warning_level: McuWarningLevel::None,
        mcu_motor_open_phase_fault: false,
        mcu_motor_stall_fault: false,
    }
}
