//! Safety properties over arbitrary input sequences (proptest).
//!
//! - AIR+ never closes unless the precharge that led there reached the target, and reached it
//!   no sooner than the minimum time after it started.
//! - A BMS timeout seen while energised releases AIR+ (and ends the state) in the same step,
//!   i.e. within one task period.
//! - AIR+ (the board's one relay output, pin 11) is high in ONLINE and CHARGING only: never in
//!   STANDBY, PRECHARGE, DISCHARGE or ERROR.
//! - With a real RC precharge, the outcome is exactly what the time to 90 % predicts.
//! - A converter that falls silent after reading 60 V or more, or while energised, and a
//!   thermistor at the resistor's limit release AIR+ in the same step; once a cause that
//!   needs a power cycle has latched, AIR+ never closes again.

use aer_pcc::measurement::Pulses;
use aer_pcc::{Inputs, Precharge, PrechargeConfig, Relays, State};
use proptest::prelude::*;

const CONFIG: PrechargeConfig = PrechargeConfig::CAR;

/// One control period's worth of stimulus.
#[derive(Debug, Clone)]
struct Tick {
    dt_ms: u32,
    accumulator_v: f32,
    tractive_v: f32,
    bms_frame: bool,
    charger_safety: bool,
    pulses: [Pulses; 2],
    resistor_c: [Option<f32>; 2],
}

fn pulses() -> impl Strategy<Value = Pulses> {
    prop_oneof![
        20 => Just(Pulses::Live),
        1 => (prop_oneof![Just(0.0f32), 0.0f32..700.0], 0u32..1_000)
            .prop_map(|(last_v, since_ms)| Pulses::Silent { last_v, since_ms }),
    ]
}

fn resistor_c() -> impl Strategy<Value = Option<f32>> {
    prop_oneof![
        20 => Just(Some(25.0f32)),
        1 => Just(None),
        1 => (-40.0f32..120.0).prop_map(Some),
    ]
}

fn tick() -> impl Strategy<Value = Tick> {
    (
        prop_oneof![Just(10u32), 1u32..40, 0u32..2_000],
        prop_oneof![Just(400.0f32), 0.0f32..700.0, Just(f32::NAN)],
        prop_oneof![0.0f32..700.0, Just(400.0f32), Just(361.0f32)],
        prop::bool::weighted(0.9),
        prop::bool::weighted(0.2),
        [pulses(), pulses()],
        [resistor_c(), resistor_c()],
    )
        .prop_map(
            |(dt_ms, accumulator_v, tractive_v, bms_frame, charger_safety, pulses, resistor_c)| {
                Tick {
                    dt_ms,
                    accumulator_v,
                    tractive_v,
                    bms_frame,
                    charger_safety,
                    pulses,
                    resistor_c,
                }
            },
        )
}

/// Sequences biased towards completing a precharge: ramps of the tractive voltage.
fn ramp() -> impl Strategy<Value = Vec<Tick>> {
    (5_000u32..12_000, 10u32..=10, 0.5f32..1.2).prop_map(|(duration_ms, dt_ms, overshoot)| {
        let steps = duration_ms / dt_ms + 30;
        (0..steps)
            .map(|i| {
                let fraction = (i * dt_ms) as f32 / duration_ms as f32;
                Tick {
                    dt_ms,
                    accumulator_v: 400.0,
                    tractive_v: (400.0 * fraction * overshoot).min(400.0),
                    bms_frame: true,
                    charger_safety: false,
                    pulses: [Pulses::Live; 2],
                    resistor_c: [Some(25.0); 2],
                }
            })
            .collect()
    })
}

