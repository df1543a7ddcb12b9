//! Properties of the generated codec over every message of the car's schema, driven only by the
//! generated metadata (so a new message is covered without touching this file).

use aer::can::{AnyMessage, MESSAGES};
use aer::runtime::{
    ByteOrder, EncodeError, MessageMeta, SignalMeta, SignalSource, SignalVisitor, Value,
};
use proptest::prelude::*;

/// Bits a signal occupies, numbered `byte * 8 + bit` (bit 0 = LSB), computed independently of
/// the generator from Vector's definition of Intel and Motorola start bits.
fn signal_bits(s: &SignalMeta) -> Vec<usize> {
    let (start, len) = (usize::from(s.start_bit), usize::from(s.len));
    match s.byte_order {
        ByteOrder::LittleEndian => (start..start + len).collect(),
        ByteOrder::BigEndian => {
            // Walk from the MSB towards the LSB: down within a byte, then to bit 7 of the next.
            let mut bits = Vec::with_capacity(len);
            let mut pos = start;
            for _ in 0..len {
                bits.push(pos);
                pos = if pos % 8 == 0 { pos + 15 } else { pos - 1 };
            }
            bits
        }
    }
}

fn covered_mask(m: &MessageMeta) -> Vec<u8> {
    let mut mask = vec![0u8; m.len];
    for s in m.signals {
        for b in signal_bits(s) {
            mask[b / 8] |= 1 << (b % 8);
        }
    }
    mask
}

