//! Contacts that bounce and edges that lie, as the car has them: AIR+ a contactor whose coil
//! the shutdown circuit feeds (it closes 25 ms after the coil is powered, opens 8 ms after),
//! edges added to or lost from the converters' trains, loads on the tractive system. Through
//! the real measurement chain and state machine; each test asserts the safe outcome, or the
//! healthy one where a false trip would cost the day (a latch needs a power cycle).

use aer_car_model::precharge::{PrechargePlant, PulseGenerator};
use aer_pcc::constants::CONVERTERS;
use aer_pcc::measurement::VoltageChannel;
use aer_pcc::{Errors, Inputs, Precharge, PrechargeConfig, Relays, State, TASK_PERIOD_MS};

type EdgeFilter = Box<dyn FnMut(usize, u32) -> bool>;
type Extra = Box<dyn FnMut(usize, u32, &[u32]) -> Vec<u32>>;
type Schedule = Box<dyn FnMut(u32) -> bool>;
type LoadSchedule = Box<dyn FnMut(u32, bool, f32) -> Option<f32>>;

const OPERATE_MS: u32 = 25;
const RELEASE_MS: u32 = 8;

/// The sensing_lies rig, plus: AIR+ as a contactor whose coil is fed through the shutdown
/// circuit (operate 25 ms from coil powered, release 8 ms), extra edges, a load schedule.
struct Rig {
    pcc: Precharge,
    plant: PrechargePlant,
    channels: [VoltageChannel; 2],
    gens: [PulseGenerator; 2],
    relays: Relays,
    coil_since: u32,
    coil: bool,
    contacts: bool,
    now_ms: u32,
    start_ms: u32,
    bms_seen: Option<u32>,
    scale: [f32; 2],
    edge_pass: EdgeFilter,
    extra: Extra,
    shutdown: Schedule,
    bms: Schedule,
    bms_pending: bool,
    charger: Schedule,
    /// (relative ms, connected without resistor) -> load on the tractive system (Ohm).
    load: LoadSchedule,
    closures: Vec<(u32, f32)>,
    was_connected: bool,
    states: Vec<(u32, State)>,
}

impl Rig {
    fn new(start_ms: u32, pack_v: f32) -> Self {
        let mut plant = PrechargePlant::new(pack_v, 3_800.0, 500.0);
        plant.shutdown_closed = false;
        Self {
            pcc: Precharge::new(PrechargeConfig::CAR, start_ms),
            plant,
            channels: CONVERTERS.map(|vf| VoltageChannel::new(vf, TASK_PERIOD_MS)),
            gens: [PulseGenerator::default(); 2],
            relays: Relays::ALL_OPEN,
            coil_since: 0,
            coil: false,
            contacts: false,
            now_ms: start_ms,
            start_ms,
            bms_seen: None,
            scale: [1.0; 2],
            edge_pass: Box::new(|_, _| true),
            extra: Box::new(|_, _, _| Vec::new()),
            shutdown: Box::new(|t| t >= 1_000),
            bms: Box::new(|t| t % 10 == 0),
            bms_pending: false,
            charger: Box::new(|_| false),
            load: Box::new(|_, _, _| None),
            closures: Vec::new(),
            was_connected: false,
            states: Vec::new(),
        }
    }

    fn rel(&self) -> u32 {
        self.now_ms.wrapping_sub(self.start_ms)
    }

    fn true_progress(&self) -> f32 {
        100.0 * self.plant.tractive_v / self.plant.accumulator_v
    }

