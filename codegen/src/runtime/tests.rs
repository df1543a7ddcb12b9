//! The runtime's own tests, against plain references (bit by bit, `std`'s rounding, exact
//! rational arithmetic, the CRC's published check value), before any generated crate uses it.

use proptest::prelude::*;

use super::bytes::{put, take};
use super::codec::*;

/// Bit `n` of `data` in Intel numbering (`byte * 8 + bit`, bit 0 the least significant).
fn bit(data: &[u8], n: u32) -> bool {
    data.get((n / 8) as usize)
        .is_some_and(|byte| byte & (1 << (n % 8)) != 0)
}

/// An Intel signal read one bit at a time.
fn reference_le(data: &[u8], start: u32, len: u32) -> u64 {
    (0..len).fold(0, |value, i| value | (u64::from(bit(data, start + i)) << i))
}

/// A Motorola signal read one bit at a time: from `msb` (big-endian linear numbering) on, each
/// next bit is the next lower one of its byte, then bit 7 of the next byte.
fn reference_be(data: &[u8], msb: u32, len: u32) -> u64 {
    (0..len).fold(0, |value, i| {
        let linear = msb + i;
        let intel = (linear / 8) * 8 + (7 - linear % 8);
        (value << 1) | u64::from(bit(data, intel))
    })
}

/// A signal that fits 8 bytes: (start, len).
fn le_signal() -> impl Strategy<Value = (u32, u32)> {
    (1u32..=64).prop_flat_map(|len| (0..=64 - len, Just(len)))
}

fn mask(len: u32) -> u64 {
    if len == 64 { u64::MAX } else { (1 << len) - 1 }
}

proptest! {
    #[test]
    fn intel_reads_and_writes_match_bit_by_bit(
        data in prop::array::uniform8(any::<u8>()),
        (start, len) in le_signal(),
        raw in any::<u64>(),
    ) {
        prop_assert_eq!(bits::read_le(&data, start, len), reference_le(&data, start, len));
        let mut out = [0u8; 8];
        bits::write_le(&mut out, start, len, raw);
        prop_assert_eq!(reference_le(&out, start, len), raw & mask(len));
        // Nothing outside the signal is touched.
        let outside = (0..64).filter(|n| !(start..start + len).contains(n));
        for n in outside {
            prop_assert!(!bit(&out, n));
        }
    }

    #[test]
    fn motorola_reads_and_writes_match_bit_by_bit(
        data in prop::array::uniform8(any::<u8>()),
        (msb, len) in le_signal(),
        raw in any::<u64>(),
    ) {
        prop_assert_eq!(bits::read_be(&data, msb, len), reference_be(&data, msb, len));
        let mut out = [0u8; 8];
        bits::write_be(&mut out, msb, len, raw);
        prop_assert_eq!(reference_be(&out, msb, len), raw & mask(len));
        prop_assert_eq!(out.iter().map(|b| b.count_ones()).sum::<u32>(), (raw & mask(len)).count_ones());
    }

    #[test]
    fn reads_past_the_payload_are_zero_and_writes_are_dropped(
        data in prop::collection::vec(any::<u8>(), 0..8),
        (start, len) in le_signal(),
        raw in any::<u64>(),
    ) {
        let mut padded = [0u8; 8];
        padded[..data.len()].copy_from_slice(&data);
        prop_assert_eq!(bits::read_le(&data, start, len), bits::read_le(&padded, start, len));
        prop_assert_eq!(bits::read_be(&data, start, len), bits::read_be(&padded, start, len));
        let mut short = data.clone();
        bits::write_le(&mut short, start, len, raw);
        bits::write_be(&mut short, start, len, raw);
        prop_assert_eq!(short.len(), data.len());
    }

    #[test]
    fn sign_extension_matches_a_shift_pair(raw in any::<u64>(), len in 1u32..=64) {
        let low = raw & mask(len);
        let negative = len < 64 && low >> (len - 1) == 1;
        let expected = if negative { (low | !mask(len)) as i64 } else { low as i64 };
        prop_assert_eq!(bits::sign_extend(low, len), expected);
    }

    #[test]
    fn rounding_is_half_away_from_zero_as_std_rounds(x in any::<f64>()) {
        let ours = round(x);
        prop_assert!(ours == x.round() || (ours.is_nan() && x.is_nan()));
    }

    #[test]
    fn integer_roundings_agree_with_round_in_their_ranges(
        x in -2_147_483_648.0f64..2_147_483_647.0,
        y in -4.5e15f64..4.5e15,
    ) {
        prop_assert_eq!(round_i32(x), round(x) as i64);
        prop_assert_eq!(round_i64(y), round(y) as i64);
    }

    #[test]
    fn halves_round_away_from_zero(whole in -1_000_000i64..1_000_000) {
        let half = whole as f64 + 0.5;
        let expected = if half > 0.0 { whole + 1 } else { whole };
        prop_assert_eq!(round(half) as i64, expected);
        prop_assert_eq!(round_i32(half), expected);
        prop_assert_eq!(round_i64(half), expected);
    }

    #[test]
    fn integer_division_rounds_half_away_from_zero(
        numerator in -(1i128 << 100)..(1i128 << 100),
        denominator in (-(1i128 << 60)..(1i128 << 60)).prop_filter("nonzero", |d| *d != 0),
    ) {
        // Exactly: |q| = floor((2|n| + |d|) / (2|d|)), with the sign of n/d.
        let magnitude = (2 * numerator.abs() + denominator.abs()) / (2 * denominator.abs());
        let expected = if (numerator < 0) == (denominator < 0) { magnitude } else { -magnitude };
        prop_assert_eq!(div_round(numerator, denominator), expected);
    }

    #[test]
    fn put_and_take_never_reach_past_the_buffer(
        len in 0usize..16,
        at in 0usize..24,
        bytes in prop::array::uniform4(any::<u8>()),
    ) {
        let mut out = vec![0u8; len];
        put(&mut out, at, &bytes);
        let back: [u8; 4] = take(&out, at);
        for (i, (b, written)) in back.iter().zip(bytes).enumerate() {
            let expected = if at + i < len { written } else { 0 };
            prop_assert_eq!(*b, expected);
        }
    }
}

