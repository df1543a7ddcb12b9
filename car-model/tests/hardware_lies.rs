//! The first HV day's hardware lies, in closed loop: each single fault of the PCC's own
//! sensing or of the circuit it switches, through the real measurement chain (pulse trains
//! into the V/F channels, thermistor counts into the PCC's conversion) and the real state
//! machine, with the CCM driving. Each asserts what the PCC decides, what it names, that AIR+
//! stays open where it must, that nothing hands the chip over while the tractive system may be
//! live, and that the rules hold throughout.

use aer_car_model::chassis::Mode;
use aer_car_model::driver::Cycle;
use aer_car_model::faults::{Fault, FaultPlan, Injection};
use aer_car_model::{ClosedLoop, ModelParams, NoTap};
use aer_pcc::machine::Converter;
use aer_pcc::{HandoverRefusal, State};
use std::sync::OnceLock;

/// The comp car driving the skidpad after its start-up, shared by every case.
fn driving() -> ClosedLoop {
    static STARTED: OnceLock<ClosedLoop> = OnceLock::new();
    STARTED
        .get_or_init(|| {
            let mut run = ClosedLoop::new(
                ModelParams::NOMINAL,
                Mode::Road,
                Cycle::Skidpad,
                FaultPlan::NONE,
            );
            assert!(run.start_up(20_000));
            run.run_until(run.now_ms() + 3_000, &mut NoTap);
            assert_eq!(run.car.pcc.state(), State::Online);
            run
        })
        .clone()
}

/// `run` with `faults` planned as (fault, from, until) relative to now.
fn plan(run: &mut ClosedLoop, faults: &[(Fault, u32, u32)]) -> u32 {
    let now = run.now_ms();
    let plan = faults
        .iter()
        .fold(FaultPlan::NONE, |plan, &(fault, from, until)| {
            plan.with(Injection {
                fault,
                from_ms: now + from,
                until_ms: until.saturating_add(now),
            })
        });
    run.retune(run.car.params, plan);
    now
}

fn assert_rules_hold(run: &ClosedLoop, what: &str) {
    assert_eq!(
        run.rules.first_violation(),
        None,
        "{what}: {} violations",
        run.rules.violations()
    );
}

#[test]
fn a_converter_wire_breaking_at_high_voltage_latches_its_own_fault_and_the_pcc_trusts_nothing() {
    for (index, converter) in Converter::BOTH.into_iter().enumerate() {
        let mut run = driving();
        // The wire breaks one second from now and touches again ten seconds later.
        let t0 = plan(&mut run, &[(Fault::ConverterSilent(index), 1_000, 11_000)]);
        let broke = t0 + 1_000;
        run.run_until(broke, &mut NoTap);
        let mut latched_at = None;
        let mut standby_seen = false;
        let mut precharge_seen = false;
        let mut air_plus_after = false;
        while run.now_ms() < t0 + 20_000 {
            run.step(&mut NoTap);
            let pcc = &run.car.pcc;
            let silent = pcc.logic.silences()[index];
            if latched_at.is_none() && silent.is_some() {
                latched_at = Some(run.now_ms());
            }
            if latched_at.is_some() {
                standby_seen |= pcc.state() == State::Standby;
                precharge_seen |= pcc.state() == State::Precharge;
                air_plus_after |= pcc.relays().air_plus;
                // While the tractive system is live and unknown, nothing hands over.
                if run.car.pcc.plant.tractive_v >= 60.0 {
                    assert!(
                        pcc.logic.handover().is_err(),
                        "{converter:?}: handed over at {} ms with {:.0} V live",
                        run.now_ms(),
                        pcc.plant.tractive_v
                    );
                }
            }
        }
        let latched_at = latched_at.expect("the silence latches");
        // Silent for the 100 ms edge timeout, then latched at the next 10 ms step.
        assert!(
            latched_at - broke <= 120,
            "{converter:?}: latched {} ms after the break",
            latched_at - broke
        );
        let pcc = &run.car.pcc;
        let silence = pcc.logic.silences()[index].expect("latched");
        assert_eq!(silence.converter, converter);
        assert!(
            silence.last_v > 250.0,
            "{converter:?}: it names what it read before: {silence:?}"
        );
        assert_eq!(pcc.state(), State::Error, "{converter:?}");
        assert!(
            !standby_seen,
            "{converter:?}: never back to STANDBY by itself"
        );
        assert!(
            !precharge_seen,
            "{converter:?}: the wire touching again starts nothing"
        );
        assert!(!air_plus_after, "{converter:?}: AIR+ never closes again");
        let errors = pcc.logic.errors();
        assert!(
            match converter {
                Converter::Accumulator => errors.accumulator_silent,
                Converter::Tractive => errors.tractive_silent,
            },
            "{errors}"
        );
        // On the bus: PCC_Status carries the latched cause.
        let status = pcc.logic.status();
        assert!(status.pcc_error_accumulator_silent || status.pcc_error_tractive_silent);
        // The wire touches again: both converters alive, but the pack reads 300 V, so the
        // chip is still not handed over: that takes the pack disconnected (the bench supply
        // on both sense inputs) or a power cycle.
        assert!(
            matches!(
                pcc.logic.handover(),
                Err(HandoverRefusal::ConverterFault { .. })
            ),
            "{:?}",
            pcc.logic.handover()
        );
        assert_rules_hold(&run, &format!("{converter:?} silent"));
        assert_eq!(
            run.last_outputs().torque.torque_nm,
            0.0,
            "{converter:?}: no torque with the PCC in ERROR"
        );
    }
}

