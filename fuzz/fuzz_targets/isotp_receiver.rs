//! Arbitrary frame sequences into the ISO-TP receiver (what the Pi takes off the bus): it must
//! never panic, and any message it delivers must have the announced length and fit its buffer.
#![no_main]

use aer_isotp::{Config, Received, Receiver};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let mut receiver: Receiver<4095> = Receiver::new(Config::CAR);
    let mut now: u32 = 0;
    // Each frame: one byte of length (0..=8) and of time step, then the payload.
    let mut rest = data;
    while let [header, tail @ ..] = rest {
        let len = usize::from(header & 0x0F).min(8).min(tail.len());
        now = now.wrapping_add(u32::from(header >> 4) * 100_000);
        let (frame, next) = tail.split_at(len);
        rest = next;
        if let Ok(Received::Message(message)) = receiver.on_frame(frame, now) {
            assert!(!message.is_empty() && message.len() <= 4095);
        }
        let _ = receiver.poll(now);
        let _ = receiver.take_interrupted();
    }
});
