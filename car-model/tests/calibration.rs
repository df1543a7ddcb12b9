//! A calibration change in closed loop: the CCM runs with whatever calibration it is given
//! from its next step on. On the acceleration event, the same start-up, then the launch slip
//! target lowered between two steps: launch control takes more torque away than with the
//! schema's defaults (the wheels slip less, the run takes longer), and the rules hold in both.

use aer_car_model::chassis::Mode;
use aer_car_model::driver::Cycle;
use aer_car_model::faults::FaultPlan;
use aer_car_model::{ClosedLoop, ModelParams, NoTap};
use aer_ccm::calibration::Calibration;
use aer_ccm::calibration::store::Startup;
use aer_ccm::launch::LaunchState;

/// What an acceleration run did while launch control was active.
struct Launch {
    /// Mean slip ratio.
    slip: f32,
    /// Mean torque commanded (Nm).
    torque_nm: f32,
    /// Time to 75 m (s).
    seconds: f32,
}

/// The acceleration run from the line with `calibration` applied at the start.
fn launch(started: &ClosedLoop, calibration: Calibration) -> Launch {
    let mut run = started.clone();
    run.ccm.set_calibration(calibration, Startup::NoneSaved);
    let start = run.now_ms();
    let (mut slip_sum, mut torque_sum, mut steps) = (0.0f32, 0.0f32, 0u32);
    while run.car.chassis.distance_m < 75.0 && run.now_ms() < start + 10_000 {
        run.step(&mut NoTap);
        let torque = run.last_outputs().torque;
        // Once a step: the control step runs every 10 ms.
        if run.now_ms() % 10 == 0 && torque.launch == LaunchState::Active && torque.slip > 0.0 {
            slip_sum += torque.slip;
            torque_sum += torque.torque_nm;
            steps += 1;
        }
    }
    assert_eq!(run.rules.violations(), 0);
    assert!(steps > 10, "launch control was active");
    Launch {
        slip: slip_sum / steps as f32,
        torque_nm: torque_sum / steps as f32,
        seconds: (run.now_ms() - start) as f32 / 1_000.0,
    }
}

#[test]
fn a_new_launch_slip_target_takes_effect_from_the_next_step() {
    let mut started = ClosedLoop::new(
        ModelParams::NOMINAL,
        Mode::Road,
        Cycle::Acceleration,
        FaultPlan::NONE,
    );
    assert!(started.start_up(20_000));
    let defaults = Calibration::DEFAULT;
    let lowered = Calibration {
        launch_slip_target: [0.03; 4],
        ..defaults
    };
    assert!(Calibration::from_page(&lowered.to_page()).is_ok());
    let default = launch(&started, defaults);
    let lowered = launch(&started, lowered);
    println!(
        "launch slip target 0.07: mean slip {:.3}, mean torque {:.0} Nm, 75 m in {:.2} s; \
         0.03: mean slip {:.3}, mean torque {:.0} Nm, 75 m in {:.2} s",
        default.slip,
        default.torque_nm,
        default.seconds,
        lowered.slip,
        lowered.torque_nm,
        lowered.seconds
    );
    assert!(
        lowered.torque_nm < default.torque_nm - 5.0,
        "a lower target takes more torque away"
    );
    assert!(lowered.slip < default.slip, "and the wheels slip less");
    assert!(lowered.seconds > default.seconds, "at the cost of time");
}
