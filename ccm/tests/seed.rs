//! The team documentation's test plans (../shared/seed), case by case.

use aer_ccm::calibration::Calibration;
use aer_ccm::chassis::{WheelSpeed, shock_raw_for_volts, shock_travel_mm};
use aer_ccm::constants::SHOCK_TRAVEL_MAX_MM;
use aer_ccm::launch::{LaunchControl, LaunchInputs, LaunchState};
use aer_ccm::power::{PowerLimiter, PowerLimits};
use aer_ccm::watchdog::{Supervisor, Task};

// --- PowerLimit_Update ---------------------------------------------------------------------

/// The test plan's constants: MOTOR_MAX_TORQUE 260, POWER_THRESHOLD 90 (in the plan's own
/// units, compared with voltage x current), SOC_START 0.2, SOC_END 0.05.
const PLAN: PowerLimits = PowerLimits {
    max_torque_nm: 260.0,
    power_limit_w: 90.0,
    power_target_w: 90.0,
    soc_derate: (0.2, 0.05),
};

#[test]
fn power_limit_case_1_base_case_passes_the_demand() {
    assert_eq!(PLAN.soc_limited(0.25, 200.0), 200.0);
}

#[test]
fn power_limit_case_2_clamps_to_the_motor_maximum() {
    assert_eq!(PLAN.soc_limited(0.25, 270.0), 260.0);
}

/// Deviation from the plan: case 3 scales the demand by threshold / measured power (40 V x
/// 3 A = 120 > 90, so 200 -> 150). Measured power is produced by the previous, already
/// limited command, so in closed loop that scaling settles near sqrt(demand x limit): with
/// the car's 80 kW it held 89 / 100 / 115 kW at 3,300 / 4,000 / 5,000 rpm (EV.3.3.1 broken).
/// The CCM instead limits with a torque ceiling from the motor speed, trimmed by the measured
/// power (`power.rs`); the car model proves it holds in closed loop
/// (`car-model/tests/power_limit.rs`). Here: the same measured power no longer scales an
/// instantaneous demand; the ceiling at the lowest efficiency keeps P <= target at any speed.
#[test]
fn power_limit_case_3_deviation_the_ceiling_comes_from_speed_not_from_the_last_measurement() {
    let mut limiter = PowerLimiter::new(10, PowerLimits::CAR.power_target_w);
    let motor_rad_s = 400.0;
    // 200 Nm at 400 rad/s is 80 kW of shaft power: above what the target allows.
    let ceiling = limiter.step(
        Calibration::DEFAULT.power_trim_gain,
        motor_rad_s,
        120.0,
        200.0,
    );
    let (lowest, _) = aer_ccm::constants::DRIVETRAIN_EFFICIENCY;
    let target = PowerLimits::CAR.power_target_w;
    assert!(
        (ceiling - lowest * target / motor_rad_s).abs() < 1e-3,
        "{ceiling}"
    );
    assert!(ceiling * motor_rad_s / lowest <= target + 1.0);
}

#[test]
fn power_limit_case_4_derates_with_soc() {
    assert!((PLAN.soc_limited(0.1, 200.0) - 66.67).abs() < 0.01);
}

#[test]
fn power_limit_case_5_is_zero_at_the_end_of_derating() {
    assert_eq!(PLAN.soc_limited(0.05, 200.0), 0.0);
}

// --- Launch control --------------------------------------------------------------------------

fn inputs(front: (f32, f32), driven: f32, torque: f32, brakes_engaged: bool) -> LaunchInputs {
    LaunchInputs {
        button: true,
        brakes_engaged,
        pedal: torque / 260.0,
        front_rad_s: front,
        driven_rad_s: driven,
        driver_torque_nm: torque,
    }
}

/// Launch control armed (brakes engaged, motor stopped, button), brakes released and the
/// pedal pressed.
fn active() -> LaunchControl {
    let mut launch = LaunchControl::new(10);
    launch.step(&Calibration::DEFAULT, &inputs((0.0, 0.0), 0.0, 0.0, true));
    launch.step(
        &Calibration::DEFAULT,
        &inputs((0.0, 0.0), 0.0, 130.0, false),
    );
    assert_eq!(launch.state(), LaunchState::Active);
    launch
}