#[test]
fn a_welded_air_plus_goes_unseen_at_shutdown_and_is_named_at_the_next_closure() {
    let mut run = driving();
    // AIR+ welds; the shutdown circuit opens for 3 s (an e-stop), then closes again.
    let t0 = plan(
        &mut run,
        &[
            (Fault::AirPlusWelded, 0, u32::MAX),
            (Fault::ShutdownOpen, 1_000, 4_000),
        ],
    );
    run.run_until(t0 + 3_900, &mut NoTap);
    // With AIR- open the tractive system discharged as it should: the PCC cannot tell a
    // welded AIR+ from a good one (the sheet's weld check before every re-closure can).
    assert_eq!(run.car.pcc.state(), State::Standby);
    assert_eq!(run.car.pcc.logic.errors().to_string(), "none");
    // The circuit closes: the pack reaches the tractive system at once, without the
    // resistor.
    let mut error_at = None;
    while run.now_ms() < t0 + 6_000 {
        run.step(&mut NoTap);
        assert!(
            !run.car.pcc.relays().air_plus,
            "the PCC never commands AIR+ on a bypassed precharge"
        );
        if error_at.is_none() && run.car.pcc.state() == State::Error {
            error_at = Some(run.now_ms());
        }
    }
    let error_at = error_at.expect("the closure is refused");
    assert!(
        error_at - (t0 + 4_000) <= 40,
        "named {} ms after the closure",
        error_at - (t0 + 4_000)
    );
    let errors = run.car.pcc.logic.errors();
    assert!(errors.too_fast && errors.bypassed, "{errors}");
    let rise = run.car.pcc.logic.bypass_rise().expect("the rise is named");
    assert!(rise.to_percent - rise.from_percent >= 20.0, "{rise:?}");
    let line = aer_pcc::console::BypassLine { now_ms: 0, rise }.to_string();
    assert!(
        line.contains("AIR+ welded"),
        "the log names the likely cause: {line}"
    );
    assert!(run.car.pcc.logic.status().pcc_error_bypassed);
    // Latched: the PCC stays in ERROR however long the circuit stays closed.
    run.run_until(t0 + 20_000, &mut NoTap);
    assert_eq!(run.car.pcc.state(), State::Error);
    assert_rules_hold(&run, "AIR+ welded");
}

#[test]
fn a_tractive_system_that_does_not_discharge_latches_no_discharge() {
    let mut run = driving();
    // The discharge circuit has failed (only the inverter's bleeder is left); the shutdown
    // circuit opens and stays open.
    let t0 = plan(
        &mut run,
        &[
            (Fault::DischargeFailed, 0, u32::MAX),
            (Fault::ShutdownOpen, 1_000, u32::MAX),
        ],
    );
    run.run_until(t0 + 30_000, &mut NoTap);
    let pcc = &run.car.pcc;
    assert_eq!(pcc.state(), State::Error);
    let errors = pcc.logic.errors();
    assert!(errors.no_discharge, "{errors}");
    let fault = pcc.logic.no_discharge().expect("named");
    assert!(
        fault.tractive_v >= 60.0 && fault.limit_ms == 5_000,
        "{fault:?}"
    );
    // Still live: nothing hands over.
    assert!(pcc.plant.tractive_v > 60.0);
    assert!(pcc.logic.handover().is_err());
    assert!(pcc.logic.status().pcc_error_no_discharge);
    assert_rules_hold(&run, "discharge failed");

    // The same shutdown with a working discharge circuit latches nothing.
    let mut run = driving();
    let t0 = plan(&mut run, &[(Fault::ShutdownOpen, 1_000, u32::MAX)]);
    run.run_until(t0 + 30_000, &mut NoTap);
    assert_eq!(run.car.pcc.state(), State::Standby);
    assert_eq!(run.car.pcc.logic.errors().to_string(), "none");
    assert!(run.car.pcc.logic.handover().is_ok());
}

