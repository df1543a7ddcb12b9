//! Every transition of the precharge state machine, and every timing limit probed just before
//! and just after it.

use aer_pcc::measurement::Pulses;
use aer_pcc::{Errors, Inputs, Precharge, PrechargeConfig, Relays, State};

const CONFIG: PrechargeConfig = PrechargeConfig::CAR;
const PACK_V: f32 = 400.0;

/// A test bench: the PCC plus the inputs the firmware would measure.
struct Bench {
    pcc: Precharge,
    inputs: Inputs,
}

impl Bench {
    /// Powered up at `start_ms` with everything ready to precharge, BMS frame just received.
    fn ready_at(start_ms: u32) -> Self {
        Self {
            pcc: Precharge::new(CONFIG, start_ms),
            inputs: Inputs {
                now_ms: start_ms,
                accumulator_v: PACK_V,
                tractive_v: 0.0,
                raw_v: [PACK_V, 0.0],
                bms_last_seen_ms: Some(start_ms),
                charger_safety: false,
                pulses: [Pulses::Live; 2],
                resistor_c: [Some(25.0); 2],
            },
        }
    }

    fn ready() -> Self {
        Self::ready_at(1_000)
    }

    fn at(&mut self, now_ms: u32) -> Relays {
        self.inputs.now_ms = now_ms;
        // Steady readings: each window's own equals the filtered one.
        self.inputs.raw_v = [self.inputs.accumulator_v, self.inputs.tractive_v];
        self.pcc.step(&self.inputs)
    }

    /// Steps to `now_ms` keeping the BMS heartbeat fresh.
    fn at_with_bms(&mut self, now_ms: u32) -> Relays {
        self.inputs.bms_last_seen_ms = Some(now_ms);
        self.at(now_ms)
    }

    fn state(&self) -> State {
        self.pcc.state()
    }

    fn set_progress(&mut self, percent: f32) {
        self.inputs.tractive_v = PACK_V * percent / 100.0;
    }

    /// Runs STANDBY -> PRECHARGE (the hardware starts precharging as the settle time ends);
    /// returns the time precharge started.
    fn start_precharge(&mut self) -> u32 {
        let t0 = self.inputs.now_ms;
        self.at_with_bms(t0);
        let start = t0.wrapping_add(CONFIG.standby_settle_ms);
        self.set_progress(CONFIG.start_percent);
        self.at_with_bms(start);
        assert_eq!(self.state(), State::Precharge);
        start
    }

    /// Runs a clean precharge reaching the target at `reached_after` ms; returns the time the
    /// hold completed.
    fn precharge_reaching_target_after(&mut self, reached_after: u32) -> u32 {
        let start = self.start_precharge();
        self.set_progress(50.0);
        self.at_with_bms(start.wrapping_add(reached_after / 2));
        self.set_progress(CONFIG.target_percent);
        let reached = start.wrapping_add(reached_after);
        self.at_with_bms(reached);
        let done = reached.wrapping_add(CONFIG.target_hold_ms);
        self.at_with_bms(done);
        // AIR+ closed joins the two: the tractive system reads the pack.
        if matches!(self.state(), State::Online | State::Charging) {
            self.set_progress(100.0);
        }
        done
    }

    /// A bench in `energised` (PRECHARGE, ONLINE or CHARGING); returns the time it got there.
    fn in_state(energised: State) -> (Self, u32) {
        let mut bench = Self::ready();
        bench.inputs.charger_safety = energised == State::Charging;
        let now = if energised == State::Precharge {
            bench.start_precharge()
        } else {
            bench.precharge_reaching_target_after(CONFIG.min_time_ms)
        };
        assert_eq!(bench.state(), energised);
        (bench, now)
    }

    fn online(&mut self) -> u32 {
        let done = self.precharge_reaching_target_after(CONFIG.min_time_ms + 100);
        assert_eq!(self.state(), State::Online);
        done
    }
}

/// During precharge AIR+ stays open: the hardware charges through the resistor.
const PRECHARGING: Relays = Relays::ALL_OPEN;
const CONNECTED: Relays = Relays { air_plus: true };

#[test]
fn reset_is_standby_with_air_plus_open() {
    let pcc = Precharge::new(CONFIG, 0);
    assert_eq!(pcc.state(), State::Standby);
    assert_eq!(pcc.relays(), Relays::ALL_OPEN);
    assert_eq!(pcc.errors(), Errors::default());
}

#[test]
fn standby_starts_precharge_at_the_first_rise() {
    let mut bench = Bench::ready();
    assert_eq!(bench.at_with_bms(1_000), Relays::ALL_OPEN);
    bench.set_progress(CONFIG.start_percent - 0.01);
    bench.at_with_bms(1_010);
    assert_eq!(bench.state(), State::Standby, "just below the rise");
    bench.set_progress(CONFIG.start_percent);
    assert_eq!(bench.at_with_bms(1_020), PRECHARGING, "at the rise");
    assert_eq!(bench.state(), State::Precharge);
}

