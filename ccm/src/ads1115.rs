//! ADS1115 16-bit ADC (the pedal sensors), over any `embedded-hal` I2C bus.
//!
//! Single-shot conversions at 860 samples/s, alternating between the two pedal channels:
//! each call to [`Ads1115::poll`] reads the finished conversion (if any) and starts the
//! other channel, so it never blocks waiting for a conversion. Each channel updates at about
//! 430 Hz; the 1 kHz pedal filter holds the latest value in between.

use embedded_hal::i2c::I2c;

/// I2C address with ADDR tied to ground.
pub const ADDRESS: u8 = 0x48;

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

/// The two pedal channels, read alternately.
#[derive(Debug)]
pub struct Ads1115<B> {
    bus: B,
    channel: u8,
    latest: [i16; 2],
    /// I2C transactions that failed (counted; the last good values are kept).
    pub bus_errors: u32,
}

impl<B: I2c> Ads1115<B> {
    /// A converter on `bus`; call [`start`](Self::start) once before polling.
    pub const fn new(bus: B) -> Self {
        Self {
            bus,
            channel: 0,
            latest: [0; 2],
            bus_errors: 0,
        }
    }

    /// Starts the first conversion.
    pub fn start(&mut self) {
        self.start_channel(0);
    }

    /// Latest counts of channel 0 (APPS1) and 1 (APPS2).
    pub fn latest(&self) -> (i16, i16) {
        (self.latest[0], self.latest[1])
    }

    /// Reads a finished conversion and starts the next channel; returns the latest pair.
    pub fn poll(&mut self) -> (i16, i16) {
        let mut config = [0u8; 2];
        if self
            .bus
            .write_read(ADDRESS, &[REG_CONFIG], &mut config)
            .is_err()
        {
            self.bus_errors = self.bus_errors.wrapping_add(1);
            return self.latest();
        }
        if u16::from_be_bytes(config) & CONVERSION_DONE == 0 {
            return self.latest();
        }
        let mut result = [0u8; 2];
        if self
            .bus
            .write_read(ADDRESS, &[REG_CONVERSION], &mut result)
            .is_err()
        {
            self.bus_errors = self.bus_errors.wrapping_add(1);
            return self.latest();
        }
        if let Some(slot) = self.latest.get_mut(usize::from(self.channel)) {
            *slot = i16::from_be_bytes(result);
        }
        self.start_channel((self.channel + 1) % 2);
        self.latest()
    }

    fn start_channel(&mut self, channel: u8) {
        self.channel = channel;
        let [high, low] = config_for(channel).to_be_bytes();
        if self.bus.write(ADDRESS, &[REG_CONFIG, high, low]).is_err() {
            self.bus_errors = self.bus_errors.wrapping_add(1);
        }
    }
}
