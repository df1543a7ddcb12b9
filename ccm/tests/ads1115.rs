//! The ADS1115 driver against a simulated converter on an in-memory I2C bus.

use aer_ccm::ads1115::{ADDRESS, Ads1115, ERROR_BACKOFF_POLLS, config_for};
use embedded_hal::i2c::{ErrorKind, ErrorType, I2c, Operation};
use std::cell::Cell;
use std::rc::Rc;

/// Register-level model of an ADS1115: a conversion finishes after `latency` config reads.
struct Simulated {
    inputs: [i16; 4],
    config: u16,
    pointer: u8,
    pending: Option<(u8, u32)>,
    latency: u32,
    result: i16,
    fail: bool,
    /// Transactions attempted, shared with the test.
    transactions: Rc<Cell<u32>>,
    writes: Vec<Vec<u8>>,
    /// Start commands (config writes) still to refuse, shared with the test.
    refuse_starts: Rc<Cell<u32>>,
    /// Whether the result register holds a conversion not read yet.
    unread: bool,
    /// Result-register reads with no new conversion behind them, shared with the test.
    stale_reads: Rc<Cell<u32>>,
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
        self.transactions.set(self.transactions.get() + 1);
        if self.fail {
            return Err(ErrorKind::Other);
        }
        for operation in operations {
            match operation {
                Operation::Write(bytes) => {
                    if bytes.len() == 3 && self.refuse_starts.get() > 0 {
                        self.refuse_starts.set(self.refuse_starts.get() - 1);
                        return Err(ErrorKind::Other);
                    }
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
                                self.unread = true;
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
                        if !self.unread {
                            self.stale_reads.set(self.stale_reads.get() + 1);
                        }
                        self.unread = false;
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
        transactions: Rc::default(),
        writes: Vec::new(),
        refuse_starts: Rc::default(),
        unread: false,
        stale_reads: Rc::default(),
    }
}

#[test]
fn config_words_select_single_ended_inputs_at_860_sps_and_6_144_v() {
    assert_eq!(config_for(0), 0xC1E3);
    assert_eq!(config_for(1), 0xD1E3);
}

#[test]
fn channels_alternate_without_blocking_and_report_only_new_conversions() {
    let mut ads = Ads1115::new(converter(1));
    assert_eq!(ads.poll(), [None, None], "APPS1 started");
    assert_eq!(ads.poll(), [None, None], "first conversion still running");
    assert_eq!(ads.poll(), [Some(1_234), None], "APPS1 done, APPS2 started");
    assert_eq!(ads.poll(), [None, None]);
    assert_eq!(ads.poll(), [None, Some(-56)]);
    assert_eq!(ads.bus_errors, 0);
}

#[test]
fn a_converter_that_stops_answering_delivers_nothing_and_is_counted() {
    // Issue 12: the driver previously repeated the last good counts, freezing the throttle.
    let mut failing = converter(0);
    failing.fail = true;
    let transactions = Rc::clone(&failing.transactions);
    let mut broken = Ads1115::new(failing);
    for _ in 0..100 {
        assert_eq!(broken.poll(), [None, None]);
    }
    // A stuck bus (each transaction ended by the controller's timeout) costs one attempt per
    // backoff period, not two transactions every millisecond: the sensor task cannot starve
    // the others.
    let period = u32::from(ERROR_BACKOFF_POLLS) + 1;
    assert_eq!(
        broken.bus_errors,
        100 / period,
        "every failed start is counted"
    );
    assert_eq!(transactions.get(), 100 / period);
}

#[test]
fn a_converter_that_answers_again_delivers_again_after_the_backoff() {
    let sim = converter(0);
    let refuse = Rc::clone(&sim.refuse_starts);
    let transactions = Rc::clone(&sim.transactions);
    let mut ads = Ads1115::new(sim);
    refuse.set(1);
    assert_eq!(ads.poll(), [None, None], "the start is refused");
    assert_eq!(ads.bus_errors, 1);
    let after_failure = transactions.get();
    for _ in 0..ERROR_BACKOFF_POLLS {
        assert_eq!(ads.poll(), [None, None]);
    }
    assert_eq!(
        transactions.get(),
        after_failure,
        "no transaction while backing off"
    );
    let delivered: usize = (0..20).map(|_| ads.poll().iter().flatten().count()).sum();
    assert!(delivered >= 5, "{delivered}");
    assert_eq!(ads.bus_errors, 1);
}

#[test]
fn a_start_that_was_not_acknowledged_is_never_read_back() {
    // An idle converter reads "done" and its result register still holds the last value:
    // reading it after a refused start would present an old value as new.
    let sim = converter(0);
    let refuse = Rc::clone(&sim.refuse_starts);
    let stale = Rc::clone(&sim.stale_reads);
    let mut ads = Ads1115::new(sim);
    let mut delivered = 0;
    for poll in 0..200 {
        if poll % 20 == 3 {
            refuse.set(1);
        }
        delivered += ads.poll().iter().flatten().count();
    }
    assert!(delivered > 50, "{delivered}");
    assert_eq!(stale.get(), 0, "result read without a new conversion");
    assert!(ads.bus_errors >= 5);
}
