//! Accumulator and tractive-system voltages from the V/F converters' pulse trains.
//!
//! The edge interrupt time-stamps every rising edge ([`FrequencyMeter::on_edge`]); the control
//! task takes one sample per period ([`FrequencyMeter::sample`]). Periods are measured edge to
//! edge across sample windows, so a slow pulse train (low voltage, fewer than one edge per
//! window) still reads right instead of alternating with zero.

use crate::constants::VfConfig;
use aer_control::LowPass;

/// A pulse train that missed this many of its own periods has stopped, not slowed: an RC
/// discharge stretches the period by a few percent per 10 ms, a broken wire ends it at once.
pub const STALL_PERIODS: u32 = 8;
/// ... but never sooner than this after the last edge (us).
pub const STALL_MIN_US: u32 = 2_000;
/// Periods a window keeps for its robust reading. A window with more (above about 9.6 kHz,
/// beyond any pack this board measures) is read from its totals alone.
pub const KEPT_PERIODS: usize = 96;
/// An LM331's periods are near uniform, so the window's upper-quartile period is the train's:
/// an edge added between two true ones (interference, a contact that frets) splits a period
/// into two shorter ones, and even several such do not move it. A period shorter than three
/// quarters of it is a fragment; a window with more than a quarter of its periods fragments is
/// irregular: what its edges say is not a voltage.
const FRAGMENT_NUM: u32 = 3;
const FRAGMENT_DEN: u32 = 4;
/// Irregular windows in a row before the train counts as silent: one glitch (a stray edge
/// among a few periods, whose two fragments can fall in two windows) skips them, the reading
/// held; a contact that frets keeps spoiling them and is silence, latched as such where that
/// matters.
pub const IRREGULAR_WINDOWS: u32 = 3;
/// A window of two periods is irregular when the longer is more than this many times the
/// shorter (too few for a median).
const TWO_PERIODS_RATIO: u32 = 2;

/// Edge-to-edge frequency measurement on one input.
///
/// The reading is robust to single edges added or lost: the window's span over its typical
/// (upper-quartile) period, rounded, is the number of true periods it held (an added edge
/// splits a period and changes neither; a lost edge doubles one, which counts as two), and
/// that number over the span is the frequency, as precise as the whole span's time stamps.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrequencyMeter {
    last_edge_us: Option<u32>,
    /// The latest edge ever (not cleared by silence): when the pulses stopped.
    latest_edge_us: Option<u32>,
    periods: u32,
    span_us: u32,
    /// This window's periods (us), the first [`KEPT_PERIODS`] of them.
    kept: [u32; KEPT_PERIODS],
    /// This window's shortest and longest period (us).
    shortest_us: u32,
    longest_us: u32,
    last_hz: f32,
    /// The true period of the last regular window that held whole periods (us).
    last_period_us: Option<u32>,
    /// Irregular windows in a row.
    irregular_windows: u32,
}

impl Default for FrequencyMeter {
    fn default() -> Self {
        Self {
            last_edge_us: None,
            latest_edge_us: None,
            periods: 0,
            span_us: 0,
            kept: [0; KEPT_PERIODS],
            shortest_us: 0,
            longest_us: 0,
            last_hz: 0.0,
            last_period_us: None,
            irregular_windows: 0,
        }
    }
}

impl FrequencyMeter {
    /// Records a rising edge at `now_us` (a free-running microsecond counter that may wrap).
    pub fn on_edge(&mut self, now_us: u32) {
        if let Some(previous) = self.last_edge_us {
            let period = now_us.wrapping_sub(previous);
            if let Some(slot) = usize::try_from(self.periods)
                .ok()
                .and_then(|index| self.kept.get_mut(index))
            {
                *slot = period;
            }
            self.span_us = self.span_us.saturating_add(period);
            self.periods = self.periods.saturating_add(1);
            self.shortest_us = if self.periods == 1 {
                period
            } else {
                self.shortest_us.min(period)
            };
            self.longest_us = self.longest_us.max(period);
        }
        self.last_edge_us = Some(now_us);
        self.latest_edge_us = Some(now_us);
    }