#[test]
fn standby_starts_precharge_only_once_the_tractive_system_rises() {
    // The shutdown circuit is open: the hardware does not precharge, the PCC waits (no
    // too-slow error for a car that is simply switched off).
    let mut bench = Bench::ready();
    bench.at_with_bms(1_000);
    bench.at_with_bms(60_000);
    assert_eq!(bench.state(), State::Standby);
    bench.set_progress(CONFIG.start_percent - 0.01);
    bench.at_with_bms(60_010);
    assert_eq!(bench.state(), State::Standby, "just below the start");
    bench.set_progress(CONFIG.start_percent);
    assert_eq!(bench.at_with_bms(60_020), PRECHARGING);
    assert_eq!(bench.state(), State::Precharge);
    // The timer runs from the rise: the target 1 ms before the minimum time from there is
    // too fast.
    bench.set_progress(CONFIG.target_percent);
    bench.at_with_bms(60_020 + CONFIG.min_time_ms - 1);
    bench.at_with_bms(60_020 + CONFIG.min_time_ms - 1 + CONFIG.target_hold_ms);
    assert!(bench.pcc.errors().too_fast);
    assert_eq!(bench.pcc.relays(), Relays::ALL_OPEN);
}

#[test]
fn a_tractive_system_still_discharging_is_not_a_precharge_start() {
    // Back in STANDBY after a shutdown error with the tractive system at 50 V and falling:
    // no rise, no precharge; the hardware's new precharge from 10 V is one.
    let mut bench = Bench::ready();
    bench.inputs.tractive_v = 50.0;
    bench.at_with_bms(1_000);
    for (t, volts) in [(1_300, 40.0), (1_600, 25.0), (1_900, 10.0)] {
        bench.inputs.tractive_v = volts;
        bench.at_with_bms(t);
        assert_eq!(bench.state(), State::Standby, "{volts} V, falling");
    }
    bench.inputs.tractive_v = 10.0 + PACK_V * CONFIG.start_percent / 100.0 - 0.01;
    bench.at_with_bms(1_910);
    assert_eq!(bench.state(), State::Standby, "just below the rise");
    bench.inputs.tractive_v = 10.0 + PACK_V * CONFIG.start_percent / 100.0;
    bench.at_with_bms(1_920);
    assert_eq!(bench.state(), State::Precharge);
}

#[test]
fn standby_needs_the_pack_and_a_live_bms_when_the_rise_is_seen() {
    // Pack voltage just below the minimum: no precharge however the tractive system moves.
    let mut bench = Bench::ready();
    bench.inputs.accumulator_v = CONFIG.min_accumulator_v - 0.01;
    bench.at_with_bms(1_000);
    bench.inputs.tractive_v = 30.0;
    bench.at_with_bms(2_000);
    assert_eq!(bench.state(), State::Standby);
    // At the minimum, the rise counts.
    let mut bench = Bench::ready();
    bench.inputs.accumulator_v = CONFIG.min_accumulator_v;
    bench.at_with_bms(1_000);
    bench.inputs.tractive_v = CONFIG.min_accumulator_v * CONFIG.start_percent / 100.0;
    bench.at_with_bms(1_010);
    assert_eq!(bench.state(), State::Precharge);

    // No BMS frame yet, then a stale one: the rise is not a start, and a fresh frame does not
    // make it one (the precharge began untimed); only a rise that begins with the BMS heard
    // starts PRECHARGE.
    let mut bench = Bench::ready();
    bench.inputs.bms_last_seen_ms = None;
    bench.at(1_000);
    bench.set_progress(CONFIG.start_percent);
    bench.at(1_010);
    assert_eq!(bench.state(), State::Standby);
    bench.inputs.bms_last_seen_ms = Some(3_000 - CONFIG.bms_timeout_ms - 1);
    bench.at(3_000);
    assert_eq!(bench.state(), State::Standby);
    bench.at_with_bms(3_010);
    assert_eq!(bench.state(), State::Standby, "a rise the PCC missed");
    bench.set_progress(2.0 * CONFIG.start_percent);
    bench.at_with_bms(3_020);
    assert_eq!(bench.state(), State::Precharge);
}

#[test]
fn reaching_the_target_at_the_minimum_time_goes_online_after_the_hold() {
    let mut bench = Bench::ready();
    let start = bench.start_precharge();
    bench.set_progress(CONFIG.target_percent);
    let reached = start + CONFIG.min_time_ms;
    assert_eq!(bench.at_with_bms(reached), PRECHARGING);
    assert_eq!(
        bench.at_with_bms(reached + CONFIG.target_hold_ms - 1),
        PRECHARGING,
        "1 ms before the hold ends"
    );
    assert_eq!(
        bench.at_with_bms(reached + CONFIG.target_hold_ms),
        CONNECTED
    );
    assert_eq!(bench.state(), State::Online);
    assert_eq!(bench.pcc.errors(), Errors::default());
}

#[test]
fn reaching_the_target_one_ms_before_the_minimum_time_is_too_fast() {
    let mut bench = Bench::ready();
    bench.precharge_reaching_target_after(CONFIG.min_time_ms - 1);
    assert_eq!(bench.state(), State::Error);
    assert_eq!(bench.pcc.relays(), Relays::ALL_OPEN);
    assert!(bench.pcc.errors().too_fast);
    assert!(!bench.pcc.errors().too_slow);
}

