//! CAN bit timing for the FlexCAN's CTRL1 register.
//!
//! A bit is split into time quanta (tq): 1 sync + (PROPSEG + 1) + (PSEG1 + 1) sample point,
//! then (PSEG2 + 1). FlexCAN allows 8..=25 tq per bit, PROPSEG up to 8 tq and each phase
//! segment up to 8 tq. We aim for an 87.5 % sample point, the CiA 601 recommendation for
//! classic CAN at 500 kbit/s and 1 Mbit/s.

/// Register values for CTRL1's timing fields (each field holds "quanta - 1").
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BitTiming {
    /// Prescaler division factor minus one: tq = (PRESDIV + 1) / clock.
    pub presdiv: u8,
    /// Propagation segment minus one (0..=7).
    pub propseg: u8,
    /// Phase segment 1 minus one (0..=7).
    pub pseg1: u8,
    /// Phase segment 2 minus one (1..=7).
    pub pseg2: u8,
    /// Resynchronisation jump width minus one (0..=3, at most PSEG2).
    pub rjw: u8,
}

/// The bit rate cannot be made exactly from the module clock.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UnreachableBitrate {
    /// Module clock in Hz.
    pub clock_hz: u32,
    /// Requested bit rate in bit/s.
    pub bitrate: u32,
}

/// Sample point we aim for, per mille of the bit time.
const TARGET_SAMPLE_POINT: u32 = 875;

impl BitTiming {
    /// Timing for `bitrate` from a module clock of `clock_hz`, exact (no rate error) and with
    /// the sample point as close to 87.5 % as the segment limits allow (ties: more quanta).
    pub fn for_bitrate(clock_hz: u32, bitrate: u32) -> Result<Self, UnreachableBitrate> {
        let mut best: Option<(u32, Self)> = None;
        for quanta in 8u32..=25 {
            let Some(per_bit) = bitrate.checked_mul(quanta) else {
                continue;
            };
            if per_bit == 0 || clock_hz % per_bit != 0 {
                continue;
            }
            let prescaler = clock_hz / per_bit;
            for pseg2 in 2..=8 {
                let Some(timing) = Self::split(quanta, pseg2, prescaler) else {
                    continue;
                };
                let error = timing.sample_point_permille().abs_diff(TARGET_SAMPLE_POINT);
                if best.is_none_or(|(best_error, _)| error <= best_error) {
                    best = Some((error, timing));
                }
            }
        }
        best.map(|(_, timing)| timing)
            .ok_or(UnreachableBitrate { clock_hz, bitrate })
    }

    /// Splits `quanta` with `pseg2` quanta after the sample point; `None` when the segment
    /// limits cannot hold the rest.
    fn split(quanta: u32, pseg2: u32, prescaler: u32) -> Option<Self> {
        let before_sample = quanta.checked_sub(1 + pseg2)?;
        let propseg = before_sample.checked_sub(1)?.min(8);
        let pseg1 = before_sample - propseg;
        if propseg == 0 || !(1..=8).contains(&pseg1) || !(1..=256).contains(&prescaler) {
            return None;
        }
        let rjw = pseg2.min(pseg1).min(4);
        Some(Self {
            presdiv: u8::try_from(prescaler - 1).ok()?,
            propseg: u8::try_from(propseg - 1).ok()?,
            pseg1: u8::try_from(pseg1 - 1).ok()?,
            pseg2: u8::try_from(pseg2 - 1).ok()?,
            rjw: u8::try_from(rjw - 1).ok()?,
        })
    }

    /// Time quanta per bit.
    pub fn quanta(&self) -> u32 {
        1 + u32::from(self.propseg) + 1 + u32::from(self.pseg1) + 1 + u32::from(self.pseg2) + 1
    }

    /// Sample point in per mille of the bit time.
    pub fn sample_point_permille(&self) -> u32 {
        (self.quanta() - (u32::from(self.pseg2) + 1)) * 1000 / self.quanta()
    }

    /// The bit rate these values give from `clock_hz`.
    pub fn bitrate(&self, clock_hz: u32) -> u32 {
        clock_hz / (u32::from(self.presdiv) + 1) / self.quanta()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const OSC: u32 = 24_000_000;

    #[test]
    fn every_car_rate_is_exact_from_the_24_mhz_oscillator() {
        for bitrate in [125_000, 250_000, 500_000, 1_000_000] {
            let timing = BitTiming::for_bitrate(OSC, bitrate).unwrap();
            assert_eq!(timing.bitrate(OSC), bitrate, "{timing:?}");
            assert!((8..=25).contains(&timing.quanta()));
            assert!(timing.propseg <= 7 && timing.pseg1 <= 7 && (1..=7).contains(&timing.pseg2));
            assert!(timing.rjw <= timing.pseg2 && timing.rjw <= 3);
            // 1 Mbit/s leaves 24 clocks per bit: 12 tq, sampled at 83.3 %, is the nearest.
            let sp = timing.sample_point_permille();
            assert!((830..=900).contains(&sp), "{bitrate}: sample point {sp}");
        }
    }

    #[test]
    fn the_bus_rate_samples_at_87_5_percent() {
        // 24 MHz / 500 kbit/s = 48 clocks per bit: 16 tq of 3 clocks, sampled after 14 tq.
        let timing = BitTiming::for_bitrate(OSC, 500_000).unwrap();
        assert_eq!(timing.quanta(), 16);
        assert_eq!(timing.presdiv, 2);
        assert_eq!(timing.sample_point_permille(), 875);
    }

    #[test]
    fn rates_the_clock_cannot_make_exactly_are_refused() {
        assert!(BitTiming::for_bitrate(OSC, 0).is_err());
        assert!(BitTiming::for_bitrate(OSC, 333_333).is_err());
        assert!(BitTiming::for_bitrate(OSC, 5_000_000).is_err());
    }
}
