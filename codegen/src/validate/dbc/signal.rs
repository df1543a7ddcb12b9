//! One signal: where its bits sit, how they are encoded and scaled, and the Rust type of its
//! physical value.

use can_dbc::{
    AttributeValue, ByteOrder as DbcByteOrder, MultiplexIndicator, NumericValue,
    SignalExtendedValueType, ValueType,
};

use super::{Builder, Draft, Frame};
use crate::diagnostic::Code;
use crate::model::{ByteOrder, Encoding, EnumType, IntType, PhysType, Signal, be_linear};

/// Signal attribute a schema can set to `"f32"` to ask for a single-precision physical value.
pub(super) const PHYS_TYPE_ATTRIBUTE: &str = "AerPhysType";

/// Where a signal's bits sit.
struct Bits {
    start_bit: u32,
    len: u32,
    byte_order: ByteOrder,
}

impl<'a> Builder<'a, '_> {
    /// The signal, or `None` (reported) when it cannot be represented faithfully.
    pub(super) fn signal(
        &mut self,
        frame: &Frame<'a>,
        msg_len: usize,
        d: &Draft<'a>,
        field: String,
        enums: &mut Vec<EnumType>,
    ) -> Option<Signal> {
        let (msg, sig) = (frame.msg, d.sig);
        let where_ = format!("signal `{}` of message `{}`", sig.name, msg.name);
        let bits = self.bits(d, msg_len, &where_)?;
        let encoding = self.encoding(frame, d, bits.len, &where_)?;
        let (min, max) = self.range(d, &where_)?;
        let mut s = Signal {
            name: sig.name.clone(),
            field,
            start_bit: bits.start_bit,
            len: bits.len,
            byte_order: bits.byte_order,
            encoding,
            factor: sig.factor,
            offset: sig.offset,
            min,
            max,
            unit: sig.unit.clone(),
            comment: self
                .index
                .signal_comment(msg.id, &sig.name)
                .map(str::to_owned),
            receivers: sig
                .receivers
                .iter()
                .filter(|r| r.as_str() != "Vector__XXX")
                .cloned()
                .collect(),
            phys: PhysType::F64,
            value_labels: Vec::new(),
            mux: None,
            is_multiplexor: matches!(
                sig.multiplexer_indicator,
                MultiplexIndicator::Multiplexor
                    | MultiplexIndicator::MultiplexorAndMultiplexedSignal(_)
            ),
        };
        self.check_range(&s, d.line, &where_);
        s.phys = self.phys_type(frame, &mut s, d.line, &where_, enums)?;
        Some(s)
    }

    /// Start bit, length and byte order, checked against the frame.
    fn bits(&mut self, d: &Draft<'_>, msg_len: usize, where_: &str) -> Option<Bits> {
        let sig = d.sig;
        if sig.size == 0 || sig.size > 64 {
            self.r.report(
                Code::SignalLength,
                d.line,
                format!(
                    "{where_} is {} bits long; signals are 1 to 64 bits",
                    sig.size
                ),
                "fix the length after the `|` in the SG_ line",
            );
            return None;
        }
        let len = u32::try_from(sig.size).unwrap_or(64);
        let start_bit = u32::try_from(sig.start_bit).unwrap_or(u32::MAX);
        let byte_order = match sig.byte_order {
            DbcByteOrder::LittleEndian => ByteOrder::LittleEndian,
            DbcByteOrder::BigEndian => ByteOrder::BigEndian,
        };
        let frame_bits = u32::try_from(msg_len * 8).unwrap_or(u32::MAX);
        let in_frame = match byte_order {
            ByteOrder::LittleEndian => start_bit
                .checked_add(len)
                .is_some_and(|end| end <= frame_bits),
            ByteOrder::BigEndian => {
                start_bit < frame_bits && be_linear(start_bit) + len <= frame_bits
            }
        };
        if in_frame {
            return Some(Bits {
                start_bit,
                len,
                byte_order,
            });
        }
        let (hint, indicator) = match byte_order {
            ByteOrder::BigEndian => (
                "for Motorola (@0) signals the start bit is the MSB in sawtooth numbering (byte*8 + 7 for the top bit of a byte); check it, the length and the message length",
                0,
            ),
            ByteOrder::LittleEndian => (
                "for Intel (@1) signals the start bit is the LSB; start + length must not exceed 8 * message length",
                1,
            ),
        };
        self.r.report(
            Code::SignalOutsideFrame,
            d.line,
            format!(
                "{where_} ({}|{}@{indicator}) has bits outside the {msg_len}-byte frame",
                sig.start_bit, sig.size
            ),
            hint,
        );
        None
    }

    /// Integer or IEEE float (`SIG_VALTYPE_`), checked against the length; and a usable factor.
    fn encoding(
        &mut self,
        frame: &Frame<'_>,
        d: &Draft<'_>,
        len: u32,
        where_: &str,
    ) -> Option<Encoding> {
        let sig = d.sig;
        let ext = self.index.value_type(frame.msg.id, &sig.name);
        let encoding = match (ext, &sig.value_type) {
            (Some(SignalExtendedValueType::IEEEfloat32Bit), _) => Encoding::Float32,
            (Some(SignalExtendedValueType::IEEEdouble64bit), _) => Encoding::Float64,
            (_, ValueType::Signed) => Encoding::Signed,
            (_, ValueType::Unsigned) => Encoding::Unsigned,
        };
        let float_len = match encoding {
            Encoding::Float32 => Some(32),
            Encoding::Float64 => Some(64),
            _ => None,
        };
        if let Some(want) = float_len.filter(|w| *w != len) {
            let value_type_line = self
                .loaded
                .lines
                .value_types
                .get(&(frame.written_id, sig.name.clone()))
                .copied()
                .unwrap_or(d.line);
            self.r.report(
                Code::FloatLength,
                value_type_line,
                format!("{where_} is declared IEEE float ({want} bits) but is {len} bits long"),
                format!("make the signal {want} bits long, or remove its SIG_VALTYPE_ line"),
            );
            return None;
        }
        if sig.factor == 0.0 || !sig.factor.is_finite() || !sig.offset.is_finite() {
            self.r.report(
                Code::BadFactor,
                d.line,
                format!("{where_} has factor {} and offset {}; the factor must be a non-zero finite number", sig.factor, sig.offset),
                "fix the `(factor,offset)` pair in the SG_ line",
            );
            return None;
        }
        if float_len.is_none() && !physical_extremes_finite(len, encoding, sig.factor, sig.offset) {
            self.r.report(
                Code::BadFactor,
                d.line,
                format!(
                    "{where_} has factor {} and offset {}; its physical values overflow f64",
                    sig.factor, sig.offset
                ),
                "fix the `(factor,offset)` pair in the SG_ line",
            );
            return None;
        }
        Some(encoding)
    }

    /// `[min|max]`, `None` each for `[0|0]` (Vector's "no range"); inverted ranges are errors.
    fn range(&mut self, d: &Draft<'_>, where_: &str) -> Option<(Option<f64>, Option<f64>)> {
        let (min, max) = (numeric(&d.sig.min), numeric(&d.sig.max));
        if min == 0.0 && max == 0.0 {
            return Some((None, None));
        }
        if min > max {
            self.r.report(
                Code::RangeInverted,
                d.line,
                format!("{where_} has minimum {min} above its maximum {max}"),
                "swap the numbers in `[min|max]`",
            );
            return None;
        }
        Some((Some(min), Some(max)))
    }

    /// Warns when `[min|max]` reaches past what the raw bits can express.
    fn check_range(&mut self, s: &Signal, line: usize, where_: &str) {
        if s.is_float_raw() {
            return;
        }
        let (lo, hi) = s.raw_range();
        let a = lo as f64 * s.factor + s.offset;
        let b = hi as f64 * s.factor + s.offset;
        let (plo, phi) = if a <= b { (a, b) } else { (b, a) };
        // Tolerate the rounding of long decimal literals (e.g. 9.22337203685478E+018 for i64).
        let tol = |v: f64| s.factor.abs() * 0.5 + v.abs() * 1e-12;
        let bad_min = s.min.filter(|m| *m < plo - tol(plo));
        let bad_max = s.max.filter(|m| *m > phi + tol(phi));
        if bad_min.is_some() || bad_max.is_some() {
            self.r.report(
                Code::RangeBeyondRaw,
                line,
                format!(
                    "{where_} declares the range [{}|{}] but its {}-bit raw value only reaches [{plo}|{phi}]",
                    s.min.unwrap_or(0.0),
                    s.max.unwrap_or(0.0),
                    s.len
                ),
                "narrow `[min|max]`, or make the signal longer or its factor larger",
            );
        }
    }

    /// The Rust type of the physical value: f32 where asked and exact, an enum for named
    /// values of an unscaled signal, bool for a plain flag, an integer for whole scaling, f64
    /// otherwise. A scaled signal with named values stays a number (as cantools decodes it:
    /// a "255 = SNA" sentinel must not turn a 40 % pedal into `Unknown(100)`); its names go to
    /// `value_labels`.
    fn phys_type(
        &mut self,
        frame: &Frame<'_>,
        s: &mut Signal,
        line: usize,
        where_: &str,
        enums: &mut Vec<EnumType>,
    ) -> Option<PhysType> {
        if self.wants_f32(frame, s) {
            return self.f32_phys(frame, s, line, where_);
        }
        match s.encoding {
            Encoding::Float32 if s.factor == 1.0 && s.offset == 0.0 => return Some(PhysType::F32),
            Encoding::Float32 | Encoding::Float64 => return Some(PhysType::F64),
            _ => {}
        }
        let choices = self.index.value_descriptions(frame.msg.id, &s.name);
        if let Some(choices) = choices.filter(|c| !c.is_empty()) {
            let val_line = self
                .loaded
                .lines
                .values
                .get(&(frame.written_id, s.name.clone()))
                .copied()
                .unwrap_or(line);
            if s.factor != 1.0 || s.offset != 0.0 {
                s.value_labels = self.named_values(s, choices, val_line, where_);
            } else {
                return self
                    .enum_for(s, choices, val_line, where_, &frame.type_name, enums)
                    .map(PhysType::Enum);
            }
        }
        if s.len == 1 && s.encoding == Encoding::Unsigned && s.factor == 1.0 && s.offset == 0.0 {
            return Some(PhysType::Bool);
        }
        let integral = |v: f64| v.fract() == 0.0 && v.abs() < 9.0e18;
        if integral(s.factor) && integral(s.offset) {
            let (lo, hi) = s.raw_range();
            let f = s.factor as i128;
            let o = s.offset as i128;
            let (a, b) = (lo * f + o, hi * f + o);
            return Some(PhysType::Int(IntType::smallest_for(a.min(b), a.max(b))));
        }
        Some(PhysType::F64)
    }

    /// Whether the schema sets [`PHYS_TYPE_ATTRIBUTE`] to `"f32"` for the signal.
    fn wants_f32(&self, frame: &Frame<'_>, s: &Signal) -> bool {
        self.index
            .signal_attributes(PHYS_TYPE_ATTRIBUTE, frame.msg.id, &s.name)
            .iter()
            .any(|value| matches!(value, AttributeValue::String(v) if v == "f32"))
    }

    /// f32, when its 24-bit mantissa holds every raw value.
    fn f32_phys(
        &mut self,
        frame: &Frame<'_>,
        s: &Signal,
        line: usize,
        where_: &str,
    ) -> Option<PhysType> {
        if s.encoding == Encoding::Float64 || (!s.is_float_raw() && s.len > 24) {
            let attr_line = self
                .loaded
                .lines
                .signal_attributes
                .get(&(
                    PHYS_TYPE_ATTRIBUTE.to_owned(),
                    frame.written_id,
                    s.name.clone(),
                ))
                .copied()
                .unwrap_or(line);
            self.r.report(
                Code::F32TooNarrow,
                attr_line,
                format!("{where_} asks for an f32 physical value, but its {}-bit raw value does not fit f32's 24-bit mantissa", s.len),
                "remove the AerPhysType attribute (f64 is used) or shorten the signal to 24 bits",
            );
            return None;
        }
        Some(PhysType::F32)
    }
}

fn numeric(v: &NumericValue) -> f64 {
    match *v {
        NumericValue::Uint(u) => u as f64,
        NumericValue::Int(i) => i as f64,
        NumericValue::Double(d) => d,
    }
}

/// Whether every raw value of an integer signal has a finite physical value.
fn physical_extremes_finite(len: u32, encoding: Encoding, factor: f64, offset: f64) -> bool {
    let len = len.clamp(1, 64);
    let (lo, hi) = match encoding {
        Encoding::Signed => (-(2f64.powi(len as i32 - 1)), 2f64.powi(len as i32 - 1)),
        _ => (0.0, 2f64.powi(len as i32)),
    };
    (lo * factor + offset).is_finite() && (hi * factor + offset).is_finite()
}