    fn ms(&mut self) {
        let rel = self.rel();
        self.plant.shutdown_closed = (self.shutdown)(rel);
        if (self.bms)(rel) {
            self.bms_pending = true;
        }
        // AIR+'s coil is fed through the shutdown circuit.
        let coil = self.relays.air_plus && self.plant.shutdown_closed;
        if coil != self.coil {
            self.coil = coil;
            self.coil_since = rel;
        }
        let delay = if coil { OPERATE_MS } else { RELEASE_MS };
        if self.contacts != coil && rel.wrapping_sub(self.coil_since) >= delay {
            self.contacts = coil;
        }
        let contacts = Relays {
            air_plus: self.contacts,
        };
        let connected = self.plant.connected(contacts);
        if connected && !self.was_connected {
            let p = self.true_progress();
            self.closures.push((rel, p));
        }
        self.was_connected = connected;
        self.plant.load_ohm = (self.load)(rel, connected, self.plant.tractive_v);
        self.plant.advance(contacts, 1.0);
        let start_us = self.now_ms.wrapping_mul(1_000);
        let volts = [self.plant.accumulator_v, self.plant.tractive_v];
        for i in 0..2 {
            let hz = CONVERTERS[i].hz_for_volts(volts[i]) * self.scale[i];
            let mut edges = Vec::new();
            self.gens[i].run(start_us, 1_000, hz, |at| edges.push(at));
            let mut all: Vec<u32> = edges
                .iter()
                .copied()
                .filter(|at| (self.edge_pass)(i, *at))
                .collect();
            all.extend((self.extra)(i, start_us, &edges));
            all.sort_unstable_by_key(|at| at.wrapping_sub(start_us));
            for at in all {
                self.channels[i].on_edge(at);
            }
        }
        self.now_ms = self.now_ms.wrapping_add(1);
        if self.now_ms.wrapping_sub(self.start_ms) % TASK_PERIOD_MS == 0 {
            self.step();
        }
    }

    fn step(&mut self) {
        let now_ms = self.now_ms;
        if self.bms_pending {
            self.bms_seen = Some(now_ms);
            self.bms_pending = false;
        }
        let now_us = now_ms.wrapping_mul(1_000);
        let [a, t] = self.channels.each_mut().map(|c| c.sample(now_us));
        let rel = self.rel();
        let inputs = Inputs {
            now_ms,
            accumulator_v: a.volts,
            tractive_v: t.volts,
            raw_v: [a.raw_volts, t.raw_volts],
            pulses: [a.pulses, t.pulses],
            bms_last_seen_ms: self.bms_seen,
            charger_safety: (self.charger)(rel),
            resistor_c: [Some(25.0); 2],
        };
        let before = self.pcc.state();
        self.relays = self.pcc.step(&inputs);
        if self.pcc.state() != before {
            self.states.push((rel, self.pcc.state()));
        }
    }

    fn run_to(&mut self, rel_ms: u32) {
        while self.rel() < rel_ms {
            self.ms();
        }
    }

    fn online_at(&self) -> Option<u32> {
        self.states
            .iter()
            .find(|(_, s)| *s == State::Online)
            .map(|(t, _)| *t)
    }

    fn online_by(&mut self, rel_ms: u32) {
        self.run_to(rel_ms);
        assert_eq!(
            self.pcc.state(),
            State::Online,
            "precondition: ONLINE ({:?}, {})",
            self.states,
            self.pcc.errors()
        );
    }
}

fn only_shutdown() -> Errors {
    Errors {
        shutdown: true,
        ..Errors::default()
    }
}

// ---------------------------------------------------------------------------------------
// A. A shutdown bounce that starts as ONLINE is entered, before AIR+ has closed: the
// pre-reach rule (filtered progress 10 points below the peak, held 20 ms) is slow.
// ---------------------------------------------------------------------------------------