#[test]
fn progress_just_below_the_target_does_not_count() {
    let mut bench = Bench::ready();
    let start = bench.start_precharge();
    bench.set_progress(CONFIG.target_percent - 0.01);
    bench.at_with_bms(start + CONFIG.min_time_ms + 500);
    bench.at_with_bms(start + CONFIG.min_time_ms + 600);
    assert_eq!(bench.state(), State::Precharge);
}

#[test]
fn a_dip_below_the_target_restarts_the_hold() {
    let mut bench = Bench::ready();
    let start = bench.start_precharge();
    let reached = start + CONFIG.min_time_ms + 10;
    bench.set_progress(CONFIG.target_percent);
    bench.at_with_bms(reached);
    bench.set_progress(CONFIG.target_percent - 1.0);
    bench.at_with_bms(reached + 10);
    bench.set_progress(CONFIG.target_percent);
    bench.at_with_bms(reached + 15);
    bench.at_with_bms(reached + 30);
    assert_eq!(bench.state(), State::Precharge, "the hold restarted at +15");
    bench.at_with_bms(reached + 35);
    assert_eq!(bench.state(), State::Online);
}

#[test]
fn not_reaching_the_target_is_too_slow_one_ms_after_the_maximum_time() {
    let mut bench = Bench::ready();
    let start = bench.start_precharge();
    bench.set_progress(80.0);
    assert_eq!(bench.at_with_bms(start + CONFIG.max_time_ms), PRECHARGING);
    assert_eq!(bench.state(), State::Precharge, "at the maximum time");
    assert_eq!(
        bench.at_with_bms(start + CONFIG.max_time_ms + 1),
        Relays::ALL_OPEN
    );
    assert_eq!(bench.state(), State::Error);
    assert!(bench.pcc.errors().too_slow);
}

#[test]
fn reaching_the_target_at_the_maximum_time_still_counts_but_after_it_does_not() {
    let mut bench = Bench::ready();
    bench.precharge_reaching_target_after(CONFIG.max_time_ms);
    assert_eq!(bench.state(), State::Online);

    // Sparse steps: below target at max - 10, at target first seen at max + 1.
    let mut bench = Bench::ready();
    let start = bench.start_precharge();
    bench.set_progress(80.0);
    bench.at_with_bms(start + CONFIG.max_time_ms - 10);
    bench.set_progress(CONFIG.target_percent);
    bench.at_with_bms(start + CONFIG.max_time_ms + 1);
    bench.at_with_bms(start + CONFIG.max_time_ms + 1 + CONFIG.target_hold_ms);
    assert_eq!(bench.state(), State::Error);
    assert!(bench.pcc.errors().too_slow);
}

#[test]
fn charger_safety_chooses_charging_and_switches_with_online() {
    let mut bench = Bench::ready();
    bench.inputs.charger_safety = true;
    let done = bench.precharge_reaching_target_after(CONFIG.min_time_ms);
    assert_eq!(bench.state(), State::Charging);
    assert_eq!(bench.pcc.relays(), CONNECTED);
    // The bit must hold its new value for the debounce time before the state follows.
    bench.inputs.charger_safety = false;
    let cleared = done + 10;
    assert_eq!(bench.at_with_bms(cleared), CONNECTED);
    assert_eq!(bench.state(), State::Charging, "not yet");
    bench.at_with_bms(cleared + CONFIG.charger_debounce_ms - 10);
    assert_eq!(bench.state(), State::Charging, "10 ms early");
    assert_eq!(
        bench.at_with_bms(cleared + CONFIG.charger_debounce_ms),
        CONNECTED
    );
    assert_eq!(bench.state(), State::Online);
    bench.inputs.charger_safety = true;
    let set = cleared + CONFIG.charger_debounce_ms + 10;
    bench.at_with_bms(set);
    bench.at_with_bms(set + CONFIG.charger_debounce_ms);
    assert_eq!(bench.state(), State::Charging);
}

#[test]
fn a_flickering_charger_bit_neither_switches_nor_blinds_the_online_watch() {
    let mut bench = Bench::ready();
    let done = bench.online();
    let mut t = done;
    // The bit flips every period: no switch, ever.
    for step in 0..50u32 {
        t += 10;
        bench.inputs.charger_safety = step % 2 == 0;
        bench.at_with_bms(t);
        assert_eq!(bench.state(), State::Online, "at {t}");
    }
    // And the tractive system falling away is still seen at the second low window.
    bench.set_progress(CONFIG.online_min_percent - 1.0);
    for step in 0..2u32 {
        t += 10;
        bench.inputs.charger_safety = step % 2 == 0;
        bench.at_with_bms(t);
    }
    assert_eq!(bench.state(), State::Error);
    assert!(bench.pcc.errors().shutdown);
}

