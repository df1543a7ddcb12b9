//! Safety properties of the whole CCM over arbitrary inputs (proptest), step by step:
//! - the commanded torque is never negative, never above 260 Nm, never above what the torque
//!   monitor allows, the SOC derating, or the power limit at the highest drivetrain
//!   efficiency for the motor speed;
//! - it is zero unless the vehicle is DRIVING, the PCC reported ONLINE within 100 ms, no
//!   torque-stopping fault is active, the pedal is sound and plausible with the brakes.
//!
//! Inputs are arbitrary, not physical: nodes fall silent at random, sensors disagree, the
//! converter drops out. The closed-loop counterpart, on a car model, is in
//! `car-model/tests/properties.rs`. Each case first drives the car into DRIVING with a
//! scripted start-up, then applies random ticks, so the properties are exercised where
//! torque actually flows.

mod rig;

use aer_ccm::ControlOutputs;
use aer_ccm::constants::{DRIVETRAIN_EFFICIENCY, MOTOR_MAX_TORQUE_NM, POWER_LIMIT_W};
use aer_ccm::power::PowerLimits;
use aer_ccm::vehicle::State;
use proptest::prelude::*;
use rig::{Bms, INVERTERS, Inverter, Rig, Tick};

fn tick() -> impl Strategy<Value = Tick> {
    let travel = prop_oneof![4 => 0.0f32..1.0, 1 => -0.3f32..1.3];
    let bms = (
        0.0f32..100.0,
        250.0f32..420.0,
        -50.0f32..400.0,
        0u16..400,
        2.5f32..4.2,
    )
        .prop_map(|(soc, voltage, current, dcl, low_cell)| Bms {
            soc,
            voltage,
            current,
            dcl,
            low_cell,
        });
    let inverter = (
        0.0f32..8_000.0,
        250.0f32..420.0,
        -50.0f32..320.0,
        prop::bool::weighted(0.03),
    )
        .prop_map(|(rpm, volts, amps, fault)| Inverter {
            rpm,
            dc: (volts, amps),
            fault,
        });
    (
        (travel.clone(), travel),
        prop::bool::weighted(0.97),
        (
            prop_oneof![0.0f32..100.0, Just(0.0), -50.0f32..2_200.0],
            0.0f32..100.0,
        ),
        (prop::bool::weighted(0.05), prop::bool::weighted(0.05)),
        prop::option::weighted(0.9, prop_oneof![8 => Just(3u8), 1 => 0u8..=7]),
        prop::option::weighted(0.9, bms),
        prop::option::weighted(0.9, inverter),
        0.0f32..250.0,
    )
        .prop_map(
            |(pedal, converter, brake_psi, (rtm, launch), pcc, bms, inverter, wheels_rad_s)| Tick {
                pedal,
                converter,
                brake_psi,
                rtm,
                launch,
                pcc,
                bms,
                inverter,
                wheels_rad_s,
            },
        )
}

/// Clean driving (pedals agree, no brake, every node healthy) with random pack state, motor
/// speed and pedal: the limits are exercised while torque actually flows.
fn driving_tick() -> impl Strategy<Value = Tick> {
    (
        0.0f32..1.0,
        0.0f32..100.0,
        200.0f32..420.0,
        -20.0f32..400.0,
        0.0f32..6_500.0,
    )
        .prop_map(|(travel, soc, voltage, current, rpm)| Tick {
            bms: Some(Bms {
                soc,
                voltage,
                current,
                dcl: 600,
                low_cell: 3.9,
            }),
            ..Tick::driving(travel, rpm)
        })
}

fn check(rig: &Rig, tick: &Tick, outputs: &ControlOutputs) -> Result<(), TestCaseError> {
    let torque = outputs.torque.torque_nm;
    prop_assert!(
        (0.0..=MOTOR_MAX_TORQUE_NM).contains(&torque),
        "torque {}",
        torque
    );
    prop_assert!(torque <= outputs.torque.allowed_nm, "{:?}", outputs.torque);
    if torque == 0.0 {
        return Ok(());
    }
    // Torque flows: every condition for it must hold.
    let soc = rig.soc.unwrap_or(0.0);
    prop_assert!(
        torque <= MOTOR_MAX_TORQUE_NM * PowerLimits::CAR.soc_factor(soc) + 1e-3,
        "torque {} at SOC {}",
        torque,
        soc
    );
    if let Some(inverter) = tick.inverter {
        let omega = inverter.rpm * std::f32::consts::TAU / 60.0;
        prop_assert!(
            torque * omega <= DRIVETRAIN_EFFICIENCY.1 * POWER_LIMIT_W * 1.001,
            "{} Nm at {} rpm",
            torque,
            inverter.rpm
        );
    }
    prop_assert_eq!(outputs.vehicle.state, State::Driving);
    prop_assert!(
        !outputs.faults.stops_torque(),
        "faults {:?}",
        outputs.faults
    );
    let apps = rig.ccm.apps();
    prop_assert!(
        !(apps.brake_plausibility || apps.sensor_fault() || apps.signal_lost),
        "{:?}",
        apps
    );
    let fresh = rig.pcc_online_at.is_some_and(|at| rig.now_ms - at <= 100);
    prop_assert!(fresh, "torque without a fresh ONLINE from the PCC");
    Ok(())
}

/// Runs `ticks` (after the scripted start into DRIVING if `from_driving`) with each inverter,
/// checking every step.
fn run(ticks: &[Tick], from_driving: bool) -> Result<(), TestCaseError> {
    for inverter in INVERTERS {
        let mut rig = Rig::with_inverter(inverter);
        if from_driving {
            rig.drive_away();
        }
        for tick in ticks {
            let outputs = rig.tick(tick);
            check(&rig, tick, &outputs)?;
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

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
            if let Some(bms) = ticks[at].bms.as_mut() {
                bms.soc = soc;
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
    for inverter in INVERTERS {
        let mut rig = Rig::with_inverter(inverter);
        rig.drive_away();
        let outputs = rig.hold(&Tick::driving(0.5, 1_000.0), 20);
        assert_eq!(outputs.vehicle.state, State::Driving, "{inverter:?}");
        // Half travel, above the 2 % deadband: (0.5 - 0.02) / 0.98 of 260 Nm.
        let expected = (0.5 - 0.02) / 0.98 * 260.0;
        assert!(
            (outputs.torque.torque_nm - expected).abs() < 1.0,
            "{inverter:?}: {:?}",
            outputs.torque
        );
    }
}