#[test]
fn a_bounce_as_online_is_entered_never_reconnects_below_target() {
    // Where ONLINE is entered on a clean run.
    let mut probe = Rig::new(0, 400.0);
    probe.online_by(12_000);
    let online = probe.online_at().expect("online");
    let mut worst: Option<(i32, u32, f32)> = None;
    for offset in (-20i32..=30).step_by(5) {
        for open_ms in (20u32..=140).step_by(10) {
            let mut rig = Rig::new(0, 400.0);
            let from = (online as i32 + offset) as u32;
            rig.shutdown = Box::new(move |t| t >= 1_000 && !(from..from + open_ms).contains(&t));
            rig.run_to(14_000);
            for &(_, p) in &rig.closures {
                if worst.is_none_or(|(_, _, w)| p < w) {
                    worst = Some((offset, open_ms, p));
                }
            }
        }
    }
    let (offset, open_ms, lowest) = worst.expect("closures");
    assert!(
        lowest >= 90.0,
        "bounce from ONLINE{offset:+} ms for {open_ms} ms: the pack connected through AIR+ onto \
         {lowest:.1} % of it"
    );
}

// ---------------------------------------------------------------------------------------
// B. A shutdown bounce while ONLINE (healthy car, the circuit closes again): only `shutdown`
// may latch, and opening the circuit once more must let the car precharge again.
// ---------------------------------------------------------------------------------------

