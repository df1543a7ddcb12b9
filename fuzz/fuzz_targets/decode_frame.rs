//! Frame-level decoding of untrusted bytes: the first byte picks a message of the schema (or, past
//! the last one, an id from the next four bytes), the rest is the payload. Decoding must never
//! panic; whatever decodes must re-encode (unless out of range) and decode to the same message.
#![no_main]

use aer::can::{AnyMessage, MESSAGES};
use aer::runtime::{EncodeError, SignalMeta, SignalVisitor, Value};
use libfuzzer_sys::fuzz_target;

struct Count(usize);

impl SignalVisitor for Count {
    fn signal(&mut self, _signal: &'static SignalMeta, _value: Value, _label: Option<&'static str>) {
        self.0 += 1;
    }
}

fuzz_target!(|input: &[u8]| {
    let Some((&selector, rest)) = input.split_first() else {
        return;
    };
    let (id, extended, data) = match MESSAGES.get(usize::from(selector) % (MESSAGES.len() + 1)) {
        Some(meta) => (meta.id, meta.extended, rest),
        None => match rest.split_first_chunk::<4>() {
            Some((raw, data)) => {
                let raw = u32::from_le_bytes(*raw);
                (raw & 0x1FFF_FFFF, raw & 0x8000_0000 != 0, data)
            }
            None => return,
        },
    };
    let Ok(message) = AnyMessage::decode(id, extended, data) else {
        return;
    };
    let mut count = Count(0);
    message.visit(&mut count);
    assert_eq!(count.0, message.meta().signals.len());
    let mut out = [0u8; 64];
    match message.encode(&mut out) {
        Ok(len) => {
            let again = AnyMessage::decode(id, extended, &out[..len]).expect("own output decodes");
            assert_eq!(again, message);
        }
        Err(EncodeError::OutOfRange { .. }) => {}
        Err(e) => panic!("unexpected encode error: {e}"),
    }
});
