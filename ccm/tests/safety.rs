//! Safety properties of the whole CCM over arbitrary inputs (proptest):
//! - the commanded torque is never negative, never above 260 Nm, never above the SOC
//!   derating or the 80 kW power limit;
//! - it is zero while any fault is active, while APPS/brake plausibility is violated, while an
//!   APPS sensor fault is active, and outside DRIVING;
//! - the vehicle is never DRIVING unless the PCC reports a completed precharge (ONLINE) in a
//!   frame no older than 100 ms.
//!
//! Each case first drives the car into DRIVING with a scripted start-up, then applies random
//! ticks, so the properties are exercised where torque actually flows.

use aer::can::{Mcu1, OrionCellVoltages, OrionLimits, OrionPackStatus, PccStatus, PrechargeState};
use aer_ccm::apps::AppsCalibration;
use aer_ccm::brakes::volts_for;
use aer_ccm::config::{MOTOR_MAX_TORQUE_NM, POWER_LIMIT_W, SOC_DERATE_END, SOC_DERATE_START};
use aer_ccm::vehicle::State;
use aer_ccm::{Ccm, ControlOutputs, DriverInputs, SensorSample};
use aer_flexcan::CanFrame;
use embedded_can::{Frame, StandardId};
use proptest::prelude::*;

const CAL: AppsCalibration = AppsCalibration::DEFAULT;

/// One 10 ms tick of stimulus.
#[derive(Debug, Clone)]
struct Tick {
    /// APPS travel of each sensor (may disagree, may be out of 0..1 = wiring fault).
    pedal: (f32, f32),
    /// Front and rear brake pressure (psi); negative = sensor below 0.5 V.
    brake_psi: (f32, f32),
    rtm: bool,
    launch: bool,
    /// PCC state sent this tick, if any.
    pcc: Option<u8>,
    /// Orion SOC (%), pack voltage, current, DCL, low cell; sent this tick if `Some`.
    pack: Option<(f32, f32, f32, u16, f32)>,
    /// Motor speed (rpm) from the inverter.
    motor_rpm: Option<f32>,
}

fn tick() -> impl Strategy<Value = Tick> {
    let travel = prop_oneof![4 => 0.0f32..1.0, 1 => -0.3f32..1.3];
    (
        (travel.clone(), travel),
        (
            prop_oneof![0.0f32..100.0, Just(0.0), -50.0f32..2_200.0],
            0.0f32..100.0,
        ),
        prop::bool::weighted(0.05),
        prop::bool::weighted(0.05),
        prop::option::weighted(0.9, prop_oneof![8 => Just(3u8), 1 => 0u8..=7]),
        prop::option::weighted(
            0.3,
            (
                0.0f32..100.0,
                250.0f32..420.0,
                -50.0f32..400.0,
                0u16..400,
                2.5f32..4.2,
            ),
        ),
        prop::option::weighted(0.3, 0.0f32..8_000.0),
    )
        .prop_map(
            |(pedal, brake_psi, rtm, launch, pcc, pack, motor_rpm)| Tick {
                pedal,
                brake_psi,
                rtm,
                launch,
                pcc,
                pack,
                motor_rpm,
            },
        )
}

/// Ticks of clean driving (pedals agree, no brake, PCC online, BMS limits generous) with
/// random pack state: the torque limits are exercised while torque actually flows.
fn driving_tick() -> impl Strategy<Value = Tick> {
    (
        0.0f32..1.0,
        0.0f32..100.0,
        200.0f32..420.0,
        -20.0f32..400.0,
        prop::option::weighted(0.5, 0.0f32..6_000.0),
    )
        .prop_map(|(travel, soc, voltage, current, motor_rpm)| Tick {
            pedal: (travel, travel),
            brake_psi: (0.0, 0.0),
            rtm: false,
            launch: false,
            pcc: Some(3),
            pack: Some((soc.max(25.0), voltage, current, 600, 3.9)),
            motor_rpm,
        })
}

/// The CCM plus what the harness last sent it.
struct Rig {
    ccm: Ccm,
    now_ms: u32,
    pcc_online_at: Option<u32>,
    soc: f32,
    power_w: f32,
}

fn std_frame(id: u32, data: &[u8]) -> CanFrame {
    CanFrame::new(StandardId::new(id as u16).unwrap(), data).unwrap()
}

impl Rig {
    fn new() -> Self {
        Self {
            ccm: Ccm::new(CAL),
            now_ms: 0,
            pcc_online_at: None,
            soc: 0.0,
            power_w: 0.0,
        }
    }

