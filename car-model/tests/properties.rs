//! The rules as invariants over random drive cycles, random car parameters and random faults
//! (proptest). Every case drives one of the cycles (acceleration with launch control,
//! skidpad, autocross with throttle/brake overlaps) with a random drivetrain efficiency
//! (0.85-0.97, also falling with speed), measurement lag (0-50 ms), BMS delay (0-2 periods)
//! and bus jitter (0-3 ms), and up to three faults at random times for random durations.
//! Each case runs with either inverter (the comp car's DTI HV-550 or the bench's IFL100).
//! Checked every millisecond (see `aer_car_model::rules`):
//! - every 100 ms average of accumulator power <= 80 kW;
//! - zero torque within each condition's time after it begins: pedal released, APPS
//!   implausible or out of range, pedal converter lost, brakes with throttle, brake sensor
//!   fault, sampling stopped, BMS or inverter silent, PCC not online, either bus off;
//! - no torque outside DRIVING; no DRIVING without a fresh ONLINE from the PCC; never more
//!   than the torque monitor allows.
//!
//! Cases: 40 by default (about 20 s in a debug build on two cores); set PROPTEST_CASES for
//! more.

use aer_car_model::chassis::Mode;
use aer_car_model::driver::Cycle;
use aer_car_model::faults::{Fault, FaultPlan, Injection, Node};
use aer_car_model::{ClosedLoop, ModelParams, NoTap};
use aer_ccm::InverterKind;
use proptest::prelude::*;
use std::sync::OnceLock;

/// Length of each case after the start-up (ms).
const RUN_MS: u32 = 15_000;

fn started(cycle: Cycle, inverter: InverterKind) -> ClosedLoop {
    static STARTED: OnceLock<[[ClosedLoop; 3]; 2]> = OnceLock::new();
    let all = STARTED.get_or_init(|| {
        [ModelParams::NOMINAL, ModelParams::BENCH].map(|params| {
            [Cycle::Acceleration, Cycle::Skidpad, Cycle::Autocross].map(|cycle| {
                let mut run = ClosedLoop::new(params, Mode::Road, cycle, FaultPlan::NONE);
                assert!(run.start_up(20_000), "{cycle:?}: start-up");
                run
            })
        })
    });
    let car = match inverter {
        InverterKind::Dti => &all[0],
        InverterKind::Ifl100 => &all[1],
    };
    match cycle {
        Cycle::Acceleration => car[0].clone(),
        Cycle::Skidpad => car[1].clone(),
        _ => car[2].clone(),
    }
}

fn fault() -> impl Strategy<Value = Fault> {
    prop_oneof![
        Just(Fault::PedalConverterLost),
        (0usize..2).prop_map(Fault::PedalSensorOpen),
        (0usize..2).prop_map(Fault::PedalSensorShorted),
        (0usize..2).prop_map(Fault::PedalSensorStuck),
        Just(Fault::BrakeSensorNan),
        Just(Fault::SamplingStopped),
        Just(Fault::BmsSilent),
        Just(Fault::InverterSilent),
        Just(Fault::InverterFaulted),
        Just(Fault::InverterStuck),
        Just(Fault::ShutdownOpen),
        (0usize..2).prop_map(Fault::BusOff),
        (0usize..2).prop_map(Fault::ConverterSilent),
        Just(Fault::AirPlusWelded),
        Just(Fault::AirPlusStuckOpen),
        Just(Fault::DischargeFailed),
        Just(Fault::TractiveLoad),
        (0usize..2).prop_map(Fault::ThermistorOpen),
        prop_oneof![
            Just(Node::Pcc),
            Just(Node::Bms),
            Just(Node::Inverter),
            Just(Node::Imd)
        ]
        .prop_map(Fault::GarbledFrames),
    ]
}

/// (fault, start after the start-up in ms, duration in ms; 0 = to the end)
fn injections() -> impl Strategy<Value = Vec<(Fault, u32, u32)>> {
    prop::collection::vec(
        (
            fault(),
            0u32..RUN_MS,
            prop_oneof![3 => 20u32..3_000, 1 => Just(0u32)],
        ),
        0..=3,
    )
}

fn params() -> impl Strategy<Value = ModelParams> {
    (
        0.85f32..=0.97,
        0.0f32..0.06,
        0.0f32..50.0,
        0usize..=2,
        0u32..=3,
        any::<u32>(),
    )
        .prop_map(
            |(
                efficiency,
                efficiency_droop,
                measurement_lag_ms,
                bms_delay_periods,
                frame_jitter_ms,
                seed,
            )| {
                ModelParams {
                    efficiency,
                    efficiency_droop,
                    measurement_lag_ms,
                    bms_delay_periods,
                    frame_jitter_ms,
                    seed,
                    // The run keeps the inverter it started with.
                    ..ModelParams::NOMINAL
                }
            },
        )
}

fn cycle() -> impl Strategy<Value = Cycle> {
    prop_oneof![
        Just(Cycle::Acceleration),
        Just(Cycle::Skidpad),
        Just(Cycle::Autocross)
    ]
}

fn cases() -> u32 {
    std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|cases| cases.parse().ok())
        .unwrap_or(40)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: cases(), ..ProptestConfig::default() })]

    #[test]
    fn the_rules_hold_over_random_cycles_cars_and_faults(
        cycle in cycle(),
        inverter in prop_oneof![Just(InverterKind::Dti), Just(InverterKind::Ifl100)],
        params in params(),
        injections in injections(),
    ) {
        let mut run = started(cycle, inverter);
        let start = run.now_ms();
        let plan = injections.iter().fold(FaultPlan::NONE, |plan, (fault, at, length)| {
            let from_ms = start + at;
            plan.with(Injection {
                fault: *fault,
                from_ms,
                until_ms: if *length == 0 { u32::MAX } else { from_ms + length },
            })
        });
        run.retune(params, plan);
        run.run_until(start + RUN_MS, &mut NoTap);
        prop_assert_eq!(
            run.rules.first_violation(),
            None,
            "{} violations; stats {:?}",
            run.rules.violations(),
            run.rules.stats()
        );
    }
}

/// Found by the property above on 2026-11-26 (older than that day's work: the same case broke
/// the rule on e02f532): a DTI whose status frames freeze (its packets carry no counter, so
/// they look fresh) kept reporting the motor at the speed it froze at; the power bounds divided
/// by that speed and the 100 ms average reached 106 kW from a freeze at the launch, 80.2 kW from
/// one at speed. Now the bounds take the larger of the reported and the front wheels' speed,
/// and a reading that contradicts the wheels or stops changing while they speed up is an
/// inverter fault (`aer_ccm::inverter::speed_watch`).
#[test]
fn a_dti_frozen_at_any_point_of_the_run_still_keeps_the_power_rule() {
    // At the launch, and at speed, where a frozen reading stays plausible for a while.
    for after_ms in [0, 1_336, 2_139, 2_411, 3_000] {
        let mut run = started(Cycle::Acceleration, InverterKind::Dti);
        let start = run.now_ms();
        let params = ModelParams {
            efficiency: 0.85,
            ..ModelParams::NOMINAL
        };
        let stuck = FaultPlan::NONE.with(Injection {
            fault: Fault::InverterStuck,
            from_ms: start + after_ms,
            until_ms: u32::MAX,
        });
        run.retune(params, stuck);
        run.run_until(start + RUN_MS, &mut NoTap);
        assert_eq!(run.rules.first_violation(), None, "frozen {after_ms} ms in");
    }
}
