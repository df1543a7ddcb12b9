//! ADS1115 16-bit ADC (the pedal sensors), over any `embedded-hal` I2C bus.
//!
//! Single-shot conversions at 860 samples/s, alternating between the two pedal channels:
//! each call to [`Ads1115::poll`] reads the finished conversion (if any) and starts the
//! other channel, so it never blocks waiting for a conversion. Each channel updates about
//! every 2.3 ms.
//!
//! A failed transaction backs the driver off for [`ERROR_BACKOFF_POLLS`] polls, so a converter
//! or bus that fails (each failure bounded in time by the I2C controller's pin-low timeout)
//! costs at most one transaction every 10 ms instead of two every millisecond.
//!
//! A poll reports only conversions that finished since the last one. A converter that stops
//! answering therefore delivers nothing, and the pedal channel's freshness check
//! ([`crate::apps`]) turns that into a fault, instead of the last good counts being
//! repeated as if the pedal were still where it was.

use crate::apps::PedalVolts;
use crate::constants::ADS1115_FULL_SCALE_V;
use embedded_hal::i2c::I2c;

/// I2C address with ADDR tied to ground.
pub const ADDRESS: u8 = 0x48;

/// Polls skipped after a failed transaction (at 1 kHz: the converter is retried every 10 ms,
/// well inside the pedal channel's 20 ms conversion timeout once it answers again).
pub const ERROR_BACKOFF_POLLS: u8 = 9;

const REG_CONVERSION: u8 = 0x00;
const REG_CONFIG: u8 = 0x01;
/// Config: start a single conversion (OS), PGA +/-6.144 V (PGA bits 0b000), single-shot,
/// 860 SPS, comparator off. The input multiplexer (bits 14-12) is added per channel: AINx vs GND = 0b100 + x.
const CONFIG_BASE: u16 = 1 << 15 | 1 << 8 | 0b111 << 5 | 0b11;
/// Config bit 15 reads 1 once the conversion is done.
const CONVERSION_DONE: u16 = 1 << 15;

/// The config word that starts a single-ended conversion on `channel` (0..=3).
pub const fn config_for(channel: u8) -> u16 {
    CONFIG_BASE | ((0b100 | (channel as u16 & 0b11)) << 12)
}

/// New conversions of channel 0 (APPS1) and 1 (APPS2) delivered by one poll; `None` where
/// nothing new arrived.
pub type Conversions = [Option<i16>; 2];

/// Volts at the input for ADS1115 counts at the configured full-scale range.
pub fn counts_to_volts(counts: i16) -> f32 {
    f32::from(counts) * ADS1115_FULL_SCALE_V / 32_768.0
}

/// ADS1115 counts for `volts` at the input (nearest, saturating).
pub fn volts_to_counts(volts: f32) -> i16 {
    (volts * 32_768.0 / ADS1115_FULL_SCALE_V) as i16
}

/// A poll's conversions as the pedal channel reads them (volts at the sensors: the ADS1115
/// reads them directly, without a divider).
pub fn pedal_volts(conversions: Conversions) -> PedalVolts {
    conversions.map(|counts| counts.map(counts_to_volts))
}

/// The two pedal channels, read alternately.
#[derive(Debug)]
pub struct Ads1115<B> {
    bus: B,
    /// The channel whose conversion was started successfully and has not been read yet.
    converting: Option<u8>,
    /// The channel to start next.
    next: u8,
    /// Polls still to skip after a failure.
    backoff: u8,
    /// I2C transactions that failed (counted; the firmware reports them in telemetry).
    pub bus_errors: u32,
}

impl<B: I2c> Ads1115<B> {
    /// A converter on `bus`; the first [`poll`](Self::poll) starts converting.
    pub const fn new(bus: B) -> Self {
        Self {
            bus,
            converting: None,
            next: 0,
            backoff: 0,
            bus_errors: 0,
        }
    }

    /// Reads a finished conversion, starts the next channel, and returns what is new.
    ///
    /// A conversion is only read back after its start was acknowledged: an idle converter
    /// also reads "done", and its result register still holds an old value.
    pub fn poll(&mut self) -> Conversions {
        let mut fresh = [None, None];
        if self.backoff > 0 {
            self.backoff -= 1;
            return fresh;
        }
        if let Some(channel) = self.converting {
            match self.read_finished() {
                Ok(Some(counts)) => {
                    if let Some(slot) = fresh.get_mut(usize::from(channel)) {
                        *slot = Some(counts);
                    }
                    self.converting = None;
                    self.next = (channel + 1) % 2;
                }
                Ok(None) => return fresh,
                Err(()) => {
                    // Whatever the converter is doing, its result cannot be trusted: start over.
                    self.count_error();
                    self.converting = None;
                    return fresh;
                }
            }
        }
        self.start(self.next);
        fresh
    }

    /// The config register as the converter holds it (the bring-up image prints it: a fitted
    /// ADS1115 answers 0x8583 after reset, or this driver's last conversion's word).
    pub fn read_config(&mut self) -> Result<u16, B::Error> {
        let mut config = [0u8; 2];
        self.bus.write_read(ADDRESS, &[REG_CONFIG], &mut config)?;
        Ok(u16::from_be_bytes(config))
    }

    /// The bus, for a scan of the addresses that answer.
    pub fn bus(&mut self) -> &mut B {
        &mut self.bus
    }

    fn read_finished(&mut self) -> Result<Option<i16>, ()> {
        let mut config = [0u8; 2];
        self.bus
            .write_read(ADDRESS, &[REG_CONFIG], &mut config)
            .map_err(|_| ())?;
        if u16::from_be_bytes(config) & CONVERSION_DONE == 0 {
            return Ok(None);
        }
        let mut result = [0u8; 2];
        self.bus
            .write_read(ADDRESS, &[REG_CONVERSION], &mut result)
            .map_err(|_| ())?;
        Ok(Some(i16::from_be_bytes(result)))
    }

    fn start(&mut self, channel: u8) {
        let [high, low] = config_for(channel).to_be_bytes();
        if self.bus.write(ADDRESS, &[REG_CONFIG, high, low]).is_ok() {
            self.converting = Some(channel);
        } else {
            self.count_error();
        }
    }

    fn count_error(&mut self) {
        self.bus_errors = self.bus_errors.wrapping_add(1);
        self.backoff = ERROR_BACKOFF_POLLS;
    }
}