struct Collect(Vec<(&'static SignalMeta, Value)>);

impl SignalVisitor for Collect {
    fn signal(&mut self, signal: &'static SignalMeta, value: Value, _label: Option<&'static str>) {
        self.0.push((signal, value));
    }
}

fn values(m: &AnyMessage) -> Vec<(&'static SignalMeta, Value)> {
    let mut c = Collect(Vec::new());
    m.visit(&mut c);
    c.0
}

fn in_range(s: &SignalMeta, v: f64) -> bool {
    match (s.min, s.max) {
        (Some(lo), Some(hi)) => {
            let tol = s.factor.abs() * 1e-6;
            lo - tol <= v && v <= hi + tol
        }
        _ => true,
    }
}

struct Phys(Vec<Value>);

impl SignalSource for Phys {
    fn value(&mut self, signal: &'static SignalMeta) -> Option<Value> {
        let meta = MESSAGES
            .iter()
            .find(|m| m.signals.iter().any(|s| std::ptr::eq(s, signal)))?;
        let i = meta.signals.iter().position(|s| std::ptr::eq(s, signal))?;
        self.0.get(i).copied()
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(4000))]

    /// Any payload decodes; re-encoding it gives back exactly the bits signals cover (other
    /// bits zero), or refuses exactly when a decoded value lies outside its range.
    #[test]
    fn decode_then_encode_keeps_covered_bits(index in 0..MESSAGES.len(), bytes in prop::collection::vec(any::<u8>(), 64)) {
        let meta = MESSAGES[index];
        let data = &bytes[..meta.len];
        let message = AnyMessage::decode(meta.id, meta.extended, data).expect("any full-length payload decodes");
        let decoded = values(&message);
        let mut out = [0u8; 64];
        match message.encode(&mut out) {
            Ok(n) => {
                prop_assert_eq!(n, meta.len);
                let mask = covered_mask(meta);
                let expected: Vec<u8> = data.iter().zip(&mask).map(|(d, m)| d & m).collect();
                prop_assert_eq!(&out[..n], &expected[..]);
                prop_assert!(decoded.iter().all(|(s, v)| in_range(s, v.to_f64())));
                let again = AnyMessage::decode(meta.id, meta.extended, &out[..n]).expect("decodes");
                prop_assert_eq!(again, message);
            }
            Err(EncodeError::OutOfRange { message: name, signal }) => {
                prop_assert_eq!(name, meta.name);
                let (s, v) = decoded.iter().find(|(s, _)| s.name == signal).expect("the named signal exists");
                prop_assert!(!in_range(s, v.to_f64()), "{} = {:?} was refused but is in range", signal, v);
            }
            Err(e) => prop_assert!(false, "unexpected {e}"),
        }
    }

    /// `decode_visit` hands over exactly what `decode` then `visit` gives, in the same order,
    /// and fails exactly as `decode` does (short payloads, unknown ids).
    #[test]
    fn decode_visit_is_decode_then_visit(index in 0..MESSAGES.len(), bytes in prop::collection::vec(any::<u8>(), 0..=64), other_id in any::<u32>()) {
        let meta = MESSAGES[index];
        for (id, extended) in [(meta.id, meta.extended), (other_id & 0x7FF, false)] {
            let mut visited = Collect(Vec::new());
            let direct = AnyMessage::decode_visit(id, extended, &bytes, &mut visited);
            match AnyMessage::decode(id, extended, &bytes) {
                Ok(message) => {
                    prop_assert_eq!(direct, Ok(()));
                    let expected = values(&message);
                    prop_assert_eq!(visited.0.len(), expected.len());
                    for ((s1, v1), (s2, v2)) in visited.0.iter().zip(&expected) {
                        prop_assert!(std::ptr::eq(*s1, *s2));
                        prop_assert_eq!(v1, v2);
                    }
                }
                Err(error) => {
                    prop_assert_eq!(direct, Err(error));
                    prop_assert!(visited.0.is_empty());
                }
            }
        }
    }

    /// Physical values anywhere in a signal's range survive encode -> decode within half a raw
    /// step.
    #[test]
    fn physical_values_round_trip_within_half_a_step(index in 0..MESSAGES.len(), unit in prop::collection::vec(0.0f64..=1.0, 64)) {
        let meta = MESSAGES[index];
        let chosen: Vec<Value> = meta.signals.iter().zip(&unit).map(|(s, u)| pick(s, *u)).collect();
        let message = AnyMessage::from_signals(meta.id, meta.extended, &mut Phys(chosen.clone()))
            .expect("values in range build a message");
        let mut out = [0u8; 64];
        let n = message.encode(&mut out).expect("values in range encode");
        let back = AnyMessage::decode(meta.id, meta.extended, &out[..n]).expect("decodes");
        for ((s, got), want) in values(&back).into_iter().zip(&chosen) {
            let err = (got.to_f64() - want.to_f64()).abs();
            prop_assert!(err <= s.factor.abs() / 2.0 + 1e-9 * want.to_f64().abs(),
                "{}.{}: wrote {:?}, read {:?}", meta.name, s.name, want, got);
        }
    }
}

/// A value for `s` at position `u` (0..=1) of its valid range: named values for enums,
/// whole numbers for integer scalings, anything in between otherwise.
fn pick(s: &SignalMeta, u: f64) -> Value {
    let len = u32::from(s.len);
    let (raw_lo, raw_hi) = if s.signed {
        (
            -(2f64.powi(len as i32 - 1)),
            2f64.powi(len as i32 - 1) - 1.0,
        )
    } else {
        (0.0, 2f64.powi(len as i32) - 1.0)
    };
    if !s.labels.is_empty() {
        let (raw, _) = s.labels[((u * s.labels.len() as f64) as usize).min(s.labels.len() - 1)];
        return Value::Float(raw as f64 * s.factor + s.offset);
    }
    let (a, b) = (raw_lo * s.factor + s.offset, raw_hi * s.factor + s.offset);
    let (mut lo, mut hi) = (a.min(b), a.max(b));
    if let (Some(min), Some(max)) = (s.min, s.max) {
        lo = lo.max(min);
        hi = hi.min(max);
    }
    let x = lo + u * (hi - lo);
    if s.factor.fract() == 0.0 && s.offset.fract() == 0.0 {
        let raw = ((x - s.offset) / s.factor).round();
        Value::Int((raw * s.factor + s.offset) as i128)
    } else {
        Value::Float(x)
    }
}

/// Halves, the float just below a half, and whole numbers: where rounding can go wrong.
fn rounding_case() -> impl Strategy<Value = f64> {
    prop_oneof![
        (-2_000_000_000i64..2_000_000_000).prop_map(|n| n as f64 + 0.5),
        (-2_000_000_000i64..2_000_000_000).prop_map(|n| n as f64),
        Just(0.499_999_999_999_999_94),
        Just(-0.499_999_999_999_999_94),
        -2.1e9..2.1e9f64,
        -1e3..1e3f64,
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(20000))]

    /// The encoders' bounded rounding (used where the range check keeps the raw value in the
    /// signal's bits) gives exactly what `round` gives.
    #[test]
    fn bounded_rounding_is_round(x in rounding_case()) {
        prop_assert_eq!(aer::runtime::round_i32(x) as f64, aer::runtime::round(x));
        prop_assert_eq!(aer::runtime::round_i64(x) as f64, aer::runtime::round(x));
        prop_assert_eq!(aer::runtime::round_i64(x * 1000.0) as f64, aer::runtime::round(x * 1000.0));
    }
}