#[test]
fn the_tractive_system_falling_away_releases_air_plus_after_the_hold_in_precharge() {
    let (mut bench, now) = Bench::in_state(State::Precharge);
    // The shutdown circuit opens: AIR- and the precharge path drop out, the tractive system
    // falls away from the pack.
    bench.set_progress(50.0);
    bench.at_with_bms(now + 1);
    bench.set_progress(50.0 - CONFIG.precharge_drop_percent - 0.01);
    bench.at_with_bms(now + 2);
    bench.at_with_bms(now + 1 + CONFIG.target_hold_ms);
    assert_eq!(bench.state(), State::Precharge, "1 ms before the hold ends");
    assert_eq!(
        bench.at_with_bms(now + 2 + CONFIG.target_hold_ms),
        Relays::ALL_OPEN
    );
    assert_eq!(bench.state(), State::Error);
    assert_eq!(
        bench.pcc.errors(),
        Errors {
            shutdown: true,
            ..Errors::default()
        }
    );
}

#[test]
fn online_the_tractive_system_falling_away_releases_air_plus_at_the_second_window() {
    for energised in [State::Online, State::Charging] {
        let (mut bench, now) = Bench::in_state(energised);
        // One window just below the online minimum is noise on a line; two in a row are the
        // shutdown circuit opening (AIR- gone), and AIR+ opens in that step.
        bench.set_progress(CONFIG.online_min_percent - 0.01);
        assert_eq!(bench.at_with_bms(now + 10), CONNECTED, "{energised:?}");
        bench.set_progress(100.0);
        assert_eq!(bench.at_with_bms(now + 20), CONNECTED, "{energised:?}");
        bench.set_progress(CONFIG.online_min_percent - 0.01);
        assert_eq!(bench.at_with_bms(now + 30), CONNECTED, "{energised:?}");
        assert_eq!(
            bench.at_with_bms(now + 40),
            Relays::ALL_OPEN,
            "{energised:?}"
        );
        assert_eq!(bench.state(), State::Error);
        assert_eq!(
            bench.pcc.errors(),
            Errors {
                shutdown: true,
                ..Errors::default()
            }
        );
    }
}

#[test]
fn a_rise_no_resistor_allows_latches_bypassed_at_once() {
    // From rest, the tractive system jumps by more than the allowed points in one window.
    let mut bench = Bench::ready();
    bench.at_with_bms(1_000);
    bench.at_with_bms(1_010);
    bench.set_progress(CONFIG.bypass_rise_percent + 1.0);
    assert_eq!(bench.at_with_bms(1_020), Relays::ALL_OPEN);
    assert_eq!(bench.state(), State::Error);
    let errors = bench.pcc.errors();
    assert!(errors.too_fast && errors.bypassed, "{errors}");
    let rise = bench.pcc.bypass_rise().expect("named");
    assert!(rise.from_percent < 1.0 && rise.to_percent > CONFIG.bypass_rise_percent);
    // Just below the allowed rise in one window is a precharge starting (a fast one).
    let mut bench = Bench::ready();
    bench.at_with_bms(1_000);
    bench.at_with_bms(1_010);
    bench.set_progress(CONFIG.bypass_rise_percent - 1.0);
    bench.at_with_bms(1_020);
    assert_eq!(bench.state(), State::Precharge);
    assert!(!bench.pcc.errors().bypassed);
}

#[test]
fn a_bms_timeout_releases_air_plus_one_ms_after_the_limit() {
    for energised in [State::Precharge, State::Online, State::Charging] {
        let (mut bench, now) = Bench::in_state(energised);
        let seen = now;
        bench.inputs.bms_last_seen_ms = Some(seen);
        bench.set_progress(if energised == State::Precharge {
            10.0
        } else {
            100.0
        });
        assert_eq!(
            bench.at(seen + CONFIG.bms_timeout_ms),
            Relays::for_state(energised)
        );
        assert_eq!(bench.state(), energised, "at the timeout");
        assert_eq!(bench.at(seen + CONFIG.bms_timeout_ms + 1), Relays::ALL_OPEN);
        assert_eq!(bench.state(), State::Error);
        assert!(bench.pcc.errors().bms_timeout);
    }
}

#[test]
fn losing_the_pack_discharges_and_standby_follows_below_60_volts() {
    let mut bench = Bench::ready();
    let done = bench.online();
    bench.inputs.accumulator_v = CONFIG.min_accumulator_v - 0.01;
    bench.inputs.tractive_v = 300.0;
    assert_eq!(bench.at_with_bms(done + 10), Relays::ALL_OPEN);
    assert_eq!(bench.state(), State::Discharge);
    assert_eq!(bench.pcc.errors(), Errors::default());
    bench.inputs.tractive_v = CONFIG.discharged_v;
    bench.at_with_bms(done + 500);
    assert_eq!(bench.state(), State::Discharge, "at 60 V");
    bench.inputs.tractive_v = CONFIG.discharged_v - 0.01;
    assert_eq!(bench.at_with_bms(done + 510), Relays::ALL_OPEN);
    assert_eq!(bench.state(), State::Standby);
}

#[test]
fn losing_the_pack_discharges_from_every_energised_state() {
    for energised in [State::Precharge, State::Online, State::Charging] {
        let (mut bench, now) = Bench::in_state(energised);
        bench.inputs.accumulator_v = 0.0;
        assert_eq!(
            bench.at_with_bms(now + 10),
            Relays::ALL_OPEN,
            "{energised:?}"
        );
        assert_eq!(bench.state(), State::Discharge);
    }
}

