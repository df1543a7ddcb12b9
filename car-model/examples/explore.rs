use aer_car_model::chassis::Mode;
use aer_car_model::driver::Cycle;
use aer_car_model::faults::FaultPlan;
use aer_car_model::{ClosedLoop, ModelParams, NoTap};

fn main() {
    let cycle = match std::env::args().nth(1).as_deref() {
        Some("skidpad") => Cycle::Skidpad,
        Some("autocross") => Cycle::Autocross,
        Some("full") => Cycle::FullThrottle,
        _ => Cycle::Acceleration,
    };
    let mode = match std::env::args().nth(2) {
        Some(rpm) => Mode::Dyno {
            rpm: rpm.parse().unwrap(),
        },
        None => Mode::Road,
    };
    let efficiency = std::env::var("EFF")
        .map(|e| e.parse().unwrap())
        .unwrap_or(0.91);
    let lag = std::env::var("LAG")
        .map(|e| e.parse().unwrap())
        .unwrap_or(10.0);
    let params = ModelParams {
        efficiency,
        measurement_lag_ms: lag,
        ..ModelParams::NOMINAL
    };
    let mut run = ClosedLoop::new(params, mode, cycle, FaultPlan::NONE);
    let mut last_state = None;
    for t in 1..=30_000u32 {
        run.step(&mut NoTap);
        let out = run.last_outputs();
        if last_state != Some((out.vehicle.state, out.faults.bits())) {
            last_state = Some((out.vehicle.state, out.faults.bits()));
            println!(
                "t={t} state={:?} faults={:#x} pcc={:?}",
                out.vehicle.state,
                out.faults.bits(),
                run.car.pcc.state()
            );
        }
        let window = std::env::var("WINDOW").ok().map(|w| {
            let (a, b) = w.split_once('-').unwrap();
            (a.parse::<u32>().unwrap(), b.parse::<u32>().unwrap())
        });
        let show = match window {
            Some((a, b)) => t >= a && t <= b && t % 10 == 0,
            None => t % 250 == 0 && t > 9_000,
        };
        if show {
            println!(
                "t={t} v={:.1} m/s d={:.1} m rpm={:.0} cmd={:.1} allowed={:.1} ceil={:.1} P={:.1} kW eff_est={:.3} slip={:.3} launch={:?} pedal={:.2} brake={:.0} apps={:?}",
                run.car.chassis.speed_m_s,
                run.car.chassis.distance_m,
                run.car.chassis.motor_rpm(),
                out.torque.torque_nm,
                out.torque.allowed_nm,
                out.torque.power_ceiling_nm,
                run.car.power_w / 1000.0,
                run.ccm.torque_path().power_limiter().efficiency(),
                run.car.chassis.slip,
                out.torque.launch,
                run.car.command.pedal,
                run.car.command.brake_psi,
                run.ccm.apps()
            );
        }
    }
    println!("stats {:?}", run.rules.stats());
    println!(
        "violations {} first {:?}",
        run.rules.violations(),
        run.rules.first_violation()
    );
}
