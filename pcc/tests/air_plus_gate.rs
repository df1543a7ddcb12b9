//! The PCC bring-up's pin 11 (AIR+) behind its HV gate, through the chain the image runs:
//! edges time-stamped in microseconds, one `FrequencyMeter` per converter read at every
//! 10 ms step, the readings as volts, the gate. A converter without pulses is unknown and
//! never arms anything; once armed, pin 11 drops at the first step a converter goes silent
//! or reads 60 V, not at the next once-a-second report.

use aer_console::hv_gate::{HvReading, HvRefusal, Unknown};
use aer_pcc::bringup::{AirPlusAnswer, AirPlusBench, converter_reading};
use aer_pcc::measurement::FrequencyMeter;
use aer_pcc::{TASK_PERIOD_MS, VfConfig};

const VF: VfConfig = VfConfig::PCC_BOARD;

/// A converter's input: pulses at the frequency `volts` make, or none.
#[derive(Clone, Copy)]
enum Input {
    Volts(f32),
    Unplugged,
}

/// The image's inputs and meters, stepped every 10 ms.
struct Bench {
    meters: [FrequencyMeter; 2],
    next_edge_us: [Option<u64>; 2],
    now_us: u64,
    air_plus: AirPlusBench,
}

impl Bench {
    fn new() -> Self {
        Self {
            meters: [FrequencyMeter::default(); 2],
            next_edge_us: [None; 2],
            now_us: 0,
            air_plus: AirPlusBench::new(),
        }
    }

    fn now_ms(&self) -> u32 {
        (self.now_us / 1_000) as u32
    }

    /// Runs the edge interrupt for 10 ms of `inputs`, then reads both meters as a bench step
    /// does.
    fn step(&mut self, inputs: [Input; 2]) -> [HvReading; 2] {
        let end_us = self.now_us + u64::from(TASK_PERIOD_MS) * 1_000;
        for ((meter, next), input) in self
            .meters
            .iter_mut()
            .zip(self.next_edge_us.iter_mut())
            .zip(inputs)
        {
            let Input::Volts(volts) = input else {
                *next = None;
                continue;
            };
            let period_us = (1e6 / f64::from(VF.hz_for_volts(volts))) as u64;
            let mut edge = next.unwrap_or(self.now_us);
            while edge < end_us {
                meter.on_edge(edge as u32);
                edge += period_us;
            }
            *next = Some(edge);
        }
        self.now_us = end_us;
        let now_ms = self.now_ms();
        let timeout_us = VF.edge_timeout_us;
        let now_us = self.now_us as u32;
        self.meters
            .each_mut()
            .map(|meter| converter_reading(meter.reading(now_us, timeout_us), &VF, now_ms))
    }

    /// Steps `inputs` for `ms`, running the gate's per-step check; the last readings.
    fn run(&mut self, inputs: [Input; 2], ms: u32) -> [HvReading; 2] {
        let mut readings = [HvReading::Silent; 2];
        for _ in 0..ms / TASK_PERIOD_MS {
            readings = self.step(inputs);
            let now = self.now_ms();
            let _ = self.air_plus.step(now, readings);
        }
        readings
    }
}

const BENCH_SUPPLY: [Input; 2] = [Input::Volts(24.0), Input::Volts(24.0)];

#[test]
fn unplugged_converters_cannot_arm_air_plus_however_the_word_is_typed() {
    let mut bench = Bench::new();
    // Step 6d's set-up: both converters disconnected. With the old once-a-second 0 Hz = 0 V
    // reading this confirmed and closed AIR+.
    let readings = bench.run([Input::Unplugged, Input::Unplugged], 500);
    let now = bench.now_ms();
    let refusal = bench
        .air_plus
        .confirm(now, readings)
        .expect_err("no pulses is no evidence");
    assert!(
        matches!(
            refusal,
            HvRefusal::Unknown {
                name: "accumulator (pin 14)",
                why: Unknown::Silent(_)
            }
        ),
        "{refusal:?}"
    );
    assert!(matches!(
        bench.air_plus.set(true, now, readings),
        AirPlusAnswer::Refused(HvRefusal::NotConfirmed)
    ));
    assert!(!bench.air_plus.air_plus());
    // One converter alive is not enough.
    let readings = bench.run([Input::Volts(24.0), Input::Unplugged], 500);
    let now = bench.now_ms();
    assert!(bench.air_plus.confirm(now, readings).is_err());
}

