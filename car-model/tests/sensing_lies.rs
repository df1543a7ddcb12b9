//! The PCC's sensing lying in ways a bench rarely shows, through the real measurement chain:
//! the car model's precharge circuit and pulse generators, edges dropped or rescaled on their
//! way to the real `VoltageChannel`s, and the real `Precharge` state machine (no CCM, no
//! AIR operate delay: the PCC alone). Each test asserts the safe outcome: the pack never
//! reconnected through AIR+ below the precharge target, a live tractive system never reported
//! dead, the rules' discharge check never defeated.

use aer_car_model::precharge::{PrechargePlant, PulseGenerator};
use aer_pcc::constants::CONVERTERS;
use aer_pcc::measurement::VoltageChannel;
use aer_pcc::{Inputs, Precharge, PrechargeConfig, Relays, State, TASK_PERIOD_MS};

/// What breaks, per millisecond, in the rig.
type EdgeFilter = Box<dyn FnMut(usize, u32) -> bool>;
type Schedule = Box<dyn FnMut(u32) -> bool>;

struct Rig {
    pcc: Precharge,
    plant: PrechargePlant,
    channels: [VoltageChannel; 2],
    gens: [PulseGenerator; 2],
    relays: Relays,
    now_ms: u32,
    start_ms: u32,
    bms_seen: Option<u32>,
    /// Frequency multiplier per converter (scale error: 1.245 = a shorted 510k of five).
    scale: [f32; 2],
    /// Per converter, per edge time (us): whether the edge reaches the pin (fretting).
    edge_pass: EdgeFilter,
    /// Per ms (relative to start): shutdown circuit closed.
    shutdown: Schedule,
    /// Per ms (relative to start): the BMS sends a frame this ms (stamped at the next step).
    bms: Schedule,
    bms_pending: bool,
    /// Per 10 ms step (relative ms): the BMS's charger-safety bit in its last frame.
    charger: Schedule,
    /// (relative ms, true progress %) at each moment the pack got connected without resistor.
    closures: Vec<(u32, f32)>,
    was_connected: bool,
    /// Every (relative ms, state) change.
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
            now_ms: start_ms,
            start_ms,
            bms_seen: None,
            scale: [1.0; 2],
            edge_pass: Box::new(|_, _| true),
            shutdown: Box::new(|t| t >= 1_000),
            bms: Box::new(|t| t % 10 == 0),
            bms_pending: false,
            charger: Box::new(|_| false),
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