#[test]
fn a_measurement_that_is_not_a_number_counts_as_no_pack() {
    let mut bench = Bench::ready();
    let done = bench.online();
    bench.inputs.accumulator_v = f32::NAN;
    assert_eq!(bench.at_with_bms(done + 10), Relays::ALL_OPEN);
    assert_eq!(bench.state(), State::Discharge);
    assert_eq!(bench.pcc.accumulator_v(), 0.0);
}

#[test]
fn progress_at_the_limits_is_not_falling_away() {
    for energised in [State::Precharge, State::Online, State::Charging] {
        let (mut bench, now) = Bench::in_state(energised);
        let (high, lowest) = if energised == State::Precharge {
            (50.0, 50.0 - CONFIG.precharge_drop_percent)
        } else {
            (100.0, CONFIG.online_min_percent)
        };
        bench.set_progress(high);
        bench.at_with_bms(now + 1);
        bench.set_progress(lowest);
        bench.at_with_bms(now + 2);
        bench.at_with_bms(now + 1_000);
        assert_eq!(bench.state(), energised);
        assert_eq!(bench.pcc.errors(), Errors::default());
    }
}

#[test]
fn a_shutdown_error_clears_after_the_bus_is_discharged() {
    let mut bench = Bench::ready();
    let done = bench.online();
    bench.inputs.tractive_v = 100.0;
    bench.at_with_bms(done + 10);
    bench.at_with_bms(done + 10 + CONFIG.target_hold_ms);
    assert_eq!(bench.state(), State::Error);
    assert!(bench.pcc.errors().shutdown);

    // The tractive system still holds 100 V: no recovery.
    bench.at_with_bms(done + 40);
    bench.at_with_bms(done + 1_000);
    assert_eq!(bench.state(), State::Error);

    bench.inputs.tractive_v = CONFIG.discharged_v - 0.01;
    bench.at_with_bms(done + 1_010);
    bench.at_with_bms(done + 1_010 + CONFIG.standby_settle_ms - 1);
    assert_eq!(bench.state(), State::Error, "1 ms before the settle time");
    assert_eq!(
        bench.at_with_bms(done + 1_010 + CONFIG.standby_settle_ms),
        Relays::ALL_OPEN
    );
    assert_eq!(bench.state(), State::Standby);
    assert_eq!(bench.pcc.errors(), Errors::default());
}

#[test]
fn timing_and_bms_errors_latch_until_reset() {
    let mut bench = Bench::ready();
    bench.precharge_reaching_target_after(CONFIG.min_time_ms - 1);
    assert!(bench.pcc.errors().too_fast);
    bench.inputs.tractive_v = 0.0;
    for t in (20_000..80_000).step_by(10) {
        assert_eq!(bench.at_with_bms(t), Relays::ALL_OPEN);
    }
    assert_eq!(bench.state(), State::Error);
    assert!(bench.pcc.errors().too_fast);
}

#[test]
fn the_millisecond_counter_may_wrap_mid_precharge() {
    let mut bench = Bench::ready_at(u32::MAX - 4_000);
    let done = bench.precharge_reaching_target_after(CONFIG.min_time_ms);
    assert!(done < 10_000, "the counter wrapped");
    assert_eq!(bench.state(), State::Online);
}

#[test]
fn through_the_board_map_pin_11_is_high_in_online_and_charging_only() {
    use aer_boards::{Mode, pcc::COMP_CAR};
    let states = [
        State::Standby,
        State::Precharge,
        State::Discharge,
        State::Online,
        State::Charging,
        State::Error,
    ];
    for state in states {
        let outputs = Relays::for_state(state).outputs(&COMP_CAR);
        let high = matches!(state, State::Online | State::Charging);
        assert_eq!(outputs.len(), 1, "one relay output on the board");
        for (pin, level) in outputs {
            assert_eq!((pin.number, pin.mode), (11, Mode::OutputPullDown));
            assert_eq!(level, high, "{state:?}");
        }
    }
    // Whatever the state, the board's other outputs are not relay outputs.
    let relay_pins = [COMP_CAR.air_plus.number];
    for pin in COMP_CAR.pins() {
        if matches!(pin.mode, Mode::Output | Mode::OutputPullDown) && pin.number != 13 {
            assert!(relay_pins.contains(&pin.number), "{pin:?}");
        }
    }
}

/// The console's `bootloader` (typed, or a host setting 134 baud) stops the state machine,
/// so it is obeyed only where nothing depends on it: STANDBY or ERROR, AIR+ open, the
/// tractive system measured below 60 V.
#[test]
fn the_bootloader_is_refused_while_energised_or_charged() {
    for energised in [State::Precharge, State::Online, State::Charging] {
        let (bench, _) = Bench::in_state(energised);
        assert_eq!(
            bench.pcc.handover(),
            Err(aer_pcc::HandoverRefusal::Energised(energised)),
            "{energised:?}"
        );
    }
    let (mut bench, now) = Bench::in_state(State::Online);
    assert_eq!(
        bench.pcc.handover().unwrap_err().to_string(),
        "the PCC is in Online: open the shutdown circuit, wait for Standby with the tractive system discharged, then ask again"
    );
    // The pack goes away: DISCHARGE, still refused until STANDBY below 60 V.
    bench.inputs.accumulator_v = 0.0;
    bench.at_with_bms(now + 10);
    assert_eq!(bench.state(), State::Discharge);
    assert!(bench.pcc.handover().is_err());
    bench.inputs.tractive_v = 59.0;
    bench.at_with_bms(now + 20);
    assert_eq!(bench.state(), State::Standby);
    assert_eq!(bench.pcc.handover(), Ok(Relays::ALL_OPEN));
}

