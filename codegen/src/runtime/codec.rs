//! Runtime support for the generated codecs: errors, bit access, signal metadata and the generic
//! visitor/source traits.
//!
//! Everything here is `no_std`, allocation-free and panic-free on any input: payloads are
//! length-checked before decoding and every byte access goes through `get`.
//!
//! (The generator compiles and tests this file, and copies it verbatim into every generated
//! crate's `runtime.rs`; edit it in the generator's `src/runtime/`, never in a generated crate.)

use core::fmt;

/// Why a payload could not be decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DecodeError {
    /// The payload is shorter than the message's length.
    TooShort {
        message: &'static str,
        expected: usize,
        actual: usize,
    },
    /// No message of the database has this id.
    UnknownId { id: u32, extended: bool },
    /// A frame was given to a message type with a different id.
    WrongId {
        message: &'static str,
        id: u32,
        extended: bool,
    },
}

impl fmt::Display for DecodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::TooShort {
                message,
                expected,
                actual,
            } => write!(
                f,
                "{message}: payload is {actual} bytes, the message needs {expected}"
            ),
            Self::UnknownId { id, extended } => {
                write!(f, "unknown {} id 0x{id:X}", id_kind(*extended))
            }
            Self::WrongId {
                message,
                id,
                extended,
            } => write!(f, "{message}: frame has {} id 0x{id:X}", id_kind(*extended)),
        }
    }
}

impl core::error::Error for DecodeError {}

/// Why a message could not be encoded. Every variant names what was wrong.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EncodeError {
    /// The output buffer is shorter than the message.
    BufferTooSmall {
        message: &'static str,
        needed: usize,
        actual: usize,
    },
    /// The physical value lies outside the signal's `[min|max]`, or its raw value does not fit
    /// the signal's bits.
    OutOfRange {
        message: &'static str,
        signal: &'static str,
    },
    /// A value of the wrong kind was supplied (a fraction for an integer signal, say).
    InvalidValue {
        message: &'static str,
        signal: &'static str,
    },
    /// A signal required by the message (or selected by its multiplexor) has no value.
    MissingSignal {
        message: &'static str,
        signal: &'static str,
    },
    /// A multiplexed signal has a value although its multiplexor selects other signals.
    NotSelected {
        message: &'static str,
        signal: &'static str,
    },
    /// No message of the database has this id.
    UnknownId { id: u32, extended: bool },
    /// The frame type rejected the payload (a classic frame cannot carry a CAN FD payload).
    FrameRejected { message: &'static str },
}

impl fmt::Display for EncodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::BufferTooSmall {
                message,
                needed,
                actual,
            } => write!(
                f,
                "{message}: buffer is {actual} bytes, the message needs {needed}"
            ),
            Self::OutOfRange { message, signal } => {
                write!(f, "{message}.{signal}: value out of range")
            }
            Self::InvalidValue { message, signal } => {
                write!(f, "{message}.{signal}: value of the wrong kind")
            }
            Self::MissingSignal { message, signal } => {
                write!(f, "{message}.{signal}: value missing")
            }
            Self::NotSelected { message, signal } => write!(
                f,
                "{message}.{signal}: set, but its multiplexor selects other signals"
            ),
            Self::UnknownId { id, extended } => {
                write!(f, "unknown {} id 0x{id:X}", id_kind(*extended))
            }
            Self::FrameRejected { message } => {
                write!(f, "{message}: the frame type cannot carry this payload")
            }
        }
    }
}

impl core::error::Error for EncodeError {}

fn id_kind(extended: bool) -> &'static str {
    if extended { "extended" } else { "standard" }
}

/// Bit order of a signal in the payload.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ByteOrder {
    /// Intel: the start bit is the least significant bit.
    LittleEndian,
    /// Motorola: the start bit is the most significant bit (Vector's sawtooth numbering).
    BigEndian,
}

