//! Accumulator and tractive-system voltages from the V/F converters' pulse trains.
//!
//! The edge interrupt time-stamps every rising edge ([`FrequencyMeter::on_edge`]); the control
//! task takes one sample per period ([`FrequencyMeter::sample`]). Periods are measured edge to
//! edge across sample windows, so a slow pulse train (low voltage, fewer than one edge per
//! window) still reads right instead of alternating with zero.

use crate::constants::VfConfig;
use aer_control::LowPass;

/// Edge-to-edge frequency measurement on one input.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct FrequencyMeter {
    last_edge_us: Option<u32>,
    periods: u32,
    span_us: u32,
    last_hz: f32,
}

impl FrequencyMeter {
    /// Records a rising edge at `now_us` (a free-running microsecond counter that may wrap).
    pub fn on_edge(&mut self, now_us: u32) {
        if let Some(previous) = self.last_edge_us {
            self.span_us = self.span_us.saturating_add(now_us.wrapping_sub(previous));
            self.periods = self.periods.saturating_add(1);
        }
        self.last_edge_us = Some(now_us);
    }

    /// The input frequency in Hz over the edges since the last sample.
    ///
    /// Without a complete period since then, the frequency can only have fallen: the result
    /// is capped by the time since the last edge, and is 0 once no edge came for
    /// `edge_timeout_us`.
    pub fn sample(&mut self, now_us: u32, edge_timeout_us: u32) -> f32 {
        let hz = match self.last_edge_us {
            None => 0.0,
            Some(_) if self.periods > 0 && self.span_us > 0 => {
                self.periods as f32 * 1e6 / self.span_us as f32
            }
            Some(last) => {
                let silent_us = now_us.wrapping_sub(last);
                if silent_us >= edge_timeout_us {
                    0.0
                } else if silent_us == 0 {
                    self.last_hz
                } else {
                    self.last_hz.min(1e6 / silent_us as f32)
                }
            }
        };
        self.periods = 0;
        self.span_us = 0;
        self.last_hz = hz;
        hz
    }

    /// [`Self::sample`], or `None` while the input is silent: no period measured yet, or no
    /// edge for `edge_timeout_us`. Silence is not 0 Hz: a converter unplugged, unpowered or
    /// broken gives no pulses either, so whoever needs to tell "low" from "unknown" (the
    /// bring-up's HV gate) reads this.
    pub fn reading(&mut self, now_us: u32, edge_timeout_us: u32) -> Option<f32> {
        let hz = self.sample(now_us, edge_timeout_us);
        (hz > 0.0).then_some(hz)
    }
}

/// Pulse train in, filtered high voltage out.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VoltageChannel {
    config: VfConfig,
    meter: FrequencyMeter,
    filter: LowPass,
}

impl VoltageChannel {
    /// A channel sampled every `period_ms`.
    pub fn new(config: VfConfig, period_ms: u32) -> Self {
        Self {
            config,
            meter: FrequencyMeter::default(),
            filter: LowPass::new(config.cutoff_hz, period_ms as f32 / 1000.0),
        }
    }

    /// Records a rising edge (call from the edge interrupt).
    pub fn on_edge(&mut self, now_us: u32) {
        self.meter.on_edge(now_us);
    }

    /// Volts at the high-voltage input, filtered; call once per control period.
    pub fn sample(&mut self, now_us: u32) -> f32 {
        let hz = self.meter.sample(now_us, self.config.edge_timeout_us);
        self.filter.update(self.config.volts_for_hz(hz))
    }

    /// The pulse frequency that `volts` at the high-voltage input produces (for simulations
    /// and tests).
    pub fn hz_for_volts(config: &VfConfig, volts: f32) -> f32 {
        config.hz_for_volts(volts)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
        let mut meter = FrequencyMeter::default();
        let last = feed(&mut meter, 0, 200, 10);
        assert!(meter.sample(last + 10, 100_000) > 0.0);
        assert!(meter.sample(last + 99_999, 100_000) > 0.0);
        assert_eq!(meter.sample(last + 100_000, 100_000), 0.0);
        assert_eq!(FrequencyMeter::default().sample(123, 100_000), 0.0);
    }

    #[test]
    fn silence_reads_as_no_reading_not_as_zero() {
        let mut meter = FrequencyMeter::default();
        assert_eq!(meter.reading(0, 100_000), None, "never an edge");
        meter.on_edge(1_000);
        assert_eq!(meter.reading(2_000, 100_000), None, "one edge is no period");
        let last = feed(&mut meter, 1_000 + 2_822, 2_822, 5);
        let hz = meter.reading(last + 100, 100_000).expect("alive");
        assert!((hz - 1e6 / 2_822.0).abs() < 0.01, "{hz}");
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
            volts = channel.sample(end_us);
        }
        assert!((volts - 400.0).abs() < 0.2, "{volts}");
    }
}