    /// This window's frequency (Hz) and true period (us), or `None` when its periods are
    /// irregular.
    fn judge(&self) -> Option<(f32, u32)> {
        let n = self.periods;
        let mean = || (n as f32 * 1e6 / self.span_us as f32, self.span_us / n);
        match n {
            0 => None,
            1 => Some(mean()),
            2 => (self.longest_us <= self.shortest_us.saturating_mul(TWO_PERIODS_RATIO)).then(mean),
            _ => {
                let count = usize::try_from(n).ok().filter(|n| *n <= KEPT_PERIODS);
                let Some(periods) = count.and_then(|count| self.kept.get(..count)) else {
                    return Some(mean());
                };
                let mut sorted = [0u32; KEPT_PERIODS];
                let sorted = sorted.get_mut(..periods.len())?;
                sorted.copy_from_slice(periods);
                sorted.sort_unstable();
                let typical = *sorted.get(sorted.len() * 3 / 4)?;
                if typical == 0 {
                    return None;
                }
                let fragments = sorted
                    .iter()
                    .filter(|p| {
                        p.saturating_mul(FRAGMENT_DEN) < typical.saturating_mul(FRAGMENT_NUM)
                    })
                    .count();
                if fragments * 4 > sorted.len() {
                    return None;
                }
                let true_periods = (self.span_us.saturating_add(typical / 2) / typical).max(1);
                Some((
                    true_periods as f32 * 1e6 / self.span_us as f32,
                    self.span_us / true_periods,
                ))
            }
        }
    }

    /// The input frequency in Hz over the edges since the last sample.
    ///
    /// Without a complete period since then, the frequency can only have fallen: the result
    /// is capped by the time since the last edge, and is 0 once no edge came for
    /// `edge_timeout_us`, or for [`STALL_PERIODS`] of the train's own last period (a train
    /// that stopped rather than slowed). An irregular window repeats the last reading; the
    /// [`IRREGULAR_WINDOWS`]-th in a row reads 0: what the edges say is not a voltage. After 0
    /// the next edge starts afresh, so a dropout is never measured as one long period.
    pub fn sample(&mut self, now_us: u32, edge_timeout_us: u32) -> f32 {
        let mut stopped = false;
        let hz = match self.last_edge_us {
            None => 0.0,
            Some(_) if self.periods > 0 && self.span_us > 0 => match self.judge() {
                Some((hz, period_us)) => {
                    self.irregular_windows = 0;
                    self.last_period_us = Some(period_us);
                    hz
                }
                None => {
                    self.irregular_windows = self.irregular_windows.saturating_add(1);
                    if self.irregular_windows >= IRREGULAR_WINDOWS {
                        stopped = true;
                        0.0
                    } else {
                        self.last_hz
                    }
                }
            },
            Some(last) => {
                let silent_us = now_us.wrapping_sub(last);
                let stalled = self.last_period_us.is_some_and(|period| {
                    silent_us >= period.saturating_mul(STALL_PERIODS).max(STALL_MIN_US)
                });
                if silent_us >= edge_timeout_us || stalled {
                    stopped = true;
                    0.0
                } else if silent_us == 0 {
                    self.last_hz
                } else {
                    self.last_hz.min(1e6 / silent_us as f32)
                }
            }
        };
        if stopped {
            self.last_edge_us = None;
            self.last_period_us = None;
            self.irregular_windows = 0;
        }
        self.periods = 0;
        self.span_us = 0;
        self.shortest_us = 0;
        self.longest_us = 0;
        self.last_hz = hz;
        hz
    }

    /// [`Self::sample`], or `None` while the input is silent: no period measured yet, no
    /// edge for `edge_timeout_us`, a train that stopped, or one whose periods keep coming
    /// irregular. Silence is not 0 Hz: a converter unplugged, unpowered or broken gives no
    /// pulses either, so whoever needs to tell "low" from "unknown" (the bring-up's HV gate)
    /// reads this.
    pub fn reading(&mut self, now_us: u32, edge_timeout_us: u32) -> Option<f32> {
        let hz = self.sample(now_us, edge_timeout_us);
        (hz > 0.0).then_some(hz)
    }
}