/// Runs `ticks` and checks every invariant after every step.
fn check_sequence(start_ms: u32, ticks: &[Tick]) -> Result<(), TestCaseError> {
    let mut pcc = Precharge::new(CONFIG, start_ms);
    prop_assert_eq!(pcc.relays(), Relays::ALL_OPEN);
    let mut now = start_ms;
    let mut bms_seen = None;
    let mut precharge_started = None;
    let mut air_plus_allowed = false;
    let mut latched = false;
    for tick in ticks {
        now = now.wrapping_add(tick.dt_ms);
        if tick.bms_frame {
            bms_seen = Some(now);
        }
        let before = pcc.state();
        let inputs = Inputs {
            now_ms: now,
            accumulator_v: tick.accumulator_v,
            tractive_v: tick.tractive_v,
            raw_v: [tick.accumulator_v, tick.tractive_v],
            pulses: tick.pulses,
            bms_last_seen_ms: bms_seen,
            charger_safety: tick.charger_safety,
            resistor_c: tick.resistor_c,
        };
        let relays = pcc.step(&inputs);
        let after = pcc.state();

        // A converter silent where silence cannot mean 0 V, or a hot resistor, opens AIR+
        // in this very step and latches.
        let unknown_hv = tick.pulses.iter().any(|pulses| match pulses {
            Pulses::Silent { last_v, .. } => {
                *last_v >= CONFIG.discharged_v || before.is_energised()
            }
            Pulses::Live => false,
        });
        let hot = tick
            .resistor_c
            .iter()
            .flatten()
            .any(|c| *c >= CONFIG.resistor_limit_c);
        if unknown_hv || hot {
            prop_assert_eq!(
                relays,
                Relays::ALL_OPEN,
                "silent converter or hot resistor in {:?}",
                before
            );
            prop_assert_eq!(after, State::Error);
        }
        latched |= pcc.errors().needs_reset();
        if latched {
            prop_assert!(
                !relays.air_plus,
                "AIR+ closed after a latched cause: {}",
                pcc.errors()
            );
        }

        // Faults seen while energised open everything in this very step.
        let bms_stale = bms_seen.is_none_or(|seen| now.wrapping_sub(seen) > CONFIG.bms_timeout_ms);
        if before.is_energised() && bms_stale {
            prop_assert_eq!(relays, Relays::ALL_OPEN, "fault in {:?}", before);
            prop_assert_eq!(after, State::Error);
        }
        if !after.is_energised() {
            prop_assert_eq!(relays, Relays::ALL_OPEN, "{:?}", after);
        }
        prop_assert_eq!(relays, Relays::for_state(after));
        prop_assert_eq!(
            relays.air_plus,
            matches!(after, State::Online | State::Charging),
            "{:?}",
            after
        );

        // Track the precharge that could allow AIR+.
        if after == State::Precharge && before != State::Precharge {
            precharge_started = Some(now);
            air_plus_allowed = false;
        }
        if before == State::Precharge && matches!(after, State::Online | State::Charging) {
            let started = precharge_started.expect("precharge has a start");
            prop_assert!(now.wrapping_sub(started) >= CONFIG.min_time_ms);
            prop_assert!(pcc.progress_percent() >= CONFIG.target_percent);
            air_plus_allowed = true;
        }
        if !after.is_energised() {
            air_plus_allowed = false;
        }
        if relays.air_plus {
            prop_assert!(
                air_plus_allowed,
                "AIR+ closed without a completed precharge"
            );
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2_000))]

    #[test]
    fn random_inputs_never_break_a_safety_rule(
        start_ms in any::<u32>(),
        ticks in prop::collection::vec(tick(), 1..400),
    ) {
        check_sequence(start_ms, &ticks)?;
    }

    #[test]
    fn ramps_with_faults_never_break_a_safety_rule(
        start_ms in any::<u32>(),
        mut ticks in ramp(),
        faults in prop::collection::vec((any::<prop::sample::Index>(), tick()), 0..4),
    ) {
        for (index, fault) in faults {
            let at = index.index(ticks.len());
            ticks[at] = Tick { dt_ms: ticks[at].dt_ms, ..fault };
        }
        check_sequence(start_ms, &ticks)?;
    }

    /// An RC precharge (started by the hardware when the shutdown circuit closes) reaches 90 %
    /// at tau x ln(10); sampled every 10 ms, the controller starts its timer at the first
    /// sample at or above the start threshold and goes ONLINE exactly when the first sample at
    /// or above the target falls within [min, max] of that, and errors otherwise.
    #[test]
    fn an_rc_precharge_ends_as_its_time_constant_predicts(tau_ms in 2_000.0f64..5_000.0) {
        let mut pcc = Precharge::new(CONFIG, 0);
        let ready = |now_ms, tractive_v| Inputs {
            now_ms,
            accumulator_v: 400.0,
            tractive_v,
            raw_v: [400.0, tractive_v],
            pulses: [Pulses::Live; 2],
            bms_last_seen_ms: Some(now_ms),
            charger_safety: false,
            resistor_c: [Some(25.0); 2],
        };
        let closed_ms = CONFIG.standby_settle_ms + 500;
        let mut started = None;
        let mut first_at_target = None;
        for k in 0..=1_300u32 {
            let now = k * 10;
            let tractive_v = if now < closed_ms {
                0.0
            } else {
                (400.0 * (1.0 - (-f64::from(now - closed_ms) / tau_ms).exp())) as f32
            };
            let progress = 100.0 * tractive_v / 400.0;
            if started.is_none() && progress >= CONFIG.start_percent {
                started = Some(now);
            }
            if first_at_target.is_none() && progress >= CONFIG.target_percent {
                first_at_target = Some(now);
            }
            pcc.step(&ready(now, tractive_v));
            if started.is_some() && pcc.state() != State::Precharge {
                break;
            }
        }
        let first_at_target = first_at_target.zip(started).map(|(at, start)| at - start);
        let expected = match first_at_target {
            Some(t) if t < CONFIG.min_time_ms => State::Error,
            Some(t) if t <= CONFIG.max_time_ms => State::Online,
            _ => State::Error,
        };
        prop_assert_eq!(pcc.state(), expected, "tau {} ms, at target after {:?} ms", tau_ms, first_at_target);
        let errors = pcc.errors();
        match first_at_target {
            Some(t) if t < CONFIG.min_time_ms => prop_assert!(errors.too_fast),
            Some(t) if t > CONFIG.max_time_ms => prop_assert!(errors.too_slow),
            None => prop_assert!(errors.too_slow),
            _ => prop_assert!(!errors.any()),
        }
    }
}