#[test]
fn the_bootloader_is_refused_in_standby_and_error_with_the_tractive_system_charged() {
    let mut bench = Bench::ready();
    bench.inputs.accumulator_v = 0.0;
    bench.inputs.tractive_v = 75.0;
    bench.at_with_bms(1_000);
    assert_eq!(bench.state(), State::Standby);
    assert_eq!(
        bench.pcc.handover().unwrap_err().to_string(),
        "the tractive system reads 75.0 V: open the shutdown circuit, wait until it is below 60 V, then ask again"
    );
    bench.inputs.tractive_v = 60.0;
    bench.at_with_bms(1_010);
    assert!(bench.pcc.handover().is_err(), "60 V is not below 60 V");
    bench.inputs.tractive_v = 12.0;
    bench.at_with_bms(1_020);
    assert_eq!(bench.pcc.handover(), Ok(Relays::ALL_OPEN));

    let mut error = Precharge::after_watchdog_reset(CONFIG, 0);
    assert_eq!(error.state(), State::Error);
    error.step(&Inputs {
        now_ms: 10,
        accumulator_v: 400.0,
        tractive_v: 300.0,
        raw_v: [400.0, 300.0],
        bms_last_seen_ms: Some(10),
        charger_safety: false,
        pulses: [Pulses::Live; 2],
        resistor_c: [Some(25.0); 2],
    });
    assert!(matches!(
        error.handover(),
        Err(aer_pcc::HandoverRefusal::Charged { .. })
    ));
}

#[test]
fn each_precharge_is_timed_against_its_window() {
    let mut bench = Bench::ready();
    assert_eq!(bench.pcc.last_precharge(), None);
    bench.online();
    let timing = bench.pcc.last_precharge().expect("timed");
    assert_eq!(timing.reached_ms, Some(CONFIG.min_time_ms + 100));
    assert_eq!(
        timing.to_string(),
        "precharge 1: 90 % reached 8300 ms after the rise (window 8200-9200 ms)"
    );
    let mut slow = Bench::ready();
    let start = slow.start_precharge();
    slow.set_progress(50.0);
    slow.at_with_bms(start + CONFIG.max_time_ms + 1);
    assert_eq!(slow.state(), State::Error);
    assert_eq!(
        slow.pcc.last_precharge().expect("timed").to_string(),
        "precharge 1: 90 % NOT reached within 9200 ms of the rise (window 8200-9200 ms)"
    );
    let mut fast = Bench::ready();
    fast.precharge_reaching_target_after(CONFIG.min_time_ms - 1);
    assert!(
        fast.pcc
            .last_precharge()
            .expect("timed")
            .to_string()
            .ends_with(", TOO FAST")
    );
}

/// STANDBY says what precharge waits for, one condition at a time, and nothing outside it.
#[test]
fn standby_names_what_precharge_waits_for() {
    use aer_pcc::Waiting;
    let mut pcc = Precharge::new(PrechargeConfig::CAR, 0);
    let mut inputs = Inputs {
        now_ms: 0,
        accumulator_v: 0.0,
        tractive_v: 0.0,
        raw_v: [0.0, 0.0],
        bms_last_seen_ms: None,
        charger_safety: false,
        pulses: [Pulses::Live; 2],
        resistor_c: [Some(25.0); 2],
    };
    inputs.raw_v = [inputs.accumulator_v, inputs.tractive_v];
    pcc.step(&inputs);
    assert_eq!(
        pcc.waiting(),
        Some(Waiting {
            pack: true,
            bms: true,
            rise: true,
            discharge: false,
            live: false,
            resistor: false
        })
    );
    inputs.now_ms = 10;
    inputs.bms_last_seen_ms = Some(10);
    inputs.accumulator_v = 300.0;
    inputs.raw_v = [inputs.accumulator_v, inputs.tractive_v];
    pcc.step(&inputs);
    assert_eq!(
        pcc.waiting(),
        Some(Waiting {
            pack: false,
            bms: false,
            rise: true,
            discharge: false,
            live: false,
            resistor: false
        })
    );
    // The shutdown circuit closes: the tractive system rises, precharge starts.
    inputs.now_ms = 20;
    inputs.bms_last_seen_ms = Some(20);
    inputs.tractive_v = 30.0;
    inputs.raw_v = [inputs.accumulator_v, inputs.tractive_v];
    pcc.step(&inputs);
    assert_eq!(pcc.state(), State::Precharge);
    assert_eq!(pcc.waiting(), None);
}