/// One control period's reading of a V/F converter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VoltageSample {
    /// Volts at the high-voltage input, filtered. A silent converter reads 0 here, which is
    /// a number for the state machine's arithmetic, not a measurement: `pulses` says which.
    pub volts: f32,
    /// The same over this window alone, unfiltered: what a fast check (a tractive system
    /// falling away, a rise no resistor allows) judges.
    pub raw_volts: f32,
    /// Whether the converter gives pulses.
    pub pulses: Pulses,
}

/// Whether a converter is alive. An LM331 gives no pulses at 0 V, and none when it is
/// unplugged, unpowered or broken: silence alone cannot tell those apart, so the last voltage
/// it measured decides what its silence may mean.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Pulses {
    /// An edge came within the edge timeout.
    Live,
    /// No edge for the edge timeout, or none since start-up.
    Silent {
        /// The last voltage measured from whole periods before the pulses stopped (V); 0
        /// when it never gave any.
        last_v: f32,
        /// Time since the last edge (ms), or since start-up if there never was one.
        since_ms: u32,
    },
}

impl Pulses {
    /// True while no pulses come.
    pub const fn is_silent(&self) -> bool {
        matches!(self, Self::Silent { .. })
    }
}

/// Pulse train in, filtered high voltage out.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VoltageChannel {
    config: VfConfig,
    meter: FrequencyMeter,
    filter: LowPass,
    /// The filtered voltage at the last sample whose window held a whole period: what the
    /// converter last measured, before any silence capped the reading towards 0.
    last_measured_v: f32,
    /// When the channel was created (us), for a converter that never gave a pulse.
    started_us: Option<u32>,
}

impl VoltageChannel {
    /// A channel sampled every `period_ms`.
    pub fn new(config: VfConfig, period_ms: u32) -> Self {
        Self {
            config,
            meter: FrequencyMeter::default(),
            filter: LowPass::new(config.cutoff_hz, period_ms as f32 / 1000.0),
            last_measured_v: 0.0,
            started_us: None,
        }
    }

    /// Records a rising edge (call from the edge interrupt).
    pub fn on_edge(&mut self, now_us: u32) {
        self.meter.on_edge(now_us);
    }

    /// Volts at the high-voltage input, filtered, and whether the converter gives pulses;
    /// call once per control period.
    pub fn sample(&mut self, now_us: u32) -> VoltageSample {
        let started = *self.started_us.get_or_insert(now_us);
        let whole_period = self.meter.periods > 0;
        let hz = self.meter.sample(now_us, self.config.edge_timeout_us);
        let raw_volts = self.config.volts_for_hz(hz);
        let volts = self.filter.update(raw_volts);
        // Only a regular window measured: an irregular one reads 0, which must not become
        // the voltage a silence is named with.
        if whole_period && hz > 0.0 {
            self.last_measured_v = volts;
        }
        let since_edge_us = now_us.wrapping_sub(self.meter.latest_edge_us.unwrap_or(started));
        let pulses = if hz > 0.0 {
            Pulses::Live
        } else {
            Pulses::Silent {
                last_v: self.last_measured_v,
                since_ms: since_edge_us / 1_000,
            }
        };
        VoltageSample {
            volts,
            raw_volts,
            pulses,
        }
    }