#[test]
fn live_converters_below_60_v_arm_it_and_it_drops_at_the_first_step_a_reading_fails() {
    for (name, failure) in [
        (
            "tractive system rises to 60 V",
            [Input::Volts(24.0), Input::Volts(60.5)],
        ),
        (
            "tractive converter unplugged",
            [Input::Volts(24.0), Input::Unplugged],
        ),
        (
            "accumulator rises to 300 V",
            [Input::Volts(300.0), Input::Volts(24.0)],
        ),
    ] {
        let mut bench = Bench::new();
        let readings = bench.run(BENCH_SUPPLY, 300);
        let now = bench.now_ms();
        assert_eq!(bench.air_plus.confirm(now, readings), Ok(()), "{name}");
        assert_eq!(
            bench.air_plus.set(true, now, readings),
            AirPlusAnswer::High,
            "{name}"
        );
        bench.run(BENCH_SUPPLY, 1_000);
        assert!(bench.air_plus.air_plus(), "{name}: held while all is well");
        // The failure starts now; count the steps until pin 11 is low.
        let started_ms = bench.now_ms();
        let mut dropped_after = None;
        for _ in 0..200 {
            let readings = bench.step(failure);
            let now = bench.now_ms();
            if let Some(why) = bench.air_plus.step(now, readings) {
                assert!(!bench.air_plus.air_plus());
                dropped_after = Some((now - started_ms, why));
                break;
            }
        }
        let (after_ms, why) = dropped_after.unwrap_or_else(|| panic!("{name}: never dropped"));
        // A voltage step shows within two steps (the first window still holds the last
        // period of the old rate); silence once the converter's edge timeout (100 ms: the
        // slowest pulse train it still measures) has passed without an edge.
        let limit_ms = match failure {
            [_, Input::Unplugged] => VF.edge_timeout_us / 1_000 + TASK_PERIOD_MS,
            _ => 2 * TASK_PERIOD_MS,
        };
        assert!(after_ms <= limit_ms, "{name}: {after_ms} ms ({why})");
        // Dropped means disarmed: it does not come back when the readings recover.
        let readings = bench.run(BENCH_SUPPLY, 300);
        let now = bench.now_ms();
        assert!(
            matches!(
                bench.air_plus.set(true, now, readings),
                AirPlusAnswer::Refused(HvRefusal::NotConfirmed)
            ),
            "{name}"
        );
    }
}

#[test]
fn the_confirmation_runs_out_and_off_revokes_it() {
    let mut bench = Bench::new();
    let readings = bench.run(BENCH_SUPPLY, 300);
    let now = bench.now_ms();
    assert_eq!(bench.air_plus.confirm(now, readings), Ok(()));
    assert_eq!(bench.air_plus.set(true, now, readings), AirPlusAnswer::High);
    let line = bench.air_plus.line(now, readings);
    assert_eq!(
        line.to_string(),
        "pin 11 (AIR+) HIGH; HV gate armed for 30 s more"
    );
    bench.run(BENCH_SUPPLY, 30_000);
    assert!(!bench.air_plus.air_plus(), "expired after 30 s");
    let readings = bench.run(BENCH_SUPPLY, 100);
    let now = bench.now_ms();
    assert_eq!(bench.air_plus.confirm(now, readings), Ok(()));
    assert_eq!(bench.air_plus.set(true, now, readings), AirPlusAnswer::High);
    bench.air_plus.all_off();
    assert!(!bench.air_plus.air_plus());
    assert!(matches!(
        bench.air_plus.set(true, now, readings),
        AirPlusAnswer::Refused(HvRefusal::NotConfirmed)
    ));
}