/// A tractive system the hardware charged while the PCC could not start (the BMS silent) is
/// an untimed precharge: the PCC stays in STANDBY, says so, and never closes AIR+ on it; once
/// the shutdown circuit has opened and the tractive system is below 60 V, the next rise is a
/// timed precharge as usual.
#[test]
fn a_precharge_the_pcc_missed_never_counts() {
    use aer_pcc::Waiting;
    let config = PrechargeConfig::CAR;
    let mut pcc = Precharge::new(config, 0);
    let pack = 300.0;
    let mut inputs = Inputs {
        now_ms: 0,
        accumulator_v: pack,
        tractive_v: 0.0,
        raw_v: [pack, 0.0],
        bms_last_seen_ms: None,
        charger_safety: false,
        pulses: [Pulses::Live; 2],
        resistor_c: [Some(25.0); 2],
    };
    // The shutdown circuit closes with the BMS silent: the hardware precharges to the pack.
    for step in 0..2_000u32 {
        inputs.now_ms = step * 10;
        inputs.tractive_v = pack * (1.0 - (-(inputs.now_ms as f32) / 3_800.0).exp());
        assert!(
            !pcc.step(&inputs).air_plus,
            "AIR+ closed at {} ms",
            inputs.now_ms
        );
    }
    assert_eq!(pcc.state(), State::Standby);
    // The BMS is heard now: no PRECHARGE (its timing would be meaningless), and STANDBY says
    // why.
    for step in 2_000..2_300u32 {
        inputs.now_ms = step * 10;
        inputs.bms_last_seen_ms = Some(inputs.now_ms);
        assert!(!pcc.step(&inputs).air_plus);
    }
    assert_eq!(pcc.state(), State::Standby);
    assert_eq!(
        pcc.waiting(),
        Some(Waiting {
            pack: false,
            bms: false,
            rise: false,
            discharge: true,
            live: true,
            resistor: false
        })
    );
    // The shutdown circuit opens: the tractive system discharges below 60 V.
    let mut now = inputs.now_ms;
    while inputs.tractive_v >= 1.0 {
        now += 10;
        inputs.now_ms = now;
        inputs.bms_last_seen_ms = Some(now);
        inputs.tractive_v *= 0.99;
        inputs.raw_v = [inputs.accumulator_v, inputs.tractive_v];
        pcc.step(&inputs);
    }
    assert_eq!(pcc.state(), State::Standby);
    assert_eq!(pcc.waiting().map(|waiting| waiting.rise), Some(true));
    // It closes again: a timed precharge to ONLINE.
    let start = now;
    while pcc.state() != State::Online {
        now += 10;
        assert!(now - start < 20_000, "never ONLINE: {:?}", pcc.state());
        inputs.now_ms = now;
        inputs.bms_last_seen_ms = Some(now);
        inputs.tractive_v = pack * (1.0 - (-((now - start) as f32) / 3_800.0).exp());
        inputs.raw_v = [inputs.accumulator_v, inputs.tractive_v];
        pcc.step(&inputs);
    }
    let timing = pcc.last_precharge().expect("timed");
    assert!(!timing.to_string().contains("TOO"), "{timing}");
}

/// The other ways a precharge goes untimed never start PRECHARGE either: the pack's reading
/// missing while the tractive system charged, the circuit closed at start-up, and the circuit
/// closed again before the tractive system had discharged to rest (5 % of the pack).
#[test]
fn only_a_rise_from_rest_with_the_pcc_ready_is_timed() {
    let config = PrechargeConfig::CAR;
    let step = |pcc: &mut Precharge, now_ms: u32, accumulator_v: f32, tractive_v: f32| {
        let relays = pcc.step(&Inputs {
            now_ms,
            accumulator_v,
            tractive_v,
            raw_v: [accumulator_v, tractive_v],
            bms_last_seen_ms: Some(now_ms),
            charger_safety: false,
            pulses: [Pulses::Live; 2],
            resistor_c: [Some(25.0); 2],
        });
        assert!(!relays.air_plus, "AIR+ closed at {now_ms} ms");
    };
    // The pack's converter silent (0 V) while the tractive system charges; then it reads.
    let mut pcc = Precharge::new(config, 0);
    for (now, tractive) in [(0, 0.0), (10, 150.0), (20, 290.0), (30, 300.0)] {
        step(&mut pcc, now, 0.0, tractive);
    }
    step(&mut pcc, 40, 300.0, 300.0);
    step(&mut pcc, 50, 300.0, 300.0);
    assert_eq!(pcc.state(), State::Standby);
    assert_eq!(pcc.waiting().map(|w| w.discharge), Some(true));

    // The circuit already closed at start-up: both readings rise together from 0.
    let mut pcc = Precharge::new(config, 0);
    for (now, volts) in [(0, 0.0), (10, 40.0), (20, 110.0), (30, 200.0), (40, 300.0)] {
        step(&mut pcc, now, volts, volts);
    }
    assert_eq!(pcc.state(), State::Standby);
    assert_eq!(pcc.waiting().map(|w| w.discharge), Some(true));

    // Closed again at 55 V, below 60 V but not at rest: no PRECHARGE until it has been
    // below 15 V (5 % of 300 V) with the circuit open.
    let mut pcc = Precharge::new(config, 0);
    step(&mut pcc, 0, 300.0, 55.0);
    step(&mut pcc, 10, 300.0, 80.0);
    assert_eq!(pcc.state(), State::Standby);
    let waiting = pcc.waiting().expect("waiting");
    assert!(waiting.discharge && !waiting.rise, "{waiting:?}");
    step(&mut pcc, 20, 300.0, 14.0);
    assert_eq!(pcc.waiting().map(|w| w.rise), Some(true));
    pcc.step(&Inputs {
        now_ms: 30,
        accumulator_v: 300.0,
        tractive_v: 21.0,
        raw_v: [300.0, 21.0],
        bms_last_seen_ms: Some(30),
        charger_safety: false,
        pulses: [Pulses::Live; 2],
        resistor_c: [Some(25.0); 2],
    });
    assert_eq!(pcc.state(), State::Precharge, "a rise from rest");
}