#[test]
fn a_shutdown_bounce_latches_nothing_beyond_shutdown() {
    let mut failures = Vec::new();
    for open_ms in [60u32, 100, 200, 400] {
        let mut rig = Rig::new(0, 400.0);
        rig.online_by(12_000);
        // The bounce at 13 s; the crew sees ERROR, opens the circuit at 25 s for 3 s, closes
        // it again at 28 s for a new precharge.
        rig.shutdown = Box::new(move |t| {
            t >= 1_000 && !(13_000..13_000 + open_ms).contains(&t) && !(25_000..28_000).contains(&t)
        });
        rig.run_to(25_000);
        let at_25 = rig.pcc.errors();
        rig.run_to(42_000);
        if at_25 != only_shutdown() || rig.pcc.state() != State::Online {
            failures.push(format!(
                "open {open_ms} ms: errors at 25 s [{at_25}], at 42 s {:?} [{}]; states {:?}",
                rig.pcc.state(),
                rig.pcc.errors(),
                rig.states
            ));
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

// ---------------------------------------------------------------------------------------
// C. The PCC opens AIR+ under load (the inverter still drawing for 20 ms) with the shutdown
// circuit closed: the cause is a converter's wire; `no-discharge` must not be added.
// ---------------------------------------------------------------------------------------

#[test]
fn air_plus_opened_under_load_with_the_circuit_closed_is_no_failed_discharge() {
    let mut rig = Rig::new(0, 400.0);
    rig.online_by(12_000);
    // The accumulator converter's wire breaks at 13 s while the car draws 100 kW... the
    // inverter keeps drawing until the CCM's zero torque reaches it (20 ms after AIR+ opened),
    // then stops at its undervoltage limit.
    rig.edge_pass = Box::new(|i, at| !(i == 0 && at >= 13_000_000));
    let mut opened_at = None;
    rig.load = Box::new(move |t, connected, ts_v| {
        if t < 13_000 {
            return Some(1.6);
        }
        if !connected && opened_at.is_none() {
            opened_at = Some(t);
        }
        // The inverter draws until the CCM's zero torque reaches it (20 ms after AIR+
        // opened), and never below its DC undervoltage limit (250 V).
        match opened_at {
            Some(at) if t < at + 20 && ts_v > 250.0 => Some(1.6),
            Some(_) => None,
            None => Some(1.6),
        }
    });
    rig.run_to(25_000);
    let errors = rig.pcc.errors();
    assert_eq!(
        errors,
        Errors {
            accumulator_silent: true,
            ..Errors::default()
        },
        "[{errors}] no-discharge {:?}, TS {:.0} V, states {:?}",
        rig.pcc.no_discharge(),
        rig.plant.tractive_v,
        rig.states
    );
}

// ---------------------------------------------------------------------------------------
// D. 103 %: a healthy car, converters within 8.1's 0.5 %, one interference edge per window
// on the tractive line (100 Hz: one edge per 10 ms) for 30 ms.
// ---------------------------------------------------------------------------------------

/// One extra edge every `every_us` from `from_us` to `until_us` on converter `which`, at a
/// phase `phase_us` into each period.
fn interference(which: usize, from_us: u32, until_us: u32, every_us: u32, phase_us: u32) -> Extra {
    Box::new(move |i, start_us, _| {
        let mut out = Vec::new();
        if i != which {
            return out;
        }
        for us in start_us..start_us + 1_000 {
            if us >= from_us && us < until_us && us % every_us == phase_us {
                out.push(us);
            }
        }
        out
    })
}

#[test]
fn interference_of_one_edge_per_window_does_not_latch_converters_disagree_on_a_healthy_car() {
    let mut failures = Vec::new();
    for (pack_v, tractive_cal) in [(400.0f32, 1.005f32), (330.0, 1.005), (280.0, 1.0)] {
        let mut rig = Rig::new(0, pack_v);
        rig.scale = [1.0, tractive_cal];
        rig.online_by(12_000);
        // 30 ms of 100 Hz interference at 13 s (a relay, a fan start).
        rig.extra = interference(1, 13_000_000, 13_030_000, 10_000, 4_321);
        rig.run_to(14_000);
        if rig.pcc.state() != State::Online {
            failures.push(format!(
                "pack {pack_v} V, tractive converter x{tractive_cal}: {:?} [{}] after 3 stray edges",
                rig.pcc.state(),
                rig.pcc.errors()
            ));
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

// ---------------------------------------------------------------------------------------
// E. One stray edge during a healthy precharge (the precharge relay's own EMI as it closes):
// the precharge must still reach ONLINE.
// ---------------------------------------------------------------------------------------

#[test]
fn one_stray_edge_during_a_healthy_precharge_still_reaches_online() {
    let mut latched = Vec::new();
    // Stray edges from 1.05 s to 3 s after the shutdown circuit closed, every 21.9 ms,
    // each right after a real edge (a contact's bounce, a coupled spike).
    let mut at_us = 1_050_000u32;
    while at_us < 3_000_000 {
        let mut rig = Rig::new(0, 400.0);
        let mut done = false;
        rig.extra = Box::new(move |i, start_us, real| {
            if i != 1 || done || start_us + 1_000 <= at_us {
                return Vec::new();
            }
            // Odd steps: a spike 30 us behind the first real edge at or after the chosen
            // time; even steps: the spike at the chosen time itself, whatever the phase.
            if (at_us / 7_300) % 2 == 0 {
                done = true;
                return vec![at_us];
            }
            match real.iter().find(|e| **e >= at_us) {
                Some(e) => {
                    done = true;
                    vec![e + 30]
                }
                None => Vec::new(),
            }
        });
        rig.run_to(12_000);
        if rig.pcc.state() != State::Online {
            latched.push((
                at_us / 1_000,
                rig.pcc.errors().to_string(),
                (at_us / 7_300) % 2 == 0,
            ));
        }
        at_us += 21_900;
    }
    assert!(
        latched.is_empty(),
        "{} of the single stray edges stopped the precharge ({} of them at an arbitrary \
         phase; ms after the circuit closed: {:?} .. {:?}), e.g. {:?}",
        latched.len(),
        latched.iter().filter(|l| l.2).count(),
        latched.first().map(|l| l.0 - 1_000),
        latched.last().map(|l| l.0 - 1_000),
        &latched[..latched.len().min(3)]
    );
}

// ---------------------------------------------------------------------------------------
// F. A normal shutdown from ONLINE; one edge of the tractive converter lost (or one stray
// edge) while the discharge passes 60-70 V: only `shutdown` may latch.
// ---------------------------------------------------------------------------------------

#[test]
fn one_lost_edge_during_a_normal_discharge_latches_nothing_beyond_shutdown() {
    let mut bad = Vec::new();
    // Find when the discharge passes 75 V .. 55 V on a clean run.
    let mut probe = Rig::new(0, 400.0);
    probe.online_by(12_000);
    probe.shutdown = Box::new(|t| (1_000..13_000).contains(&t));
    let mut band = (0u32, 0u32);
    while probe.rel() < 16_000 {
        probe.ms();
        let v = probe.plant.tractive_v;
        if band.0 == 0 && v < 75.0 && probe.rel() > 13_000 {
            band.0 = probe.rel();
        }
        if band.1 == 0 && v < 55.0 && probe.rel() > 13_000 {
            band.1 = probe.rel();
        }
    }
    assert_eq!(
        (probe.pcc.state(), probe.pcc.errors()),
        (State::Standby, Errors::default()),
        "control: a clean discharge"
    );
    for lost_at_ms in band.0..band.1 {
        let mut rig = Rig::new(0, 400.0);
        rig.online_by(12_000);
        rig.shutdown = Box::new(|t| (1_000..13_000).contains(&t));
        let mut dropped = false;
        let from_us = lost_at_ms * 1_000;
        rig.edge_pass = Box::new(move |i, at| {
            if i == 1 && !dropped && at >= from_us {
                dropped = true;
                return false;
            }
            true
        });
        rig.run_to(16_000);
        if rig.pcc.errors() != Errors::default() || rig.pcc.state() != State::Standby {
            bad.push((lost_at_ms, rig.pcc.state(), rig.pcc.errors().to_string()));
        }
    }
    assert!(
        bad.is_empty(),
        "discharge 75->55 V between {band:?} ms: {} of {} single lost edges latched, e.g. {:?}",
        bad.len(),
        band.1 - band.0,
        &bad[..bad.len().min(4)]
    );
}

// ---------------------------------------------------------------------------------------
// G. Two faults: the tractive converter reading 2.9 % high and a precharge time constant 5 %
// long (resistor tolerance). The first closure judged on that reading cannot be undone (it
// lands at about 88 %), but once AIR+ joins the two converters the PCC sees them disagree by
// more than 2 % and latches `converters-disagree`: no second closure on the wrong reading.
// ---------------------------------------------------------------------------------------

#[test]
fn a_converter_reading_high_is_named_at_the_first_closure_and_closes_nothing_again() {
    let mut rig = Rig::new(0, 400.0);
    rig.plant.precharge_tau_ms = 3_800.0 * 1.05;
    rig.scale = [1.0, 1.029];
    rig.run_to(14_000);
    let first = rig.closures.first().map(|c| c.1).expect("AIR+ closed once");
    assert!(first >= 87.0, "AIR+ closed onto {first:.1} % of the pack");
    assert!(
        rig.pcc.errors().converters_disagree,
        "[{}] {:?}",
        rig.pcc.errors(),
        rig.pcc.state()
    );
    // A bounce of the shutdown circuit now closes nothing again.
    rig.shutdown = Box::new(|t| t >= 1_000 && !(14_500..14_600).contains(&t));
    rig.run_to(16_000);
    assert_eq!(rig.closures.len(), 1, "{:?}", rig.closures);
}

// G2. A converter error under the 102 % limit, then a shutdown bounce while ONLINE.
#[test]
fn a_converter_error_under_the_limit_then_a_bounce_never_reconnects_below_target() {
    let mut worst: Option<(u32, f32)> = None;
    for open_ms in (30u32..=120).step_by(5) {
        let mut rig = Rig::new(0, 400.0);
        rig.online_by(12_000);
        rig.scale = [1.0, 1.019];
        rig.run_to(12_500);
        assert_eq!(rig.pcc.state(), State::Online);
        rig.shutdown = Box::new(move |t| t >= 1_000 && !(13_000..13_000 + open_ms).contains(&t));
        let before = rig.closures.len();
        rig.run_to(15_000);
        for &(_, p) in &rig.closures[before..] {
            if worst.is_none_or(|(_, w)| p < w) {
                worst = Some((open_ms, p));
            }
        }
    }
    if let Some((open_ms, lowest)) = worst {
        assert!(
            lowest >= 90.0,
            "tractive converter +1.9 % (accepted), {open_ms} ms bounce: reconnected onto {lowest:.1} %"
        );
    }
}

// ---------------------------------------------------------------------------------------
// H. The rules' 5 s: a discharge circuit slow enough to miss it (time constant 2.75 s: 60 V
// at 5.2 s after the circuit opened) must latch `no-discharge`.
// ---------------------------------------------------------------------------------------

#[test]
fn a_discharge_slower_than_the_rules_latches_no_discharge() {
    let mut rig = Rig::new(0, 400.0);
    rig.plant.discharge_tau_ms = 2_750.0;
    rig.online_by(12_000);
    rig.shutdown = Box::new(|t| (1_000..13_000).contains(&t));
    let mut below_at = None;
    while rig.rel() < 22_000 {
        rig.ms();
        if below_at.is_none() && rig.plant.tractive_v < 60.0 {
            below_at = Some(rig.rel() - 13_000);
        }
    }
    let below = below_at.expect("it does discharge");
    assert!(below > 5_000, "precondition: {below} ms");
    assert!(
        rig.pcc.errors().no_discharge,
        "below 60 V only {below} ms after the circuit opened, and no `no-discharge`: [{}]",
        rig.pcc.errors()
    );
}

// ---------------------------------------------------------------------------------------
// I. The CCM's tractive mismatch: the PCC reads the tractive system dead (below 60 V) while
// the inverter reads it live.
// ---------------------------------------------------------------------------------------

#[test]
fn the_ccm_sees_a_pcc_reading_dead_where_the_inverter_reads_live() {
    use aer::can::{PccStatus, PrechargeState};
    use aer_ccm::faults::tractive_readings_disagree;
    let status = |volts: f64| PccStatus {
        pcc_state: PrechargeState::Standby,
        pcc_error_air_plus_open: false,
        pcc_error_converters_disagree: false,
        pcc_error_bypassed: false,
        pcc_error_resistor_hot: false,
        pcc_accumulator_no_pulses: false,
        pcc_tractive_no_pulses: false,
        pcc_error_too_fast: false,
        pcc_error_too_slow: false,
        pcc_error_bms_timeout: false,
        pcc_error_shutdown: false,
        pcc_error_accumulator_silent: false,
        pcc_error_tractive_silent: false,
        pcc_error_no_discharge: false,
        pcc_error_undefined_state: false,
        pcc_accumulator_voltage: 392.0,
        pcc_tractive_voltage: volts,
        pcc_precharge_progress: 0.0,
    };
    let mut missed = Vec::new();
    for dti in [70.0f32, 80.0, 90.0, 99.0] {
        for pcc in [40.0f64, 50.0, 59.0] {
            if !tractive_readings_disagree(&status(pcc), dti) {
                missed.push((pcc, dti));
            }
        }
    }
    assert!(
        missed.is_empty(),
        "(PCC V, inverter V) not a mismatch: {missed:?}"
    );
}

// ---------------------------------------------------------------------------------------
// A (table). Where the bounce's start falls against ONLINE's entry.
// ---------------------------------------------------------------------------------------

#[test]
fn table_bounce_against_online_entry() {
    let mut probe = Rig::new(0, 400.0);
    probe.online_by(12_000);
    let online = probe.online_at().expect("online");
    for offset in (-40i32..=60).step_by(5) {
        let mut worst: Option<(u32, f32)> = None;
        for open_ms in (10u32..=160).step_by(5) {
            let mut rig = Rig::new(0, 400.0);
            let from = (online as i32 + offset) as u32;
            rig.shutdown = Box::new(move |t| t >= 1_000 && !(from..from + open_ms).contains(&t));
            rig.run_to(14_000);
            for &(_, p) in &rig.closures {
                if worst.is_none_or(|(_, w)| p < w) {
                    worst = Some((open_ms, p));
                }
            }
        }
        println!("bounce from ONLINE{offset:+} ms: worst closure {worst:?}");
    }
}

// ---------------------------------------------------------------------------------------
// B in closed loop: the comp car driving the skidpad, the CCM in the loop, a 100 ms bounce.
// ---------------------------------------------------------------------------------------

#[test]
fn closed_loop_bounce_latches_nothing_beyond_shutdown() {
    use aer_car_model::chassis::Mode;
    use aer_car_model::driver::Cycle;
    use aer_car_model::faults::{Fault, FaultPlan, Injection};
    use aer_car_model::{ClosedLoop, ModelParams, NoTap};
    let mut run = ClosedLoop::new(
        ModelParams::NOMINAL,
        Mode::Road,
        Cycle::Skidpad,
        FaultPlan::NONE,
    );
    assert!(run.start_up(20_000));
    run.run_until(run.now_ms() + 3_000, &mut NoTap);
    assert_eq!(run.car.pcc.state(), State::Online);
    let now = run.now_ms();
    let plan = FaultPlan::NONE.with(Injection {
        fault: Fault::ShutdownOpen,
        from_ms: now + 1_000,
        until_ms: now + 1_100,
    });
    run.retune(run.car.params, plan);
    run.run_until(now + 10_000, &mut NoTap);
    let errors = run.car.pcc.logic.errors();
    assert_eq!(
        errors,
        only_shutdown(),
        "100 ms bounce while driving: PCC {:?} [{errors}] {:?}",
        run.car.pcc.state(),
        run.car.pcc.logic.no_discharge()
    );
}

// ---------------------------------------------------------------------------------------
// Held? A normal shutdown across the millisecond and microsecond counters' wraps.
// ---------------------------------------------------------------------------------------

#[test]
fn a_normal_shutdown_across_the_wraps_latches_nothing_beyond_shutdown() {
    for start in [u32::MAX - 12_950, 4_294_967 - 12_950, u32::MAX - 12_990] {
        let mut rig = Rig::new(start, 400.0);
        rig.online_by(12_000);
        rig.shutdown = Box::new(|t| (1_000..13_000).contains(&t));
        rig.run_to(15_000);
        assert_eq!(
            (rig.pcc.state(), rig.pcc.errors()),
            (State::Standby, Errors::default()),
            "start {start}: {:?}",
            rig.states
        );
        // And a new precharge reaches ONLINE.
        rig.shutdown = Box::new(|t| (1_000..13_000).contains(&t) || t >= 16_000);
        rig.run_to(27_000);
        assert_eq!(
            rig.pcc.state(),
            State::Online,
            "start {start}: {:?}",
            rig.states
        );
    }
}

// ---------------------------------------------------------------------------------------
// Held? The charger-safety bit switching ONLINE <-> CHARGING for real (held 110 ms each way)
// while the shutdown circuit bounces: the watch goes on across the switch.
// ---------------------------------------------------------------------------------------

#[test]
fn a_charger_bit_that_really_switches_does_not_blind_the_watch() {
    let mut worst: Option<(u32, u32, f32)> = None;
    for phase in (0u32..220).step_by(10) {
        for open_ms in (30u32..=200).step_by(10) {
            let mut rig = Rig::new(0, 400.0);
            rig.online_by(12_000);
            rig.charger = Box::new(move |t| t >= 12_000 && ((t + phase) / 110) % 2 == 1);
            rig.shutdown =
                Box::new(move |t| t >= 1_000 && !(13_000..13_000 + open_ms).contains(&t));
            let before = rig.closures.len();
            rig.run_to(15_000);
            for &(_, p) in &rig.closures[before..] {
                if worst.is_none_or(|(_, _, w)| p < w) {
                    worst = Some((phase, open_ms, p));
                }
            }
        }
    }
    if let Some((phase, open_ms, lowest)) = worst {
        assert!(
            lowest >= 90.0,
            "phase {phase}, open {open_ms}: {lowest:.1} %"
        );
    }
}

// ---------------------------------------------------------------------------------------
// Held? Fretting bursts of 4-7 edges (the spread rule's side of the few-periods rule), while
// ONLINE and while a failed discharge is watched.
// ---------------------------------------------------------------------------------------

fn jitter(k: u32, span: u32) -> u32 {
    let mut x = k.wrapping_mul(0x9E37_79B9) ^ 0x85EB_CA6B;
    x ^= x >> 15;
    x = x.wrapping_mul(0x2C1B_3C6D);
    x ^= x >> 12;
    x % span
}

fn bursts(from_ms: u32, cycle_us: u32, closed_us: u32) -> EdgeFilter {
    Box::new(move |converter, at_us| {
        if converter != 1 || at_us < from_ms * 1_000 {
            return true;
        }
        let k = at_us / cycle_us;
        let open_at = k * cycle_us + 1_000 + jitter(k, cycle_us / 4);
        (open_at..open_at + closed_us).contains(&at_us)
    })
}

#[test]
fn longer_fretting_bursts_never_read_a_live_tractive_system_dead() {
    let mut failures = Vec::new();
    for cycle_us in [10_000u32, 20_000] {
        for closed_us in [700u32, 900, 1_100, 1_500, 2_500] {
            // ONLINE.
            let mut rig = Rig::new(0, 400.0);
            rig.online_by(12_000);
            rig.edge_pass = bursts(12_000, cycle_us, closed_us);
            while rig.rel() < 16_000 {
                rig.ms();
                if rig.rel() % 10 != 0 {
                    continue;
                }
                let status = rig.pcc.status();
                let dead = status.pcc_tractive_voltage < 60.0
                    && !status.pcc_error_tractive_silent
                    && !status.pcc_tractive_no_pulses;
                if rig.plant.tractive_v >= 60.0 && (dead || rig.pcc.handover().is_ok()) {
                    failures.push(format!("ONLINE {closed_us}/{cycle_us}: at {}", rig.rel()));
                    break;
                }
            }
            // A failed discharge after the circuit opened.
            let mut rig = Rig::new(0, 400.0);
            rig.online_by(12_000);
            rig.plant.discharge_failed = true;
            rig.shutdown = Box::new(|t| (1_000..13_000).contains(&t));
            rig.run_to(15_000);
            rig.edge_pass = bursts(15_000, cycle_us, closed_us);
            rig.run_to(27_000);
            let errors = rig.pcc.errors();
            if !(errors.no_discharge || errors.tractive_silent) {
                failures.push(format!("discharge {closed_us}/{cycle_us}: [{errors}]"));
            }
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

// A in closed loop (the car model's own AIR+ contacts, the CCM driving): the shutdown circuit
// opens for 70 ms as the PCC enters ONLINE.
#[test]
fn closed_loop_bounce_as_online_is_entered() {
    use aer_car_model::chassis::Mode;
    use aer_car_model::driver::Cycle;
    use aer_car_model::faults::{Fault, FaultPlan, Injection};
    use aer_car_model::{ClosedLoop, ModelParams, NoTap};
    let mut run = ClosedLoop::new(
        ModelParams::NOMINAL,
        Mode::Road,
        Cycle::Skidpad,
        FaultPlan::NONE,
    );
    while run.car.pcc.state() != State::Online {
        run.step(&mut NoTap);
        assert!(run.now_ms() < 30_000, "never ONLINE");
    }
    let now = run.now_ms();
    let first = run.car.pcc.closures;
    let plan = FaultPlan::NONE.with(Injection {
        fault: Fault::ShutdownOpen,
        from_ms: now + 1,
        until_ms: now + 71,
    });
    run.retune(run.car.params, plan);
    run.run_until(now + 3_000, &mut NoTap);
    let closures = run.car.pcc.closures;
    assert!(
        closures.lowest_percent.is_none_or(|p| p >= 90.0),
        "closures {} (before the bounce {}), lowest {:?} %; PCC {:?} [{}]",
        closures.count,
        first.count,
        closures.lowest_percent,
        run.car.pcc.state(),
        run.car.pcc.logic.errors()
    );
}