/// What the schema says about one signal.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SignalMeta {
    pub name: &'static str,
    /// Position in its message's (or the packet's) list of signals, in schema order.
    pub index: u16,
    pub unit: &'static str,
    pub comment: &'static str,
    pub start_bit: u16,
    pub len: u8,
    pub byte_order: ByteOrder,
    pub signed: bool,
    pub factor: f64,
    pub offset: f64,
    /// `None` when the schema gives no range.
    pub min: Option<f64>,
    pub max: Option<f64>,
    /// Named raw values, for enum signals.
    pub labels: &'static [(i128, &'static str)],
    /// True for a signal that is only present when its multiplexor selects it.
    pub multiplexed: bool,
}

impl SignalMeta {
    /// The name the schema gives raw value `raw`, if any.
    pub fn label_of(&self, raw: i128) -> Option<&'static str> {
        self.labels
            .iter()
            .find(|(value, _)| *value == raw)
            .map(|(_, label)| *label)
    }
}

/// What the schema says about one message.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MessageMeta {
    pub name: &'static str,
    pub id: u32,
    pub extended: bool,
    pub len: usize,
    pub cycle_time_ms: Option<u32>,
    /// How old its last frame may be before a receiver counts it lost (the schema's
    /// `AerTimeoutMs`, else a few cycle times); `None` for a message sent on demand.
    pub timeout_ms: Option<u32>,
    pub comment: &'static str,
    /// The node that sends it (`BO_`'s transmitter), `None` when the schema names none.
    pub sender: Option<&'static str>,
    /// The buses it is sent on (the `AerBus` attribute), empty when the schema names none.
    pub buses: &'static [&'static str],
    pub signals: &'static [SignalMeta],
    /// The rolling counter the message carries, if the schema declares one.
    pub counter: Option<CounterMeta>,
    /// The checksum the message carries, if the schema declares one.
    pub checksum: Option<ChecksumMeta>,
}

impl MessageMeta {
    /// The message id as an `embedded-can` id.
    pub fn can_id(&self) -> embedded_can::Id {
        // Ids are validated by the generator, so the fallbacks are unreachable.
        if self.extended {
            embedded_can::ExtendedId::new(self.id).map_or(
                embedded_can::Id::Extended(embedded_can::ExtendedId::ZERO),
                embedded_can::Id::Extended,
            )
        } else {
            u16::try_from(self.id)
                .ok()
                .and_then(embedded_can::StandardId::new)
                .map_or(
                    embedded_can::Id::Standard(embedded_can::StandardId::ZERO),
                    embedded_can::Id::Standard,
                )
        }
    }
}

/// A message's rolling counter (the schema's `CounterStep` signal attribute): the sender adds
/// `step` to it on every frame, modulo 2^bits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CounterMeta {
    /// The counter signal's name.
    pub signal: &'static str,
    /// Where each of its bits sits (`byte * 8 + bit`, bit 0 the least significant of its
    /// byte), the counter's least significant bit first; at most 8.
    pub bits: &'static [u16],
    /// What the sender adds on every frame.
    pub step: u8,
}

impl CounterMeta {
    /// The counter's value in `data` (bits beyond the payload read as 0).
    pub fn read(&self, data: &[u8]) -> u8 {
        self.bits.iter().enumerate().fold(0u8, |value, (i, &at)| {
            let set = data
                .get(usize::from(at / 8))
                .is_some_and(|byte| byte & (1 << (at % 8)) != 0);
            value | (u8::from(set) << (i % 8))
        })
    }

    /// Writes `value` into the counter's bits of `data`.
    pub fn write(&self, data: &mut [u8], value: u8) {
        for (i, &at) in self.bits.iter().enumerate() {
            if let Some(byte) = data.get_mut(usize::from(at / 8)) {
                let mask = 1u8 << (at % 8);
                if value & (1 << (i % 8)) != 0 {
                    *byte |= mask;
                } else {
                    *byte &= !mask;
                }
            }
        }
    }

