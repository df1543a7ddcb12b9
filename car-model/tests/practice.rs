//! The desk car's practice loop ([`Cycle::Practice`]): a launch, a stop, a stand with the
//! tractive system live, a park with it off, and a second launch, so a tuner can try the
//! launch parameters (standstill), saving and the sensor parameters (tractive system off)
//! and see a new launch curve take effect.

use aer_car_model::chassis::Mode;
use aer_car_model::driver::{Activity, Cycle, PARK_MS, STAND_MS};
use aer_car_model::faults::FaultPlan;
use aer_car_model::{ClosedLoop, ModelParams, NoTap};
use aer_ccm::launch::LaunchState;

#[test]
fn the_practice_loop_launches_parks_with_the_tractive_system_off_and_launches_again() {
    let mut run = ClosedLoop::new(
        ModelParams::NOMINAL,
        Mode::Road,
        Cycle::Practice,
        FaultPlan::NONE,
    );
    let mut launches = 0;
    let mut was_launching = false;
    let mut parked_off_ms = 0u32;
    let mut standing_live_ms = 0u32;
    let limit = 2 * (30_000 + STAND_MS + PARK_MS);
    while run.now_ms() < limit && launches < 2 {
        run.step(&mut NoTap);
        let launching = run.last_outputs().torque.launch == LaunchState::Active;
        if launching && !was_launching {
            launches += 1;
        }
        was_launching = launching;
        let state = run.ccm.vehicle_state();
        match run.car.driver.activity() {
            Activity::Parked if !state.moving && !state.tractive_live => parked_off_ms += 1,
            Activity::Standing if !state.moving && state.tractive_live => standing_live_ms += 1,
            _ => {}
        }
    }
    assert_eq!(launches, 2, "two launches by {} ms", run.now_ms());
    assert_eq!(run.rules.violations(), 0);
    // Most of the stand is at standstill with the tractive system live; most of the park is
    // with it off (it takes a few seconds to discharge below 60 V).
    assert!(
        standing_live_ms > STAND_MS / 2,
        "{standing_live_ms} ms standing"
    );
    assert!(
        parked_off_ms > PARK_MS / 2,
        "{parked_off_ms} ms parked, tractive system off"
    );
}