#[test]
fn launch_case_1_brake_held_at_standstill_turns_launch_on() {
    let mut launch = LaunchControl::new(10);
    launch.step(&Calibration::DEFAULT, &inputs((0.0, 0.0), 0.0, 0.0, true));
    assert_eq!(
        launch.state(),
        LaunchState::Armed,
        "ON, waiting for the brake release"
    );
}

#[test]
fn launch_case_2_no_slip_barely_changes_the_torque() {
    let mut launch = active();
    let torque = launch.step(
        &Calibration::DEFAULT,
        &inputs((80.0, 82.0), 80.0, 150.0, false),
    );
    assert!(launch.slip().abs() <= 0.02, "slip {}", launch.slip());
    assert_eq!(torque, 150.0, "unchanged");
    assert_eq!(launch.state(), LaunchState::Active);
}

#[test]
fn launch_case_3_very_high_slip_takes_the_torque_to_near_zero() {
    let mut launch = active();
    let torque = launch.step(
        &Calibration::DEFAULT,
        &inputs((40.0, 42.0), 100.0, 200.0, false),
    );
    assert!(launch.slip() > 1.4, "slip {}", launch.slip());
    assert!(torque < 5.0, "{torque}");
}

/// Deviation from the plan: case 4 expects the PID to add torque above the driver's 250 Nm
/// (up to 260) when slip is below the target. Adding torque is what kept the car pushing
/// with the pedal released (74 Nm for 10 s after a launch, issue 12); launch control now
/// only takes torque away, so the driver's 250 Nm passes unchanged.
#[test]
fn launch_case_4_deviation_slip_below_target_never_adds_torque() {
    let mut launch = active();
    let torque = launch.step(
        &Calibration::DEFAULT,
        &inputs((100.0, 99.0), 100.0, 250.0, false),
    );
    assert!(launch.slip() < 0.07);
    assert_eq!(torque, 250.0);
}

#[test]
fn launch_case_5_brake_ends_launch_and_resets_the_pid() {
    let mut launch = active();
    for _ in 0..20 {
        launch.step(
            &Calibration::DEFAULT,
            &inputs((40.0, 42.0), 100.0, 200.0, false),
        );
    }
    let torque = launch.step(
        &Calibration::DEFAULT,
        &inputs((40.0, 42.0), 100.0, 0.9 * 260.0, true),
    );
    assert_eq!(launch.state(), LaunchState::Off);
    assert_eq!(torque, 0.9 * 260.0, "torque = raw input");
    // Re-armed, the controller starts from zero: the first correction equals a fresh one's.
    let mut fresh = active();
    let mut reused = launch;
    reused.step(&Calibration::DEFAULT, &inputs((0.0, 0.0), 0.0, 0.0, true));
    reused.step(
        &Calibration::DEFAULT,
        &inputs((0.0, 0.0), 0.0, 130.0, false),
    );
    let step = inputs((40.0, 42.0), 50.0, 150.0, false);
    assert_eq!(
        reused.step(&Calibration::DEFAULT, &step),
        fresh.step(&Calibration::DEFAULT, &step)
    );
}

#[test]
fn launch_ends_when_the_pedal_drops_below_5_percent() {
    let mut launch = active();
    launch.step(
        &Calibration::DEFAULT,
        &inputs((80.0, 82.0), 80.0, 150.0, false),
    );
    let torque = launch.step(
        &Calibration::DEFAULT,
        &inputs((80.0, 82.0), 80.0, 10.0, false),
    );
    assert_eq!(launch.state(), LaunchState::Off, "3.8 % pedal");
    assert_eq!(torque, 10.0);
}

#[test]
fn launch_reduction_state_persists_between_steps() {
    // Fixed defect: with the PID rebuilt every step the correction would never grow.
    let mut launch = active();
    let step = inputs((80.0, 82.0), 100.0, 200.0, false);
    let first = launch.step(&Calibration::DEFAULT, &step);
    let second = launch.step(&Calibration::DEFAULT, &step);
    assert!(second < first, "{first} -> {second}");
}