    /// The value that follows `value`.
    pub fn after(&self, value: u8) -> u8 {
        let next = u16::from(value) + u16::from(self.step);
        let modulus = 1u16 << self.bits.len().min(8);
        (next % modulus) as u8
    }
}

/// A checksum algorithm the schema can name (the `ChecksumAlgorithm` signal attribute). Each
/// covers every payload byte but the checksum's own, in order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ChecksumAlgorithm {
    /// The bytes' sum (mod 256), XOR 0xFF.
    SumXorFf,
    /// CRC-8 SAE J1850: polynomial 0x1D, initial value 0xFF, final XOR 0xFF.
    Crc8SaeJ1850,
}

impl ChecksumAlgorithm {
    /// The checksum of `bytes`.
    pub fn compute<'a>(self, bytes: impl Iterator<Item = &'a u8>) -> u8 {
        match self {
            Self::SumXorFf => bytes.fold(0u8, |sum, byte| sum.wrapping_add(*byte)) ^ 0xFF,
            Self::Crc8SaeJ1850 => {
                bytes.fold(0xFFu8, |crc, byte| {
                    (0..8).fold(crc ^ byte, |crc, _| {
                        if crc & 0x80 != 0 {
                            (crc << 1) ^ 0x1D
                        } else {
                            crc << 1
                        }
                    })
                }) ^ 0xFF
            }
        }
    }
}

/// A message's checksum: one byte of the payload.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ChecksumMeta {
    /// The checksum signal's name.
    pub signal: &'static str,
    /// The payload byte it occupies.
    pub byte: u8,
    pub algorithm: ChecksumAlgorithm,
}

impl ChecksumMeta {
    /// The checksum `data` should carry.
    pub fn compute(&self, data: &[u8]) -> u8 {
        let own = usize::from(self.byte);
        self.algorithm.compute(
            data.iter()
                .enumerate()
                .filter(move |(i, _)| *i != own)
                .map(|(_, byte)| byte),
        )
    }
}

/// Why a received frame's counter or checksum says it is not fresh, intact data.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum IntegrityError {
    /// The checksum byte does not match the payload.
    Checksum {
        message: &'static str,
        expected: u8,
        found: u8,
    },
    /// The counter did not move: the sender repeated a frame (or is stuck).
    CounterRepeated { message: &'static str, value: u8 },
    /// The counter skipped: frames were lost, or the frame is not the sender's next.
    CounterJumped {
        message: &'static str,
        expected: u8,
        found: u8,
    },
}

impl fmt::Display for IntegrityError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Checksum {
                message,
                expected,
                found,
            } => write!(
                f,
                "{message}: checksum 0x{found:02X}, the payload needs 0x{expected:02X}"
            ),
            Self::CounterRepeated { message, value } => {
                write!(f, "{message}: counter repeated ({value})")
            }
            Self::CounterJumped {
                message,
                expected,
                found,
            } => write!(f, "{message}: counter {found}, expected {expected}"),
        }
    }
}

impl core::error::Error for IntegrityError {}

/// The sender's side of one message's counter: the value its next frame carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct CounterSender {
    next: u8,
}

/// The receiver's side of one message's counter: the last value accepted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct CounterCheck {
    last: Option<u8>,
}

impl CounterCheck {
    /// Forgets the last value: the next frame is accepted whatever its counter (after the
    /// sender restarted, or the receiver lost track on purpose).
    pub fn reset(&mut self) {
        self.last = None;
    }
}

impl MessageMeta {
    /// Fills the counter (advancing `sender`) and then the checksum into an encoded payload.
    /// A message without them is left as it is.
    pub fn seal(&self, sender: &mut CounterSender, data: &mut [u8]) {
        if let Some(counter) = &self.counter {
            counter.write(data, sender.next);
            sender.next = counter.after(sender.next);
        }
        if let Some(checksum) = &self.checksum {
            let value = checksum.compute(data);
            if let Some(byte) = data.get_mut(usize::from(checksum.byte)) {
                *byte = value;
            }
        }
    }