#[test]
fn air_plus_that_does_not_close_is_named_and_starts_no_discharge_timer() {
    // ONLINE at 90 %: AIR+ commanded closed, but the tractive system stays where the
    // precharge resistor holds it (the coil unpowered, the driver dead).
    let mut bench = Bench::ready();
    let start = bench.start_precharge();
    bench.set_progress(CONFIG.target_percent);
    let reached = start + CONFIG.min_time_ms + 100;
    bench.at_with_bms(reached);
    let online = reached + CONFIG.target_hold_ms;
    bench.at_with_bms(online);
    assert_eq!(bench.state(), State::Online);
    let mut t = online;
    while t < online + CONFIG.air_plus_close_ms - 10 {
        t += 10;
        assert_eq!(bench.at_with_bms(t), CONNECTED, "closing at {t}");
    }
    t += 10;
    assert_eq!(
        bench.at_with_bms(t),
        Relays::ALL_OPEN,
        "the close time is over"
    );
    assert_eq!(
        bench.pcc.errors(),
        Errors {
            air_plus_open: true,
            ..Errors::default()
        }
    );
    // The shutdown circuit stays closed: the tractive system held at 90 % through the
    // resistor is no failed discharge.
    for _ in 0..1_000 {
        t += 10;
        bench.at_with_bms(t);
    }
    assert!(!bench.pcc.errors().no_discharge, "{}", bench.pcc.errors());
}

#[test]
fn online_holds_while_a_slow_rise_reaches_the_minimum_within_the_close_time() {
    // The bench's linear sweep: 90 % at ONLINE, 95 % about 450 ms later, then the pack.
    let mut bench = Bench::ready();
    let start = bench.start_precharge();
    bench.set_progress(CONFIG.target_percent);
    let reached = start + CONFIG.min_time_ms + 100;
    bench.at_with_bms(reached);
    let online = reached + CONFIG.target_hold_ms;
    bench.at_with_bms(online);
    assert_eq!(bench.state(), State::Online);
    let mut t = online;
    for step in 1..=100u32 {
        t += 10;
        let percent = (CONFIG.target_percent + step as f32 * 0.1).min(100.0);
        bench.set_progress(percent);
        assert_eq!(bench.at_with_bms(t), CONNECTED, "{percent} % at {t}");
    }
    assert_eq!(bench.pcc.errors(), Errors::default());
}

#[test]
fn a_fall_while_air_plus_closes_opens_it_as_a_shutdown() {
    let mut bench = Bench::ready();
    let start = bench.start_precharge();
    bench.set_progress(CONFIG.target_percent);
    let reached = start + CONFIG.min_time_ms + 100;
    bench.at_with_bms(reached);
    let online = reached + CONFIG.target_hold_ms;
    bench.at_with_bms(online);
    assert_eq!(bench.state(), State::Online);
    // The shutdown circuit opens before AIR+ has closed: the tractive system falls.
    bench.set_progress(CONFIG.target_percent - CONFIG.precharge_drop_percent - 1.0);
    bench.at_with_bms(online + 10);
    assert_eq!(bench.at_with_bms(online + 30), Relays::ALL_OPEN);
    assert_eq!(
        bench.pcc.errors(),
        Errors {
            shutdown: true,
            ..Errors::default()
        }
    );
}

#[test]
fn the_discharge_timer_starts_at_the_fall_after_a_shutdown_from_online() {
    let mut bench = Bench::ready();
    let online = bench.online();
    bench.at_with_bms(online + 10);
    // The shutdown circuit opens: the tractive system falls to 93 % and stays there (no
    // discharge circuit, no load): the fall from the peak is under 10 %, so no timer yet.
    bench.set_progress(93.0);
    let mut t = online + 10;
    for _ in 0..3 {
        t += 10;
        bench.at_with_bms(t);
    }
    assert_eq!(bench.state(), State::Error);
    for _ in 0..1_000 {
        t += 10;
        bench.at_with_bms(t);
    }
    assert!(!bench.pcc.errors().no_discharge, "no fall, no timer");
    // It falls well below its peak and stalls at 150 V: no-discharge 5 s after that fall.
    bench.set_progress(50.0);
    t += 10;
    bench.at_with_bms(t);
    let fell = t;
    while t < fell + CONFIG.discharge_time_ms - 10 {
        t += 10;
        bench.at_with_bms(t);
        assert!(!bench.pcc.errors().no_discharge, "early at {t}");
    }
    t += 20;
    bench.at_with_bms(t);
    assert!(bench.pcc.errors().no_discharge);
}
