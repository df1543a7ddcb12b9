//! The ADS1115 driver against a simulated converter on an in-memory I2C bus.

use aer_ccm::ads1115::{ADDRESS, Ads1115, config_for};
use embedded_hal::i2c::{ErrorKind, ErrorType, I2c, Operation};

/// Register-level model of an ADS1115: a conversion finishes after `latency` config reads.
struct Simulated {
    inputs: [i16; 4],
    config: u16,
    pointer: u8,
    pending: Option<(u8, u32)>,
    latency: u32,
    result: i16,
    fail: bool,
    writes: Vec<Vec<u8>>,
}

impl ErrorType for Simulated {
    type Error = ErrorKind;
}

impl I2c for Simulated {
    fn transaction(
        &mut self,
        address: u8,
        operations: &mut [Operation<'_>],
    ) -> Result<(), Self::Error> {
        assert_eq!(address, ADDRESS);
        if self.fail {
            return Err(ErrorKind::Other);
        }
        for operation in operations {
            match operation {
                Operation::Write(bytes) => {
                    self.writes.push(bytes.to_vec());
                    self.pointer = bytes[0];
                    if let [0x01, high, low] = **bytes {
                        self.config = u16::from_be_bytes([high, low]);
                        let mux = (self.config >> 12) & 0b111;
                        self.pending = Some(((mux - 0b100) as u8, self.latency));
                    }
                }
                Operation::Read(buffer) => {
                    let value = if self.pointer == 0x01 {
                        let done = match self.pending.as_mut() {
                            Some((channel, left)) if *left == 0 => {
                                self.result = self.inputs[usize::from(*channel)];
                                self.pending = None;
                                true
                            }
                            Some((_, left)) => {
                                *left -= 1;
                                false
                            }
                            None => true,
                        };
                        (self.config & 0x7FFF) | if done { 0x8000 } else { 0 }
                    } else {
                        self.result as u16
                    };
                    buffer.copy_from_slice(&value.to_be_bytes());
                }
            }
        }
        Ok(())
    }
}

fn converter(latency: u32) -> Simulated {
    Simulated {
        inputs: [1_234, -56, 0, 0],
        config: 0,
        pointer: 0,
        pending: None,
        latency,
        result: 0,
        fail: false,
        writes: Vec::new(),
    }
}

#[test]
fn config_words_select_single_ended_inputs_at_860_sps_and_6_144_v() {
    assert_eq!(config_for(0), 0xC1E3);
    assert_eq!(config_for(1), 0xD1E3);
}

#[test]
fn channels_alternate_without_blocking() {
    let mut ads = Ads1115::new(converter(1));
    ads.start();
    assert_eq!(ads.poll(), (0, 0), "first conversion still running");
    assert_eq!(ads.poll(), (1_234, 0), "APPS1 done, APPS2 started");
    ads.poll();
    assert_eq!(ads.poll(), (1_234, -56));
    assert_eq!(ads.bus_errors, 0);
}

#[test]
fn bus_errors_are_counted_and_the_last_values_kept() {
    let mut ads = Ads1115::new(converter(0));
    ads.start();
    ads.poll();
    let before = ads.latest();
    let mut failing = converter(0);
    failing.fail = true;
    let mut broken = Ads1115::new(failing);
    broken.start();
    assert_eq!(broken.poll(), (0, 0));
    assert_eq!(broken.bus_errors, 2);
    assert_eq!(before, (1_234, 0));
}