#[test]
fn a_stalled_precharge_heats_the_resistor_to_a_latched_fault() {
    // A load across the tractive system from power-up: the precharge stalls at half the
    // pack, latches too-slow, and the closed shutdown circuit keeps heating the resistor.
    let mut run = ClosedLoop::new(
        ModelParams::NOMINAL,
        Mode::Road,
        Cycle::Skidpad,
        FaultPlan::NONE.with(Injection {
            fault: Fault::TractiveLoad,
            from_ms: 0,
            until_ms: u32::MAX,
        }),
    );
    let mut hot_at = None;
    while run.now_ms() < 400_000 && hot_at.is_none() {
        run.step(&mut NoTap);
        assert!(!run.car.pcc.relays().air_plus, "AIR+ never closes");
        if run.car.pcc.logic.errors().resistor_hot {
            hot_at = Some(run.now_ms());
        }
    }
    let hot_at = hot_at.expect("the resistor's limit latches");
    let errors = run.car.pcc.logic.errors();
    assert!(errors.too_slow && errors.resistor_hot, "{errors}");
    let hot = run.car.pcc.logic.hot_resistor().expect("named");
    assert!(hot.celsius >= 69.0 && hot.celsius < 70.0, "{hot:?}");
    assert!(
        (run.car.pcc.plant.resistor.celsius - hot.celsius).abs() < 1.0,
        "the thermistor reads the resistor through the PCC's conversion"
    );
    let thermal = run.car.pcc.logic.thermal();
    assert!(thermal.pcc_resistor_temp1_valid && thermal.pcc_resistor_temp1 >= 69.0);
    assert!(run.car.pcc.logic.status().pcc_error_resistor_hot);
    println!("resistor at its limit {hot_at} ms after power-up");
    assert_rules_hold(&run, "stalled precharge");
}

#[test]
fn an_open_thermistor_is_no_reading_not_a_cold_resistor() {
    let mut run = driving();
    let t0 = plan(&mut run, &[(Fault::ThermistorOpen(0), 0, u32::MAX)]);
    run.run_until(t0 + 1_000, &mut NoTap);
    let pcc = &run.car.pcc;
    let [first, second] = pcc.logic.resistor_c();
    assert_eq!(first, None, "open: no reading");
    assert!(second.is_some());
    let thermal = pcc.logic.thermal();
    assert!(!thermal.pcc_resistor_temp1_valid && thermal.pcc_resistor_temp2_valid);
    // Unknown latches nothing: the car drives on (the console says the protection is off).
    assert_eq!(pcc.state(), State::Online);
    assert_rules_hold(&run, "thermistor open");
}

#[test]
fn a_late_bms_leaves_the_hardware_precharge_untimed_and_air_plus_open() {
    // The BMS is silent for the first 15 s: the shutdown circuit is closed from power-up, so
    // the hardware precharges while the PCC cannot time it.
    let mut run = ClosedLoop::new(
        ModelParams::NOMINAL,
        Mode::Road,
        Cycle::Skidpad,
        FaultPlan::NONE.with(Injection {
            fault: Fault::BmsSilent,
            from_ms: 0,
            until_ms: 15_000,
        }),
    );
    let mut live_waiting = false;
    while run.now_ms() < 30_000 {
        run.step(&mut NoTap);
        let pcc = &run.car.pcc;
        assert!(
            !pcc.relays().air_plus,
            "an untimed precharge never closes AIR+"
        );
        assert_ne!(pcc.state(), State::Online);
        live_waiting |= pcc.logic.waiting().is_some_and(|waiting| waiting.live);
    }
    assert!(
        live_waiting,
        "STANDBY says the tractive system charged while the PCC could not time it"
    );
    assert_rules_hold(&run, "BMS late");
}

/// The longest the shaft keeps any torque after the CCM fails at `fault`'s start, with the
/// DTI's own command timeout left disabled (ms); `None` while it still turns torque at the
/// end of the window.
fn torque_after_ccm_failure(fault: Fault) -> (Option<u32>, ClosedLoop) {
    let mut run = driving();
    // Full throttle on the skidpad: torque flows when the CCM fails.
    let t0 = plan(
        &mut run,
        &[(Fault::InverterTimeoutOff, 0, u32::MAX), (fault, 500, 600)],
    );
    run.run_until(t0 + 500, &mut NoTap);
    assert!(
        run.car.inverter.torque_nm > 5.0,
        "torque flows before the failure: {}",
        run.car.inverter.torque_nm
    );
    let failed = t0 + 500;
    let mut last_torque = None;
    while run.now_ms() < failed + 3_000 {
        run.step(&mut NoTap);
        if run.car.inverter.torque_nm > 0.1 {
            last_torque = Some(run.now_ms() - failed);
        }
    }
    (last_torque, run)
}