    /// Checks a received payload's checksum, then its counter against the last one `check`
    /// accepted. A repeated counter is refused and leaves `check` as it was; a jump is
    /// refused but followed (the frame after it is in sequence again), so one lost frame
    /// costs one more. A message without them always passes.
    pub fn verify(&self, check: &mut CounterCheck, data: &[u8]) -> Result<(), IntegrityError> {
        if let Some(checksum) = &self.checksum {
            let expected = checksum.compute(data);
            let found = data.get(usize::from(checksum.byte)).copied().unwrap_or(0);
            if found != expected {
                return Err(IntegrityError::Checksum {
                    message: self.name,
                    expected,
                    found,
                });
            }
        }
        let Some(counter) = &self.counter else {
            return Ok(());
        };
        let found = counter.read(data);
        let last = check.last.replace(found);
        match last {
            Some(last) if last == found => Err(IntegrityError::CounterRepeated {
                message: self.name,
                value: found,
            }),
            Some(last) if counter.after(last) != found => Err(IntegrityError::CounterJumped {
                message: self.name,
                expected: counter.after(last),
                found,
            }),
            _ => Ok(()),
        }
    }
}

/// A physical value, as numbers go on the wire: exact integers or floating point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Value {
    Int(i128),
    Float(f64),
}

impl Value {
    /// The value as `f64` (large integers round to the nearest `f64`).
    pub fn to_f64(self) -> f64 {
        match self {
            Self::Int(i) => i as f64,
            Self::Float(f) => f,
        }
    }

    /// The value as `f32`.
    pub fn to_f32(self) -> f32 {
        self.to_f64() as f32
    }

    /// The value as an integer of type `T`, if it is whole and fits.
    pub fn to_int<T: TryFrom<i128>>(self) -> Option<T> {
        let i = match self {
            Self::Int(i) => i,
            Self::Float(f) if f.is_finite() && f == (f as i128) as f64 => f as i128,
            Self::Float(_) => return None,
        };
        T::try_from(i).ok()
    }

    /// `0` or `1` as a flag.
    pub fn to_bool(self) -> Option<bool> {
        match self.to_int::<u8>() {
            Some(0) => Some(false),
            Some(1) => Some(true),
            _ => None,
        }
    }
}

macro_rules! value_from_int {
    ($($t:ty),*) => {$(
        impl From<$t> for Value {
            fn from(v: $t) -> Self {
                Self::Int(v as i128)
            }
        }
    )*};
}
value_from_int!(u8, u16, u32, u64, u128, i8, i16, i32, i64, i128);

impl From<bool> for Value {
    fn from(v: bool) -> Self {
        Self::Int(i128::from(v))
    }
}

impl From<f32> for Value {
    fn from(v: f32) -> Self {
        Self::Float(f64::from(v))
    }
}

impl From<f64> for Value {
    fn from(v: f64) -> Self {
        Self::Float(v)
    }
}

/// Receives every present signal of a message, in schema order: a JSON writer, a table row, a
/// plot feed can all be written once for every message.
pub trait SignalVisitor {
    /// `label` is the value's name for enum signals whose raw value is named in the schema.
    fn signal(&mut self, signal: &'static SignalMeta, value: Value, label: Option<&'static str>);
}

/// Supplies physical values by signal, to build a message without per-message code.
pub trait SignalSource {
    /// The value for `signal`, or `None` when the source has none.
    fn value(&mut self, signal: &'static SignalMeta) -> Option<Value>;
}

/// Implemented by every generated message type.
pub trait CanMessage: Sized {
    const META: &'static MessageMeta;

    /// Decodes a payload; bytes past the message's length are ignored.
    fn decode(data: &[u8]) -> Result<Self, DecodeError>;