    /// The pulse frequency that `volts` at the high-voltage input produces (for simulations
    /// and tests).
    pub fn hz_for_volts(config: &VfConfig, volts: f32) -> f32 {
        config.hz_for_volts(volts)
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::vec::Vec;

    fn feed(meter: &mut FrequencyMeter, start_us: u32, period_us: u32, edges: u32) -> u32 {
        let mut t = start_us;
        for _ in 0..edges {
            meter.on_edge(t);
            t = t.wrapping_add(period_us);
        }
        t.wrapping_sub(period_us)
    }

    #[test]
    fn frequency_is_measured_edge_to_edge() {
        let mut meter = FrequencyMeter::default();
        // 4,700 Hz is what 400 V gives on the board (about 212.8 us per period).
        let last = feed(&mut meter, 0, 213, 48);
        let hz = meter.sample(last + 50, 100_000);
        assert!((hz - 1e6 / 213.0).abs() < 0.01, "{hz}");
    }

    #[test]
    fn periods_span_sample_windows_for_slow_inputs() {
        let mut meter = FrequencyMeter::default();
        meter.on_edge(1_000);
        assert_eq!(
            meter.sample(5_000, 100_000),
            0.0,
            "one edge is no period yet"
        );
        meter.on_edge(26_000); // 25 ms period = 40 Hz, longer than a 10 ms window
        assert!((meter.sample(30_000, 100_000) - 40.0).abs() < 1e-3);
        // A window without an edge cannot raise the reading, and 1/(silence) caps it.
        assert!((meter.sample(40_000, 100_000) - 40.0).abs() < 1e-3);
        let capped = meter.sample(76_000, 100_000);
        assert!((capped - 20.0).abs() < 1e-3, "{capped}");
    }

    #[test]
    fn no_edges_for_the_timeout_reads_zero() {
        // A slow train (20 ms period): silence up to the timeout is a frequency that fell.
        let mut meter = FrequencyMeter::default();
        let last = feed(&mut meter, 0, 20_000, 3);
        assert!(meter.sample(last + 10, 100_000) > 0.0);
        assert!(meter.sample(last + 99_999, 100_000) > 0.0);
        assert_eq!(meter.sample(last + 100_000, 100_000), 0.0);
        assert_eq!(FrequencyMeter::default().sample(123, 100_000), 0.0);
    }

    #[test]
    fn a_fast_train_that_stops_is_silent_within_a_few_of_its_periods() {
        // 5 kHz (about 425 V on the board) that stops: no RC discharge slows a train this
        // much within milliseconds, so it stopped.
        let mut meter = FrequencyMeter::default();
        let last = feed(&mut meter, 0, 200, 10);
        assert!(meter.sample(last + 10, 100_000) > 0.0);
        assert!(meter.sample(last + 1_999, 100_000) > 0.0, "not before 2 ms");
        assert_eq!(meter.sample(last + 2_000, 100_000), 0.0);
        // A train of 2 ms periods: eight of them.
        let mut meter = FrequencyMeter::default();
        let last = feed(&mut meter, 0, 2_000, 5);
        assert!(meter.sample(last + 15_999, 100_000) > 0.0);
        assert_eq!(meter.sample(last + 16_000, 100_000), 0.0);
    }

    #[test]
    fn silence_reads_as_no_reading_not_as_zero() {
        let mut meter = FrequencyMeter::default();
        assert_eq!(meter.reading(0, 100_000), None, "never an edge");
        meter.on_edge(1_000);
        assert_eq!(meter.reading(2_000, 100_000), None, "one edge is no period");
        let last = feed(&mut meter, 1_000 + 12_822, 12_822, 5);
        let hz = meter.reading(last + 100, 100_000).expect("alive");
        assert!((hz - 1e6 / 12_822.0).abs() < 0.01, "{hz}");
        assert!(meter.reading(last + 99_999, 100_000).is_some());
        assert_eq!(meter.reading(last + 100_000, 100_000), None, "silent again");
    }

    #[test]
    fn the_microsecond_counter_may_wrap() {
        let mut meter = FrequencyMeter::default();
        let last = feed(&mut meter, u32::MAX - 1_000, 250, 20);
        assert!((meter.sample(last.wrapping_add(10), 100_000) - 4_000.0).abs() < 0.01);
    }

    #[test]
    fn the_board_reads_400_volts_from_its_pulse_train() {
        let config = VfConfig::PCC_BOARD;
        let hz = VoltageChannel::hz_for_volts(&config, 400.0);
        assert!((4_700.0..4_760.0).contains(&hz), "{hz}");
        let mut channel = VoltageChannel::new(config, 10);
        // Edges time-stamped to the whole microsecond, as the 1 MHz timer does.
        let period_us = 1e6 / f64::from(hz);
        let mut edge = 0u32;
        let mut volts = 0.0;
        for window in 1..=50u32 {
            let end_us = window * 10_000;
            loop {
                let t = (f64::from(edge) * period_us).round() as u32;
                if t >= end_us {
                    break;
                }
                channel.on_edge(t);
                edge += 1;
            }
            volts = channel.sample(end_us).volts;
        }
        assert!((volts - 400.0).abs() < 0.2, "{volts}");
    }

    /// Runs `channel` at `volts` (through the board's scaling) for `windows` 10 ms windows
    /// from `start_us`; returns the last sample and where it ended.
    fn pulse(
        channel: &mut VoltageChannel,
        volts: f32,
        start_us: u32,
        windows: u32,
    ) -> (VoltageSample, u32) {
        let hz = VfConfig::PCC_BOARD.hz_for_volts(volts);
        let period_us = 1e6 / f64::from(hz);
        let mut edge = 1.0;
        let mut sample = None;
        let mut end_us = start_us;
        for _ in 0..windows {
            end_us += 10_000;
            loop {
                let t = start_us + (edge * period_us) as u32;
                if t >= end_us {
                    break;
                }
                channel.on_edge(t);
                edge += 1.0;
            }
            sample = Some(channel.sample(end_us));
        }
        (sample.expect("at least one window"), end_us)
    }

    #[test]
    fn a_converter_that_stops_is_silent_with_what_it_measured_last() {
        let mut channel = VoltageChannel::new(VfConfig::PCC_BOARD, 10);
        let first = channel.sample(0);
        assert_eq!(
            first.pulses,
            Pulses::Silent {
                last_v: 0.0,
                since_ms: 0
            },
            "never a pulse: silent, having measured nothing"
        );
        let (live, stopped_us) = pulse(&mut channel, 300.0, 0, 50);
        assert_eq!(live.pulses, Pulses::Live);
        assert!((live.volts - 300.0).abs() < 0.5, "{live:?}");
        // The wire breaks: at 300 V (3.5 kHz) eight periods are under the 2 ms floor, so
        // the first sample after the break is silent, naming the 300 V it read last.
        let mut t = stopped_us;
        let mut first_silent = None;
        while first_silent.is_none() {
            t += 10_000;
            let sample = channel.sample(t);
            if let Pulses::Silent { last_v, since_ms } = sample.pulses {
                first_silent = Some((t - stopped_us, last_v, since_ms, sample.volts));
            }
        }
        let (after_us, last_v, since_ms, volts) = first_silent.expect("silent");
        assert!(after_us <= 10_000, "{after_us}");
        assert!((last_v - 300.0).abs() < 0.5, "{last_v}");
        assert!(since_ms <= 10, "{since_ms}");
        assert!(
            volts < 300.0,
            "the filtered reading falls towards 0: {volts}"
        );
    }

    #[test]
    fn a_fretting_contact_never_reads_a_live_input_low() {
        // 400 V (4.7 kHz) through a contact that passes edges only a quarter of the time: the
        // windows either rebuild the true train (its gaps are whole periods) or say nothing.
        let true_hz = 1e6 / 213.0;
        let mut meter = FrequencyMeter::default();
        let period = 213u32;
        let mut t = 0;
        for window in 1..=20u32 {
            while t < window * 10_000 {
                if t % 3_000 < 750 {
                    meter.on_edge(t);
                }
                t += period;
            }
            if let Some(hz) = meter.reading(window * 10_000, 100_000) {
                assert!(
                    hz > 0.95 * true_hz,
                    "window {window} read {hz} Hz of {true_hz}"
                );
            }
        }
        // One stray and one missed edge in a clean window change nothing.
        let mut meter = FrequencyMeter::default();
        let mut t = 0;
        for edge in 0..47u32 {
            if edge != 20 {
                meter.on_edge(t);
            }
            if edge == 30 {
                meter.on_edge(t + 7);
            }
            t += period;
        }
        let hz = meter.reading(t - period, 100_000).expect("a reading");
        assert!((hz / true_hz - 1.0).abs() < 0.002, "{hz} against {true_hz}");
    }

    #[test]
    fn one_glitch_among_few_periods_holds_the_reading_and_a_lasting_one_is_silence() {
        // 70 V (about 830 Hz, eight periods a window): one stray edge 30 us after a true one
        // spoils that window only; its reading is held, not silence.
        let period = 1_204u32;
        let mut meter = FrequencyMeter::default();
        let mut t = 0u32;
        let mut readings = Vec::new();
        for window in 1..=6u32 {
            while t < window * 10_000 {
                meter.on_edge(t);
                if window == 3 && t == 24_080 {
                    meter.on_edge(t + 30);
                }
                t += period;
            }
            readings.push(meter.reading(window * 10_000, 100_000));
        }
        assert!(readings.iter().skip(1).all(Option::is_some), "{readings:?}");
        // Glitches in every window: silent from the second on.
        let mut meter = FrequencyMeter::default();
        let mut t = 0u32;
        let mut silent = 0;
        for window in 1..=6u32 {
            while t < window * 10_000 {
                meter.on_edge(t);
                meter.on_edge(t + 30);
                meter.on_edge(t + 70);
                t += period;
            }
            if meter.reading(window * 10_000, 100_000).is_none() {
                silent += 1;
            }
        }
        assert!(silent >= 4, "{silent} of 6 windows silent");
    }

    #[test]
    fn a_lost_edge_among_few_periods_reads_the_true_voltage() {
        let period = 1_204u32;
        let true_hz = 1e6 / f64::from(period);
        let mut meter = FrequencyMeter::default();
        let mut t = 0u32;
        for window in 1..=4u32 {
            while t < window * 10_000 {
                if !(window == 3 && t == 26_488) {
                    meter.on_edge(t);
                }
                t += period;
            }
            let hz = f64::from(meter.reading(window * 10_000, 100_000).expect("a reading"));
            if window > 1 {
                assert!(
                    (hz / true_hz - 1.0).abs() < 0.01,
                    "window {window}: {hz} Hz"
                );
            }
        }
    }

    #[test]
    fn bursts_of_a_few_edges_between_gaps_never_read_low() {
        // 400 V through a contact that closes for 450-600 us once per 10 or 20 ms, at a
        // jittered phase: two or three edges per burst, which would read 8-28 V.
        for (cycle_us, closed_us) in [(10_000u32, 450u32), (10_000, 600), (20_000, 600)] {
            let mut meter = FrequencyMeter::default();
            let period = 213u32;
            let mut read = Vec::new();
            let mut t = 0u32;
            for window in 1..=40u32 {
                while t < window * 10_000 {
                    let cycle = t / cycle_us;
                    let open = cycle * cycle_us
                        + 1_000
                        + (cycle.wrapping_mul(2_654_435_761) >> 20) % (cycle_us / 4);
                    if (open..open + closed_us).contains(&t) {
                        meter.on_edge(t);
                    }
                    t += period;
                }
                read.push(meter.reading(window * 10_000, 100_000));
            }
            // Past the first windows, no window reads a voltage far below the true one.
            let low: Vec<_> = read
                .iter()
                .skip(2)
                .flatten()
                .map(|hz| VfConfig::PCC_BOARD.volts_for_hz(*hz))
                .filter(|volts| *volts < 300.0)
                .collect();
            assert!(low.is_empty(), "{cycle_us}/{closed_us}: {low:?}");
        }
    }

    #[test]
    fn a_slow_discharge_ends_silent_at_a_low_reading() {
        // 300 V falling with a 0.5 s time constant: the converter slows down and stops below
        // about a volt, so what it read last is low.
        // Edges by accumulated phase, the frequency falling every microsecond: the train
        // stays regular however slow it gets.
        let mut channel = VoltageChannel::new(VfConfig::PCC_BOARD, 10);
        let mut phase = 0.0f64;
        let mut last = None;
        for window in 1..=500u32 {
            for us in (window - 1) * 10_000..window * 10_000 {
                let volts = 300.0 * libm::exp(-f64::from(us) / 500_000.0);
                phase += VfConfig::PCC_BOARD.hz_for_volts(volts as f32) as f64 / 1e6;
                if phase >= 1.0 {
                    phase -= 1.0;
                    channel.on_edge(us);
                }
            }
            let sample = channel.sample(window * 10_000);
            if window > 20
                && let Pulses::Silent { last_v, .. } = sample.pulses
            {
                last = Some(last_v);
                break;
            }
            assert!(window <= 20 || sample.pulses == Pulses::Live || last.is_some());
        }
        let last_v = last.expect("it stops");
        assert!(last_v < 10.0, "{last_v}");
    }
}