    /// Sends `message` if it encodes (values outside the DBC range do not); true if sent.
    fn send<M>(
        &mut self,
        id: u32,
        message: M,
        encode: fn(&M, &mut [u8]) -> Result<usize, aer::runtime::EncodeError>,
    ) -> bool {
        let mut data = [0u8; 8];
        let sent = encode(&message, &mut data).is_ok();
        if sent {
            self.ccm.on_frame(&std_frame(id, &data), self.now_ms);
        }
        sent
    }

    fn tick(&mut self, tick: &Tick) -> ControlOutputs {
        if let Some(raw) = tick.pcc {
            let state = PrechargeState::from_raw(raw);
            if self.send(0x222, pcc_status(state), PccStatus::encode) {
                self.pcc_online_at = (state == PrechargeState::Online).then_some(self.now_ms);
            }
        }
        if let Some((soc, voltage, current, dcl, low_cell)) = tick.pack {
            self.send(
                0x6B0,
                OrionPackStatus {
                    orion_pack_current: f64::from((current * 10.0).round() / 10.0),
                    orion_pack_inst_voltage: f64::from((voltage * 10.0).round() / 10.0),
                    orion_pack_soc: f64::from((soc * 2.0).round() / 2.0),
                    orion_relay_state: 1,
                },
                OrionPackStatus::encode,
            );
            // The harness's SOC and power are what the CCM decodes (0.5 %, 0.1 V, 0.1 A).
            self.soc = ((soc * 2.0).round() / 2.0) / 100.0;
            self.power_w = ((voltage * 10.0).round() / 10.0) * ((current * 10.0).round() / 10.0);
            self.send(
                0x6B1,
                OrionLimits {
                    orion_pack_dcl: dcl,
                    orion_pack_ccl: 50,
                    orion_high_temperature: 35,
                    orion_low_temperature: 20,
                },
                OrionLimits::encode,
            );
            self.send(
                0x6B2,
                OrionCellVoltages {
                    orion_low_cell_voltage: f64::from((low_cell * 1e4).round() / 1e4),
                    orion_high_cell_voltage: 4.1,
                    orion_avg_cell_voltage: 3.9,
                    orion_low_cell_id: 7,
                },
                OrionCellVoltages::encode,
            );
        }
        if let Some(rpm) = tick.motor_rpm {
            let mut mcu1 = mcu1();
            mcu1.mcu_motor_speed = f64::from((rpm * 4.0).round() / 4.0);
            self.send(0x105, mcu1, Mcu1::encode);
        }
        let raw = |(rest, full): (f32, f32), t: f32| {
            (rest + t * (full - rest)).clamp(-32_768.0, 32_767.0) as i16
        };
        let sample = SensorSample {
            apps_raw: (raw(CAL.apps1, tick.pedal.0), raw(CAL.apps2, tick.pedal.1)),
            brake_v: (volts_for(tick.brake_psi.0), volts_for(tick.brake_psi.1)),
            shock_raw: [4000; 4],
        };
        for _ in 0..10 {
            self.now_ms += 1;
            self.ccm.sample(&sample, self.now_ms);
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

    /// Scripted start-up into DRIVING: pack data, PCC precharge then online, button with the
    /// brake held, ready-to-drive sound.
    fn drive_away(&mut self) {
        let calm = Tick {
            pedal: (0.0, 0.0),
            brake_psi: (100.0, 100.0),
            rtm: false,
            launch: false,
            pcc: Some(1),
            pack: Some((80.0, 400.0, 5.0, 300, 3.9)),
            motor_rpm: Some(0.0),
        };
        for _ in 0..5 {
            self.tick(&calm);
        }
        let online = Tick {
            pcc: Some(3),
            ..calm.clone()
        };
        self.tick(&online);
        for _ in 0..30 {
            self.tick(&Tick {
                rtm: true,
                ..online.clone()
            });
        }
        for _ in 0..210 {
            self.tick(&online);
        }
        let state = self
            .tick(&Tick {
                brake_psi: (0.0, 0.0),
                ..online
            })
            .vehicle
            .state;
        assert_eq!(
            state,
            State::Driving,
            "the scripted start-up must reach DRIVING"
        );
    }
}

fn pcc_status(state: PrechargeState) -> PccStatus {
    PccStatus {
        pcc_state: state,
        pcc_error_too_fast: false,
        pcc_error_too_slow: false,
        pcc_error_bms_timeout: false,
        pcc_error_shutdown: false,
        pcc_error_undefined_state: false,
        pcc_accumulator_voltage: 400.0,
        pcc_tractive_voltage: 399.0,
        pcc_precharge_progress: 99.75,
    }
}

fn mcu1() -> Mcu1 {
    Mcu1 {
        mcu_motor_speed: 0.0,
        mcu_actual_torque: 0.0,
        mcu_max_motor_torque: 259.896,
        mcu_max_motor_brake_torque: 0.0,
        mcu_main_state: aer::can::McuMainState::Run,
        mcu_rotate_direction: aer::can::MotorRotateDirection::Forward,
        mcu1_rolling_counter: 0,
        mcu_motor_state: aer::can::MotorMode::Drive,
        mcu_work_mode: aer::can::McuWorkMode::Torque,
    }
}

fn check(rig: &Rig, outputs: &ControlOutputs) -> Result<(), TestCaseError> {
    let torque = outputs.torque.torque_nm;
    prop_assert!(
        (0.0..=MOTOR_MAX_TORQUE_NM).contains(&torque),
        "torque {}",
        torque
    );
    // SOC derating bound.
    let soc_factor =
        ((rig.soc - SOC_DERATE_END) / (SOC_DERATE_START - SOC_DERATE_END)).clamp(0.0, 1.0);
    prop_assert!(
        torque <= MOTOR_MAX_TORQUE_NM * soc_factor + 1e-3,
        "torque {} at SOC {}",
        torque,
        rig.soc
    );
    // Power bound.
    if rig.power_w > POWER_LIMIT_W {
        prop_assert!(torque <= MOTOR_MAX_TORQUE_NM * POWER_LIMIT_W / rig.power_w + 1e-3);
    }
    let apps = rig.ccm.apps();
    if outputs.faults.any() || apps.brake_plausibility || apps.sensor_fault() {
        prop_assert_eq!(torque, 0.0, "faults {:?}, apps {:?}", outputs.faults, apps);
    }
    if outputs.vehicle.state != State::Driving {
        prop_assert_eq!(torque, 0.0, "state {:?}", outputs.vehicle.state);
    }
    if outputs.vehicle.state == State::Driving {
        let fresh = rig.pcc_online_at.is_some_and(|at| rig.now_ms - at <= 100);
        prop_assert!(fresh, "DRIVING without a fresh ONLINE from the PCC");
    }
    Ok(())
}

/// Runs `ticks` (after the scripted start into DRIVING if `from_driving`), checking every step.
fn run(ticks: &[Tick], from_driving: bool) -> Result<(), TestCaseError> {
    let mut rig = Rig::new();
    if from_driving {
        rig.drive_away();
    }
    for tick in ticks {
        let outputs = rig.tick(tick);
        check(&rig, &outputs)?;
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]

    #[test]
    fn torque_and_state_stay_safe_for_any_inputs(ticks in prop::collection::vec(tick(), 1..300)) {
        run(&ticks, true)?;
    }

    #[test]
    fn torque_limits_hold_while_driving(
        ticks in prop::collection::vec(driving_tick(), 1..200),
        low_soc in prop::collection::vec((any::<prop::sample::Index>(), 0.0f32..25.0), 0..5),
    ) {
        let mut ticks = ticks;
        for (index, soc) in low_soc {
            let at = index.index(ticks.len());
            if let Some(pack) = ticks[at].pack.as_mut() {
                pack.0 = soc;
            }
        }
        run(&ticks, true)?;
    }

    #[test]
    fn from_reset_random_inputs_never_drive_unsafely(ticks in prop::collection::vec(tick(), 1..300)) {
        run(&ticks, false)?;
    }
}

#[test]
fn the_scripted_start_up_delivers_torque_from_the_pedal() {
    let mut rig = Rig::new();
    rig.drive_away();
    let pedal = Tick {
        pedal: (0.5, 0.5),
        brake_psi: (0.0, 0.0),
        rtm: false,
        launch: false,
        pcc: Some(3),
        pack: Some((80.0, 400.0, 5.0, 300, 3.9)),
        motor_rpm: Some(1_000.0),
    };
    let mut outputs = rig.tick(&pedal);
    for _ in 0..20 {
        outputs = rig.tick(&pedal);
    }
    assert_eq!(outputs.vehicle.state, State::Driving);
    assert!(
        (outputs.torque.torque_nm - 130.0).abs() < 1.0,
        "{:?}",
        outputs.torque
    );
}