#[test]
fn rounding_passes_non_finite_and_huge_values_through() {
    assert!(round(f64::NAN).is_nan());
    assert_eq!(round(f64::INFINITY), f64::INFINITY);
    assert_eq!(round(-1e300), -1e300);
    assert_eq!(round(-2.5), -3.0);
    assert_eq!(round(2.4999999999999996), 2.0);
}

#[test]
fn payloads_are_length_checked_and_zeroed() {
    let short = [1u8, 2, 3];
    assert_eq!(
        payload::<4>(&short, "M"),
        Err(DecodeError::TooShort {
            message: "M",
            expected: 4,
            actual: 3
        })
    );
    assert_eq!(payload::<2>(&short, "M"), Ok(&[1, 2]));
    let mut out = [0xAAu8; 3];
    assert_eq!(
        payload_mut::<4>(&mut out, "M").map(|p| p.len()),
        Err(EncodeError::BufferTooSmall {
            message: "M",
            needed: 4,
            actual: 3
        })
    );
    assert_eq!(payload_mut::<2>(&mut out, "M").map(|p| *p), Ok([0, 0]));
    assert_eq!(out, [0, 0, 0xAA]);
}

#[test]
fn range_checks_take_the_tolerance_and_refuse_nan() {
    let check = |v| check_range(v, 0.0, 10.0, 1e-6, "M", "S");
    assert_eq!(check(10.0000005), Ok(()));
    assert_eq!(check(-0.0000005), Ok(()));
    assert_eq!(
        check(10.01),
        Err(EncodeError::OutOfRange {
            message: "M",
            signal: "S"
        })
    );
    assert!(check(f64::NAN).is_err());
}

/// A 4-bit counter at bits 8..12 (step 1) and a CRC in byte 0, over a 3-byte payload.
static SEALED: MessageMeta = MessageMeta {
    name: "Sealed",
    id: 0x123,
    extended: false,
    len: 3,
    cycle_time_ms: Some(10),
    timeout_ms: Some(50),
    comment: "",
    sender: None,
    buses: &[],
    signals: &[],
    counter: Some(CounterMeta {
        signal: "Counter",
        bits: &[8, 9, 10, 11],
        step: 1,
    }),
    checksum: Some(ChecksumMeta {
        signal: "Crc",
        byte: 0,
        algorithm: ChecksumAlgorithm::Crc8SaeJ1850,
    }),
};

#[test]
fn the_crc_is_sae_j1850_and_the_sum_its_complement() {
    // CRC-8/SAE-J1850's published check value over "123456789".
    assert_eq!(
        ChecksumAlgorithm::Crc8SaeJ1850.compute(b"123456789".iter()),
        0x4B
    );
    assert_eq!(
        ChecksumAlgorithm::SumXorFf.compute([1u8, 2, 0xFF].iter()),
        0xFD
    );
}