// --- Shock travel ----------------------------------------------------------------------------

/// The travel a sensor with the schema's default calibration (5.00 V extended, 4.86 V
/// compressed: the team's 0.14 V span) reads.
fn travel_mm(raw: u16) -> f32 {
    let nominal = Calibration::DEFAULT;
    shock_travel_mm(
        raw,
        nominal.shock_extended_v[0],
        nominal.shock_compressed_v[0],
    )
}

/// A sensor whose calibrated ends differ from the team's reads zero at its own extension and
/// full travel at its own compression, either way round.
#[test]
fn shock_a_calibrated_sensor_reads_its_own_ends() {
    for (extended_v, compressed_v) in [(4.9, 4.75), (1.2, 3.8)] {
        let at = |volts: f32| shock_travel_mm(shock_raw_for_volts(volts), extended_v, compressed_v);
        assert!(at(extended_v) < 0.1, "{extended_v}");
        let half = at((extended_v + compressed_v) / 2.0);
        assert!((half - 0.5 * SHOCK_TRAVEL_MAX_MM).abs() < 0.5, "{half}");
        assert!((at(compressed_v) - SHOCK_TRAVEL_MAX_MM).abs() < 0.5);
    }
    // Ends closer than the minimum span are no calibration: 0, not a huge gain.
    assert_eq!(shock_travel_mm(shock_raw_for_volts(4.9), 4.95, 4.94), 0.0);
}

#[test]
fn shock_case_2_fully_extended_is_zero() {
    assert_eq!(travel_mm(4095), 0.0);
}

#[test]
fn shock_case_3_half_the_span_is_half_the_travel() {
    let travel = travel_mm(shock_raw_for_volts(4.93));
    assert!((travel - 0.5 * SHOCK_TRAVEL_MAX_MM).abs() < 0.5, "{travel}");
}

#[test]
fn shock_case_4_full_compression_is_full_travel() {
    let travel = travel_mm(shock_raw_for_volts(4.86));
    assert!((travel - SHOCK_TRAVEL_MAX_MM).abs() < 0.5, "{travel}");
}

#[test]
fn shock_case_5_beyond_the_span_is_clamped() {
    assert_eq!(travel_mm(shock_raw_for_volts(4.0)), SHOCK_TRAVEL_MAX_MM);
    assert_eq!(travel_mm(0), SHOCK_TRAVEL_MAX_MM);
}

// --- Wheel speed -----------------------------------------------------------------------------

#[test]
fn wheel_speed_is_60e6_over_dt_times_teeth_and_zero_after_half_a_second() {
    let mut wheel = WheelSpeed::new(24);
    assert_eq!(wheel.rpm(0), 0.0);
    wheel.on_pulse(1_000);
    assert_eq!(wheel.rpm(1_500), 0.0, "one pulse is no period");
    wheel.on_pulse(3_500); // dt 2,500 us
    assert!((wheel.rpm(3_600) - 1_000.0).abs() < 1e-3);
    assert!(wheel.rpm(3_500 + 500_000) > 0.0, "at 0.5 s");
    assert_eq!(wheel.rpm(3_500 + 500_001), 0.0, "after 0.5 s");
}

// --- Watchdog ----------------------------------------------------------------------------------

#[test]
fn watchdog_is_fed_only_while_every_task_beat_within_100_ms() {
    let mut supervisor = Supervisor::default();
    assert_eq!(supervisor.overdue(0), 0b1111, "nothing has run yet");
    for task in Task::ALL {
        supervisor.beat(task, 1_000);
    }
    assert_eq!(supervisor.overdue(1_100), 0, "at 100 ms");
    supervisor.beat(Task::Control, 1_100);
    supervisor.beat(Task::Inverter, 1_100);
    supervisor.beat(Task::Telemetry, 1_100);
    assert_eq!(
        supervisor.overdue(1_101),
        1 << Task::Sensors as u8,
        "sensors overdue"
    );
}