#[test]
fn a_ccm_panic_stops_torque_within_100_ms_whatever_the_dti_is_set_to() {
    // The panic handler sends the stop frames the control task last published, then resets.
    let (torque_until, run) = torque_after_ccm_failure(Fault::CcmPanic);
    let torque_until = torque_until.expect("torque flowed at the panic");
    assert!(
        torque_until <= 100,
        "torque for {torque_until} ms after the panic"
    );
    assert!(!run.car.inverter.enabled(run.now_ms()), "drive disabled");
    assert!(!run.ccm_is_down(), "the CCM runs again after its reset");
    assert_rules_hold(&run, "CCM panic");

    // The same CCM hanging instead (no panic handler runs): the DTI, without its timeout,
    // holds the last current until the watchdog's reset and the restart: this is what the
    // panic handler's frames are for.
    let (torque_until, _) = torque_after_ccm_failure(Fault::CcmHang);
    let torque_until = torque_until.expect("torque held");
    assert!(
        torque_until >= 1_000,
        "a hang holds torque until the watchdog: {torque_until} ms"
    );
}

#[test]
fn a_shutdown_circuit_that_bounces_never_connects_the_pack_below_the_precharge_target() {
    // A connector that bounces over a kerb: the shutdown circuit open for a few to a few
    // hundred milliseconds, then closed again. AIR+ must be open again before it closes onto
    // a tractive system the precharge target would not accept.
    for open_ms in [5u32, 10, 20, 30, 40, 50, 60, 80, 100, 150, 200, 400] {
        let mut run = driving();
        let before = run.car.pcc.closures;
        let t0 = plan(&mut run, &[(Fault::ShutdownOpen, 1_000, 1_000 + open_ms)]);
        run.run_until(t0 + 20_000, &mut NoTap);
        let closures = run.car.pcc.closures;
        if closures.count > before.count {
            let lowest = closures.lowest_percent.expect("a closure");
            assert!(
                lowest >= 90.0,
                "open {open_ms} ms: the pack connected onto {lowest:.1} % of it"
            );
        }
        assert_rules_hold(&run, &format!("shutdown bounce of {open_ms} ms"));
    }
}

#[test]
fn a_welded_air_plus_under_a_closure_of_a_few_milliseconds_is_named_all_the_same() {
    // A chattering shutdown contact with AIR+ welded: closed for 5 to 20 ms at a time. The
    // pack reaches the tractive system in each, and a rise no resistor allows latches at
    // once, however short the closure.
    for closed_ms in [5u32, 10, 15, 20] {
        let mut run = driving();
        let t0 = plan(
            &mut run,
            &[
                (Fault::AirPlusWelded, 0, u32::MAX),
                (Fault::ShutdownOpen, 1_000, 4_000),
                (Fault::ShutdownOpen, 4_000 + closed_ms, u32::MAX),
            ],
        );
        run.run_until(t0 + 6_000, &mut NoTap);
        let errors = run.car.pcc.logic.errors();
        assert!(
            errors.bypassed,
            "closed {closed_ms} ms: {errors} ({:?})",
            run.car.pcc.state()
        );
        assert_rules_hold(&run, &format!("AIR+ welded, closed {closed_ms} ms"));
    }
}

#[test]
fn air_plus_that_never_closes_is_named_and_no_torque_flows() {
    // AIR+'s coil is dead: the PCC commands it closed at 90 %, the tractive system stays
    // where the precharge resistor holds it.
    let plan = FaultPlan::NONE.with(Injection {
        fault: Fault::AirPlusStuckOpen,
        from_ms: 0,
        until_ms: u32::MAX,
    });
    let mut run = ClosedLoop::new(ModelParams::NOMINAL, Mode::Road, Cycle::Skidpad, plan);
    assert!(
        !run.start_up(20_000),
        "the car never becomes ready to drive"
    );
    run.run_until(run.now_ms() + 10_000, &mut NoTap);
    let errors = run.car.pcc.logic.errors();
    assert!(errors.air_plus_open, "{errors}");
    assert!(
        !errors.no_discharge,
        "held up through the resistor: {errors}"
    );
    assert!(!run.car.pcc.relays().air_plus, "AIR+ released");
    assert_eq!(run.car.pcc.state(), State::Error);
    assert_rules_hold(&run, "AIR+ stuck open");
}