#[test]
fn counters_sit_in_their_bits_and_wrap_at_their_width() {
    let counter = CounterMeta {
        signal: "C",
        bits: &[0, 7, 12],
        step: 3,
    };
    let mut data = [0u8; 2];
    counter.write(&mut data, 0b101);
    assert_eq!(data, [0x01, 0x10]);
    assert_eq!(counter.read(&data), 0b101);
    assert_eq!(counter.after(6), 1);
    // Bits past a short payload read as 0 and are not written.
    let mut short = [0u8; 1];
    counter.write(&mut short, 0b111);
    assert_eq!((short, counter.read(&short)), ([0x81], 0b011));
}

#[test]
fn sealed_frames_verify_in_sequence_and_every_fault_is_named() {
    let mut sender = CounterSender::default();
    let mut check = CounterCheck::default();
    let mut frames = Vec::new();
    for _ in 0..20 {
        let mut data = [0u8, 0, 0x5A];
        SEALED.seal(&mut sender, &mut data);
        frames.push(data);
    }
    // The counter wraps at 16 and every frame passes in order.
    assert_eq!(SEALED.counter.map(|c| c.read(&frames[16])), Some(0));
    for frame in &frames {
        assert_eq!(SEALED.verify(&mut check, frame), Ok(()));
    }
    let last = frames[19];
    assert_eq!(
        SEALED.verify(&mut check, &last),
        Err(IntegrityError::CounterRepeated {
            message: "Sealed",
            value: 3
        })
    );
    // A jump is refused, then followed.
    let mut sender = CounterSender::default();
    let mut check = CounterCheck::default();
    let sealed: Vec<[u8; 3]> = (0..4)
        .map(|_| {
            let mut data = [0u8; 3];
            SEALED.seal(&mut sender, &mut data);
            data
        })
        .collect();
    assert_eq!(SEALED.verify(&mut check, &sealed[0]), Ok(()));
    assert_eq!(
        SEALED.verify(&mut check, &sealed[2]),
        Err(IntegrityError::CounterJumped {
            message: "Sealed",
            expected: 1,
            found: 2
        })
    );
    assert_eq!(SEALED.verify(&mut check, &sealed[3]), Ok(()));
    check.reset();
    assert_eq!(SEALED.verify(&mut check, &sealed[1]), Ok(()));
    // One flipped payload bit fails the checksum before the counter is looked at.
    let mut corrupt = sealed[2];
    corrupt[2] ^= 0x04;
    assert!(matches!(
        SEALED.verify(&mut check, &corrupt),
        Err(IntegrityError::Checksum {
            message: "Sealed",
            ..
        })
    ));
    assert_eq!(SEALED.verify(&mut check, &sealed[2]), Ok(()));
}

#[test]
fn values_convert_only_when_whole_and_in_range() {
    assert_eq!(Value::from(3.0f64).to_int::<u8>(), Some(3));
    assert_eq!(Value::from(3.5f64).to_int::<u8>(), None);
    assert_eq!(Value::from(300u16).to_int::<u8>(), None);
    assert_eq!(Value::from(f64::NAN).to_int::<i32>(), None);
    assert_eq!(Value::from(-1i8).to_int::<i16>(), Some(-1));
    assert_eq!(Value::from(true).to_bool(), Some(true));
    assert_eq!(Value::from(2u8).to_bool(), None);
    assert_eq!(Value::from(1.5f32).to_f64(), 1.5);
    assert_eq!(Value::Int(7).to_f32(), 7.0);
}

/// A one-signal message implemented by hand as the generator writes it, to drive the trait's
/// frame helpers.
#[derive(Debug, PartialEq)]
struct Speed(u16);

static SPEED_SIGNALS: [SignalMeta; 1] = [SignalMeta {
    name: "Speed",
    index: 0,
    unit: "rpm",
    comment: "",
    start_bit: 0,
    len: 16,
    byte_order: ByteOrder::LittleEndian,
    signed: false,
    factor: 1.0,
    offset: 0.0,
    min: None,
    max: None,
    labels: &[(0, "Stopped")],
    multiplexed: false,
}];

static SPEED: MessageMeta = MessageMeta {
    name: "Speed",
    id: 0x1ABC_DEF0,
    extended: true,
    len: 2,
    cycle_time_ms: None,
    timeout_ms: None,
    comment: "",
    sender: None,
    buses: &[],
    signals: &SPEED_SIGNALS,
    counter: None,
    checksum: None,
};

impl CanMessage for Speed {
    const META: &'static MessageMeta = &SPEED;

    fn decode(data: &[u8]) -> Result<Self, DecodeError> {
        let data = payload::<2>(data, SPEED.name)?;
        Ok(Self(bits::read_le(data, 0, 16) as u16))
    }