    /// One millisecond: the circuit and the edges of (now, now+1], then the 10 ms step.
    fn ms(&mut self) {
        let rel = self.rel();
        self.plant.shutdown_closed = (self.shutdown)(rel);
        if (self.bms)(rel) {
            self.bms_pending = true;
        }
        let connected = self.plant.connected(self.relays);
        if connected && !self.was_connected {
            let p = self.true_progress();
            self.closures.push((rel, p));
        }
        self.was_connected = connected;
        self.plant.advance(self.relays, 1.0);
        let start_us = self.now_ms.wrapping_mul(1_000);
        let volts = [self.plant.accumulator_v, self.plant.tractive_v];
        for i in 0..2 {
            let hz = CONVERTERS[i].hz_for_volts(volts[i]) * self.scale[i];
            let mut edges = Vec::new();
            self.gens[i].run(start_us, 1_000, hz, |at| edges.push(at));
            for at in edges {
                if (self.edge_pass)(i, at) {
                    self.channels[i].on_edge(at);
                }
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
        let inputs = Inputs {
            now_ms,
            accumulator_v: a.volts,
            tractive_v: t.volts,
            raw_v: [a.raw_volts, t.raw_volts],
            pulses: [a.pulses, t.pulses],
            bms_last_seen_ms: self.bms_seen,
            charger_safety: {
                let rel = self.rel();
                (self.charger)(rel)
            },
            resistor_c: [Some(25.0); 2],
        };
        let before = self.pcc.state();
        self.relays = self.pcc.step(&inputs);
        if self.pcc.state() != before {
            let rel = self.rel();
            self.states.push((rel, self.pcc.state()));
        }
    }

    fn run_to(&mut self, rel_ms: u32) {
        while self.rel() < rel_ms {
            self.ms();
        }
    }

    /// Runs a clean precharge (shutdown closed at 1 s) to ONLINE, then on to `rel_ms`.
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

// ---------------------------------------------------------------------------------------
// a tractive converter that reads high (one of the five 510 kOhm divider resistors
// shorted: x1.245) while ONLINE, then a shutdown bounce. The existing bounce proof's own
// criterion: the pack never reconnects below the 90 % precharge target.
// ---------------------------------------------------------------------------------------

#[test]
fn tractive_scale_error_while_online_then_a_bounce_never_reconnects_below_target() {
    let mut worst: Option<(u32, f32)> = None;
    for open_ms in (40u32..=200).step_by(10) {
        let mut rig = Rig::new(0, 400.0);
        rig.online_by(12_000);
        // The divider resistor shorts at 12 s (ONLINE, AIR+ closed)...
        rig.scale = [1.0, 1.245];
        rig.run_to(13_000);
        // The tractive system reads 124 % of the pack: the converters disagree, AIR+ opens.
        assert_eq!(rig.pcc.state(), State::Error);
        assert!(rig.pcc.errors().converters_disagree, "{}", rig.pcc.errors());
        // ...and the shutdown circuit bounces open for `open_ms` at 13 s.
        rig.shutdown = Box::new(move |t| t >= 1_000 && !(13_000..13_000 + open_ms).contains(&t));
        let before = rig.closures.len();
        rig.run_to(20_000);
        for &(_, p) in &rig.closures[before..] {
            if worst.is_none_or(|(_, w)| p < w) {
                worst = Some((open_ms, p));
            }
        }
    }
    // AIR+ stays open after the latch: no reconnection at all.
    assert_eq!(worst, None, "reconnected after the converters disagreed");
}

/// Control: the same bounces with a good converter (the repo's own claim).
#[test]
fn control_bounces_with_good_converters_stay_above_target() {
    let mut lowest = 100.0f32;
    for open_ms in (40u32..=200).step_by(10) {
        let mut rig = Rig::new(0, 400.0);
        rig.online_by(12_000);
        rig.shutdown = Box::new(move |t| t >= 1_000 && !(13_000..13_000 + open_ms).contains(&t));
        let before = rig.closures.len();
        rig.run_to(20_000);
        for &(_, p) in &rig.closures[before..] {
            lowest = lowest.min(p);
        }
    }
    assert!(lowest >= 90.0, "{lowest}");
}

// ---------------------------------------------------------------------------------------
// a fretting tractive-converter contact that passes short bursts (2-3 edges) once
// per vibration cycle. Each window holds fewer than 4 periods, so the spread check never
// judges it; the burst's edges read as a low, live voltage. The docs: "pulses too irregular
// to be a voltage ... while ONLINE ... latched: unknown, not 0 V".
// ---------------------------------------------------------------------------------------

/// Deterministic jitter in [0, span).
fn jitter(k: u32, span: u32) -> u32 {
    let mut x = k.wrapping_mul(0x9E37_79B9) ^ 0x85EB_CA6B;
    x ^= x >> 15;
    x = x.wrapping_mul(0x2C1B_3C6D);
    x ^= x >> 12;
    x % span
}

/// Contact closed for `closed_us` once every `cycle_us`, at a jittered phase, from `from_ms`.
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
fn fretting_tractive_converter_while_online_never_reports_a_live_tractive_system_as_dead() {
    for (cycle_us, closed_us) in [
        (10_000u32, 450u32),
        (10_000, 600),
        (20_000, 600),
        (30_000, 600),
    ] {
        let mut rig = Rig::new(0, 400.0);
        rig.online_by(12_000);
        rig.edge_pass = bursts(12_000, cycle_us, closed_us);
        let mut first_bad = None;
        while rig.rel() < 20_000 {
            rig.ms();
            if rig.rel() % 10 != 0 {
                continue;
            }
            let live = rig.plant.tractive_v >= 60.0;
            let status = rig.pcc.status();
            let says_dead = status.pcc_tractive_voltage < 60.0
                && !status.pcc_error_tractive_silent
                && !status.pcc_tractive_no_pulses;
            let unsafe_now = live
                && (rig.pcc.handover().is_ok() || rig.pcc.state() == State::Standby || says_dead);
            if unsafe_now && first_bad.is_none() {
                first_bad = Some((
                    rig.rel(),
                    rig.plant.tractive_v,
                    rig.pcc.state(),
                    status.pcc_tractive_voltage,
                    rig.pcc.errors().to_string(),
                    rig.pcc.handover().is_ok(),
                ));
            }
        }
        assert_eq!(
            first_bad, None,
            "bursts of {closed_us} us every {cycle_us} us: (ms, true TS V, state, reported TS V, \
             errors, handover ok)"
        );
    }
}

// ---------------------------------------------------------------------------------------
// a shutdown contact chattering (open `open_ms`, closed `closed_ms`, repeated)
// while ONLINE, AIR+ sound. The pack must never be reconnected through AIR+ onto a tractive
// system below the 90 % target.
// ---------------------------------------------------------------------------------------

#[test]
fn chattering_shutdown_contact_while_online_never_reconnects_below_target() {
    let mut worst: Option<(u32, u32, f32)> = None;
    for open_ms in (20u32..=80).step_by(2) {
        for closed_ms in [1u32, 2, 3, 5, 8, 13] {
            let mut rig = Rig::new(0, 400.0);
            rig.online_by(12_000);
            let period = open_ms + closed_ms;
            rig.shutdown =
                Box::new(move |t| t >= 1_000 && (t < 13_000 || (t - 13_000) % period >= open_ms));
            let before = rig.closures.len();
            rig.run_to(16_000);
            for &(_, p) in &rig.closures[before..] {
                if worst.is_none_or(|(_, _, w)| p < w) {
                    worst = Some((open_ms, closed_ms, p));
                }
            }
        }
    }
    let (open_ms, closed_ms, lowest) = worst.expect("closures");
    println!("worst: open {open_ms} ms / closed {closed_ms} ms -> {lowest:.2} %");
    assert!(
        lowest >= 90.0,
        "chatter open {open_ms} ms / closed {closed_ms} ms: the pack reconnected through AIR+ onto {lowest:.2} %"
    );
}

#[test]
fn welded_air_plus_under_sub_window_closures_is_named() {
    for closed_ms in [1u32, 2, 3, 4] {
        let mut rig = Rig::new(0, 400.0);
        rig.plant.air_plus_welded = true;
        // Shutdown circuit open from power-up (BMS heard), then closes for `closed_ms`
        // every 500 ms.
        rig.shutdown = Box::new(move |t| t >= 2_000 && (t - 2_000) % 500 < closed_ms);
        rig.run_to(6_000);
        let errors = rig.pcc.errors();
        assert!(
            errors.bypassed,
            "closed {closed_ms} ms with AIR+ welded: {errors} {:?}",
            rig.states
        );
        assert!(!rig.pcc.relays().air_plus);
    }
}

// ---------------------------------------------------------------------------------------
// Timers and the BMS near its 1.5 s timeout.
// ---------------------------------------------------------------------------------------

/// A full precharge and an ONLINE period across the millisecond counter's wrap and across
/// the microsecond counter's (every 71.6 min), then a BMS gap straddling the wrap.
#[test]
fn wrapped_timers_precharge_and_bms_timeout() {
    for start in [u32::MAX - 5_000, 4_294_967 - 6_000, u32::MAX - 11_000] {
        let mut rig = Rig::new(start, 400.0);
        rig.online_by(12_000);
        let timing = rig.pcc.last_precharge().expect("timed");
        let reached = timing.reached_ms.expect("reached");
        assert!((8_200..=9_200).contains(&reached), "{timing}");
        // BMS stops at 13 s: AIR+ must open within the 1.5 s timeout plus one period.
        rig.bms = Box::new(|t| t % 10 == 0 && t < 13_000);
        rig.run_to(14_600);
        assert_eq!(
            rig.pcc.state(),
            State::Error,
            "start {start}: {:?}",
            rig.states
        );
        assert!(rig.pcc.errors().bms_timeout);
        let opened = rig
            .states
            .iter()
            .find(|(_, s)| *s == State::Error)
            .unwrap()
            .0;
        assert!(
            opened <= 13_000 + 1_500 + 10,
            "start {start}: opened at {opened}"
        );
        assert!(!rig.pcc.relays().air_plus);
    }
}

/// BMS frames late and jittery around the timeout: a gap just under keeps ONLINE, a gap just
/// over opens AIR+, whatever the phase of the frames against the 10 ms step.
#[test]
fn bms_gaps_around_the_timeout() {
    for phase in 0u32..10 {
        for gap in [
            1_480u32, 1_495, 1_499, 1_500, 1_501, 1_505, 1_509, 1_511, 1_520,
        ] {
            let mut rig = Rig::new(0, 400.0);
            rig.online_by(12_000);
            let last = 13_000 + phase;
            rig.bms = Box::new(move |t| {
                (t % 10 == 0 && t < 13_000) || t == last || (t >= last + gap && t % 10 == 0)
            });
            rig.run_to(last + gap + 100);
            let opened = rig.states.iter().any(|(_, s)| *s == State::Error);
            // The frame is stamped at the next 10 ms step; the PCC's own timeout is judged on
            // those stamps: a gap of more than 1.5 s plus one period must open AIR+.
            if gap > 1_500 + TASK_PERIOD_MS {
                assert!(opened, "gap {gap} phase {phase}: still ONLINE");
            }
            if gap < 1_500 - TASK_PERIOD_MS {
                assert!(!opened, "gap {gap} phase {phase}: opened");
            }
        }
    }
}

// ---------------------------------------------------------------------------------------
// the BMS's charger-safety bit changing every frame (a chattering charger-safety
// output, garbled BMS frames) while ONLINE. Every ONLINE <-> CHARGING transition resets the
// "two windows in a row below 95 %" counter, so a falling tractive system is never seen.
// ---------------------------------------------------------------------------------------

#[test]
fn charger_safety_chatter_does_not_blind_the_online_drop_check() {
    let mut failures = Vec::new();
    for (name, toggling) in [
        ("steady (control)", Box::new(|_: u32| false) as Schedule),
        (
            "toggling every 10 ms",
            Box::new(|t: u32| (t / 10) % 2 == 1) as Schedule,
        ),
        (
            "random per frame",
            Box::new(|t: u32| jitter(t / 10, 2) == 1) as Schedule,
        ),
    ] {
        let mut worst: Option<(u32, f32)> = None;
        let mut slowest = 0u32;
        for open_ms in (40u32..=400).step_by(20) {
            let mut rig = Rig::new(0, 400.0);
            rig.online_by(12_000);
            rig.charger = Box::new(|_| false);
            let mut toggles = {
                // Each rig needs its own schedule: rebuild from the name.
                match name {
                    "steady (control)" => Box::new(|_: u32| false) as Schedule,
                    "toggling every 10 ms" => Box::new(|t: u32| (t / 10) % 2 == 1) as Schedule,
                    _ => Box::new(|t: u32| jitter(t / 10, 2) == 1) as Schedule,
                }
            };
            rig.charger = Box::new(move |t| t >= 12_500 && toggles(t));
            rig.shutdown =
                Box::new(move |t| t >= 1_000 && !(13_000..13_000 + open_ms).contains(&t));
            let before = rig.closures.len();
            let mut left_online_at = None;
            while rig.rel() < 16_000 {
                rig.ms();
                if left_online_at.is_none()
                    && rig.rel() >= 13_000
                    && !matches!(rig.pcc.state(), State::Online | State::Charging)
                {
                    left_online_at = Some(rig.rel() - 13_000);
                }
            }
            // Bounces of 100 ms or more are seen by a PCC with a steady charger-safety bit
            // (the control run below): judge the detection time on those.
            if open_ms >= 100 {
                slowest = slowest.max(left_online_at.unwrap_or(u32::MAX));
            }
            for &(_, p) in &rig.closures[before..] {
                if worst.is_none_or(|(_, w)| p < w) {
                    worst = Some((open_ms, p));
                }
            }
        }
        let _ = toggling;
        println!("{name}: slowest detection {slowest} ms, worst reconnection {worst:?}");
        if let Some((open_ms, lowest)) = worst
            && lowest < 90.0
        {
            failures.push(format!(
                "charger safety {name}: a {open_ms} ms shutdown bounce reconnected the pack \
                 through AIR+ onto {lowest:.1} % of it"
            ));
        }
        if slowest > 60 {
            failures.push(format!(
                "charger safety {name}: ONLINE/CHARGING held {slowest} ms after the shutdown opened"
            ));
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// The same through the whole closed loop with the model's own fault list: garbled BMS frames
/// (random bytes: the charger-safety bit random per frame) and a shutdown bounce, the repo's
/// own bounce criterion (hardware_lies.rs: never below 90 %).
#[test]
fn closed_loop_garbled_bms_frames_and_a_bounce() {
    use aer_car_model::chassis::Mode;
    use aer_car_model::driver::Cycle;
    use aer_car_model::faults::{Fault, FaultPlan, Injection, Node};
    use aer_car_model::{ClosedLoop, ModelParams, NoTap};
    let mut worst: Option<(u32, u32, f32)> = None;
    for seed in 1u32..=8 {
        let params = ModelParams {
            seed,
            ..ModelParams::NOMINAL
        };
        let mut base = ClosedLoop::new(params, Mode::Road, Cycle::Skidpad, FaultPlan::NONE);
        assert!(base.start_up(20_000));
        base.run_until(base.now_ms() + 3_000, &mut NoTap);
        for open_ms in (40u32..=400).step_by(20) {
            let mut run = base.clone();
            run.car.pcc.closures = Default::default();
            let now = run.now_ms();
            let before = run.car.pcc.closures;
            let plan = FaultPlan::NONE
                .with(Injection {
                    fault: Fault::GarbledFrames(Node::Bms),
                    from_ms: now,
                    until_ms: u32::MAX,
                })
                .with(Injection {
                    fault: Fault::ShutdownOpen,
                    from_ms: now + 1_000,
                    until_ms: now + 1_000 + open_ms,
                });
            run.retune(run.car.params, plan);
            run.run_until(now + 4_000, &mut NoTap);
            let closures = run.car.pcc.closures;
            if closures.count > before.count {
                let lowest = closures.lowest_percent.expect("closure");
                if worst.is_none_or(|(_, _, w)| lowest < w) {
                    worst = Some((seed, open_ms, lowest));
                }
            }
        }
    }
    println!("closed loop, garbled BMS: worst (seed, open ms, %) {worst:?}");
    if let Some((_, open_ms, lowest)) = worst {
        assert!(
            lowest >= 90.0,
            "garbled BMS frames, {open_ms} ms bounce: pack reconnected onto {lowest:.1} %"
        );
    }
}

/// A converter's scale drifting during the precharge (an LM331 warming up): the timing window
/// bounds where AIR+ can close. Holds if every closure is at 88 % or more (the window's 8.2 s
/// on the modelled 3.8 s time constant is 88.4 %).
#[test]
fn scale_drifting_during_precharge_closes_only_inside_the_window() {
    let mut report = Vec::new();
    for converter in 0..2usize {
        for drift in [
            -0.2f32, -0.1, -0.05, -0.02, -0.01, -0.005, 0.005, 0.01, 0.015, 0.02, 0.05, 0.1, 0.2,
        ] {
            for (from, to) in [(1_000u32, 10_000u32), (7_000, 9_500), (8_000, 8_400)] {
                let mut rig = Rig::new(0, 400.0);
                let mut t = 0u32;
                while t < 14_000 {
                    let f = ((t.saturating_sub(from)) as f32 / (to - from) as f32).min(1.0);
                    let mut scale = [1.0f32; 2];
                    // Positive drift: the tractive reading up, or the accumulator reading down.
                    scale[converter] = if converter == 1 {
                        1.0 + drift * f
                    } else {
                        1.0 / (1.0 + drift * f)
                    };
                    rig.scale = scale;
                    rig.ms();
                    t = rig.rel();
                }
                for &(at, p) in &rig.closures {
                    report.push((converter, drift, from, to, at, p));
                }
            }
        }
    }
    let worst =
        report
            .iter()
            .cloned()
            .fold(None, |w: Option<(usize, f32, u32, u32, u32, f32)>, r| {
                if w.is_none_or(|w| r.5 < w.5) {
                    Some(r)
                } else {
                    w
                }
            });
    println!(
        "closures: {}, worst (converter, drift, from, to, at, %): {worst:?}",
        report.len()
    );
    if let Some(w) = worst {
        assert!(w.5 >= 88.0, "{w:?}");
    }
}

/// The same fretting after the shutdown circuit opened with the discharge circuit failed: the
/// rules' 5 s discharge check (`no-discharge`) must latch while the tractive system stays up.
#[test]
fn fretting_tractive_converter_does_not_defeat_no_discharge() {
    let mut failures = Vec::new();
    for (cycle_us, closed_us) in [(10_000u32, 450u32), (10_000, 600), (20_000, 600)] {
        let mut rig = Rig::new(0, 400.0);
        rig.online_by(12_000);
        rig.plant.discharge_failed = true;
        rig.shutdown = Box::new(|t| (1_000..13_000).contains(&t));
        rig.run_to(15_000);
        assert_eq!(rig.pcc.state(), State::Error, "{:?}", rig.states);
        rig.edge_pass = bursts(15_000, cycle_us, closed_us);
        rig.run_to(27_000);
        let errors = rig.pcc.errors();
        if !(errors.no_discharge || errors.tractive_silent) {
            failures.push(format!(
                "bursts {closed_us}/{cycle_us} us: TS still {:.0} V 14 s after the shutdown opened; \
                 PCC {:?} reads {:.1} V, errors [{errors}], states {:?}, handover ok: {}",
                rig.plant.tractive_v,
                rig.pcc.state(),
                rig.pcc.tractive_v(),
                rig.states,
                rig.pcc.handover().is_ok()
            ));
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}