    /// Encodes into `out` (bits no signal covers are zero); returns the payload length.
    fn encode(&self, out: &mut [u8]) -> Result<usize, EncodeError>;

    /// Calls `visitor` for every present signal.
    fn visit(&self, visitor: &mut impl SignalVisitor);

    /// Builds the message from physical values.
    fn from_signals(source: &mut impl SignalSource) -> Result<Self, EncodeError>;

    /// Decodes an `embedded-can` frame, checking its id.
    fn from_frame(frame: &impl embedded_can::Frame) -> Result<Self, DecodeError> {
        let (id, extended) = raw_id(frame.id());
        if id != Self::META.id || extended != Self::META.extended {
            return Err(DecodeError::WrongId {
                message: Self::META.name,
                id,
                extended,
            });
        }
        Self::decode(frame.data())
    }

    /// Encodes into an `embedded-can` frame.
    fn to_frame<F: embedded_can::Frame>(&self) -> Result<F, EncodeError> {
        let mut buf = [0u8; 64];
        let len = self.encode(&mut buf)?;
        let data = buf.get(..len).unwrap_or_default();
        F::new(Self::META.can_id(), data).ok_or(EncodeError::FrameRejected {
            message: Self::META.name,
        })
    }
}

/// Splits an `embedded-can` id into its number and whether it is extended.
pub fn raw_id(id: embedded_can::Id) -> (u32, bool) {
    match id {
        embedded_can::Id::Standard(s) => (u32::from(s.as_raw()), false),
        embedded_can::Id::Extended(e) => (e.as_raw(), true),
    }
}

/// The first `N` bytes of `data`, or `TooShort`.
#[inline]
pub fn payload<'a, const N: usize>(
    data: &'a [u8],
    message: &'static str,
) -> Result<&'a [u8; N], DecodeError> {
    data.get(..N)
        .and_then(|d| d.try_into().ok())
        .ok_or(DecodeError::TooShort {
            message,
            expected: N,
            actual: data.len(),
        })
}

/// The first `N` bytes of `out`, zeroed, or `BufferTooSmall`.
#[inline]
pub fn payload_mut<'a, const N: usize>(
    out: &'a mut [u8],
    message: &'static str,
) -> Result<&'a mut [u8; N], EncodeError> {
    let actual = out.len();
    let out: &mut [u8; N] =
        out.get_mut(..N)
            .and_then(|d| d.try_into().ok())
            .ok_or(EncodeError::BufferTooSmall {
                message,
                needed: N,
                actual,
            })?;
    *out = [0; N];
    Ok(out)
}

/// Fails with `OutOfRange` unless `min - tolerance <= value <= max + tolerance` (NaN fails).
/// The tolerance (a millionth of a raw step) lets values decoded at a limit be encoded again.
#[inline]
pub fn check_range(
    value: f64,
    min: f64,
    max: f64,
    tolerance: f64,
    message: &'static str,
    signal: &'static str,
) -> Result<(), EncodeError> {
    if (min - tolerance..=max + tolerance).contains(&value) {
        Ok(())
    } else {
        Err(EncodeError::OutOfRange { message, signal })
    }
}

/// Rounds half away from zero (`f64::round` is not in `core`).
#[inline]
pub fn round(x: f64) -> f64 {
    // From 2^52 on every f64 is whole; NaN and infinities pass through unchanged.
    if x.is_nan() || x.abs() >= 4_503_599_627_370_496.0 {
        return x;
    }
    let whole = (x as i64) as f64;
    let rest = x - whole;
    if rest >= 0.5 {
        whole + 1.0
    } else if rest <= -0.5 {
        whole - 1.0
    } else {
        whole
    }
}

/// [`round`] to an integer, for a value its caller has bounded to `i32`'s range (a range
/// check the generator showed to imply it): one truncating conversion and two comparisons
/// instead of `round`'s special cases and a checked conversion back. Beyond `i32` the result
/// is wrong but still no panic.
#[inline(always)]
pub fn round_i32(x: f64) -> i64 {
    let whole = x as i32;
    let rest = x - f64::from(whole);
    i64::from(whole) + i64::from(rest >= 0.5) - i64::from(rest <= -0.5)
}