    fn encode(&self, out: &mut [u8]) -> Result<usize, EncodeError> {
        let out = payload_mut::<2>(out, SPEED.name)?;
        bits::write_le(out, 0, 16, u64::from(self.0));
        Ok(2)
    }

    fn visit(&self, visitor: &mut impl SignalVisitor) {
        let signal = &SPEED_SIGNALS[0];
        visitor.signal(
            signal,
            Value::from(self.0),
            signal.label_of(i128::from(self.0)),
        );
    }

    fn from_signals(source: &mut impl SignalSource) -> Result<Self, EncodeError> {
        let signal = &SPEED_SIGNALS[0];
        source
            .value(signal)
            .ok_or(EncodeError::MissingSignal {
                message: SPEED.name,
                signal: signal.name,
            })?
            .to_int()
            .map(Self)
            .ok_or(EncodeError::InvalidValue {
                message: SPEED.name,
                signal: signal.name,
            })
    }
}

/// A classic CAN frame, as a HAL's would be.
#[derive(Debug)]
struct Frame {
    id: embedded_can::Id,
    data: Vec<u8>,
}

impl embedded_can::Frame for Frame {
    fn new(id: impl Into<embedded_can::Id>, data: &[u8]) -> Option<Self> {
        (data.len() <= 8).then(|| Self {
            id: id.into(),
            data: data.to_vec(),
        })
    }
    fn new_remote(_: impl Into<embedded_can::Id>, _: usize) -> Option<Self> {
        None
    }
    fn is_extended(&self) -> bool {
        matches!(self.id, embedded_can::Id::Extended(_))
    }
    fn is_remote_frame(&self) -> bool {
        false
    }
    fn id(&self) -> embedded_can::Id {
        self.id
    }
    fn dlc(&self) -> usize {
        self.data.len()
    }
    fn data(&self) -> &[u8] {
        &self.data
    }
}

#[test]
fn frames_carry_the_message_id_and_a_wrong_id_is_refused() {
    let frame: Frame = Speed(1234).to_frame().expect("fits a classic frame");
    assert_eq!(raw_id(frame.id), (0x1ABC_DEF0, true));
    assert_eq!(Speed::from_frame(&frame), Ok(Speed(1234)));
    let standard = embedded_can::StandardId::new(0x0F0).expect("valid id");
    let wrong = Frame {
        id: embedded_can::Id::Standard(standard),
        data: vec![0, 0],
    };
    assert_eq!(
        Speed::from_frame(&wrong),
        Err(DecodeError::WrongId {
            message: "Speed",
            id: 0x0F0,
            extended: false
        })
    );
    let standard_meta = MessageMeta {
        id: 0x7FF,
        extended: false,
        ..SPEED
    };
    assert_eq!(raw_id(standard_meta.can_id()), (0x7FF, false));
}

#[test]
fn visitors_and_sources_see_physical_values_and_labels() {
    struct Seen(Vec<(&'static str, Value, Option<&'static str>)>);
    impl SignalVisitor for Seen {
        fn signal(
            &mut self,
            signal: &'static SignalMeta,
            value: Value,
            label: Option<&'static str>,
        ) {
            self.0.push((signal.name, value, label));
        }
    }
    let mut seen = Seen(Vec::new());
    Speed(0).visit(&mut seen);
    assert_eq!(seen.0, [("Speed", Value::Int(0), Some("Stopped"))]);

    struct Constant(Option<Value>);
    impl SignalSource for Constant {
        fn value(&mut self, _: &'static SignalMeta) -> Option<Value> {
            self.0
        }
    }
    assert_eq!(
        Speed::from_signals(&mut Constant(Some(Value::Float(7.0)))),
        Ok(Speed(7))
    );
    assert_eq!(
        Speed::from_signals(&mut Constant(None)),
        Err(EncodeError::MissingSignal {
            message: "Speed",
            signal: "Speed"
        })
    );
}

#[test]
fn errors_name_the_message_and_what_was_wrong() {
    let texts = [
        DecodeError::UnknownId {
            id: 0x1F,
            extended: true,
        }
        .to_string(),
        EncodeError::NotSelected {
            message: "M",
            signal: "S",
        }
        .to_string(),
        IntegrityError::Checksum {
            message: "M",
            expected: 0x12,
            found: 0x34,
        }
        .to_string(),
    ];
    assert_eq!(
        texts,
        [
            "unknown extended id 0x1F",
            "M.S: set, but its multiplexor selects other signals",
            "M: checksum 0x34, the payload needs 0x12",
        ]
    );
}