/// [`round_i32`] for values bounded to `+-2^52` (where every `f64` is still whole or not).
#[inline(always)]
pub fn round_i64(x: f64) -> i64 {
    let whole = x as i64;
    let rest = x - whole as f64;
    whole
        .wrapping_add(i64::from(rest >= 0.5))
        .wrapping_sub(i64::from(rest <= -0.5))
}

/// `numerator / denominator` rounded half away from zero, for integer scaling.
#[inline]
pub fn div_round(numerator: i128, denominator: i128) -> i128 {
    let quotient = numerator / denominator;
    let rest = numerator % denominator;
    if 2 * rest.abs() >= denominator.abs() {
        if (rest < 0) == (denominator < 0) {
            quotient + 1
        } else {
            quotient - 1
        }
    } else {
        quotient
    }
}

/// Bit access. Positions are validated by the generator; out-of-payload bytes read as zero and
/// are never written, so no input can make these panic.
pub mod bits {
    #[inline(always)]
    fn mask(len: u32) -> u64 {
        if len >= 64 {
            u64::MAX
        } else {
            (1u64 << len) - 1
        }
    }

    /// Reads an Intel signal: `start` is its least significant bit.
    #[inline(always)]
    pub fn read_le(data: &[u8], start: u32, len: u32) -> u64 {
        let first = (start / 8) as usize;
        let last = ((start + len - 1) / 8) as usize;
        let mut acc: u128 = 0;
        let mut i = last + 1;
        while i > first {
            i -= 1;
            acc = (acc << 8) | u128::from(data.get(i).copied().unwrap_or(0));
        }
        ((acc >> (start % 8)) as u64) & mask(len)
    }

    /// Reads a Motorola signal: `msb` is its most significant bit in big-endian linear
    /// numbering (bit 0 is the MSB of byte 0).
    #[inline(always)]
    pub fn read_be(data: &[u8], msb: u32, len: u32) -> u64 {
        let lsb = msb + len - 1;
        let first = (msb / 8) as usize;
        let last = (lsb / 8) as usize;
        let mut acc: u128 = 0;
        let mut i = first;
        while i <= last {
            acc = (acc << 8) | u128::from(data.get(i).copied().unwrap_or(0));
            i += 1;
        }
        ((acc >> (7 - lsb % 8)) as u64) & mask(len)
    }

    /// ORs an Intel signal into zeroed bits.
    #[inline(always)]
    pub fn write_le(out: &mut [u8], start: u32, len: u32, raw: u64) {
        let first = (start / 8) as usize;
        let last = ((start + len - 1) / 8) as usize;
        let mut acc = u128::from(raw & mask(len)) << (start % 8);
        let mut i = first;
        while i <= last {
            if let Some(byte) = out.get_mut(i) {
                *byte |= acc as u8;
            }
            acc >>= 8;
            i += 1;
        }
    }

    /// ORs a Motorola signal into zeroed bits (`msb` as in [`read_be`]).
    #[inline(always)]
    pub fn write_be(out: &mut [u8], msb: u32, len: u32, raw: u64) {
        let lsb = msb + len - 1;
        let first = (msb / 8) as usize;
        let last = (lsb / 8) as usize;
        let mut acc = u128::from(raw & mask(len)) << (7 - lsb % 8);
        let mut i = last + 1;
        while i > first {
            i -= 1;
            if let Some(byte) = out.get_mut(i) {
                *byte |= acc as u8;
            }
            acc >>= 8;
        }
    }

    /// Sign-extends the low `len` bits of `raw`.
    #[inline(always)]
    pub fn sign_extend(raw: u64, len: u32) -> i64 {
        let shift = 64 - len;
        ((raw << shift) as i64) >> shift
    }
}
