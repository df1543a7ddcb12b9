//! A signal as the codec template sees it: typed parts (where its bits sit, how bits become
//! the raw value, when it is present, how raw and physical values convert) that
//! `templates/signal.rs` spells out as statements.

use crate::model::{ByteOrder, Database, Encoding, IntType, Message, PhysType, Signal, be_linear};
use crate::render::fragment::{FloatLit, IntScaling, OptionLit, Scaling, StrLit, ToF64, int_arith};
use crate::render::meta::{MetaView, signal_labels};
use crate::render::{doc_lines, phys_rust};

pub(crate) struct SignalView {
    pub name: StrLit,
    /// The message's name, for errors that name the signal.
    pub message: StrLit,
    pub field: String,
    /// What its conversion functions and raw-bits local are named after: the field without
    /// a keyword's trailing `_` (`type_` -> `type_from_raw`, not `type__from_raw`).
    pub stem: String,
    /// Position in the message's signal list (and its metadata array).
    pub index: usize,
    pub docs: Vec<String>,
    pub raw_ty: &'static str,
    pub phys_ty: String,
    pub placement: Placement,
    pub raw: RawCodec,
    pub presence: Presence,
    pub is_multiplexor: bool,
    pub conversion: Conversion,
    /// The schema's range, checked before encoding.
    pub range: Option<RangeCheck>,
    pub value: ValueKind,
    /// A scaled signal with named raw values: its value stays a number and
    /// `<stem>_label(v)` recognises the named ones.
    pub named: Option<NamedValues>,
    pub meta: MetaView,
}

/// How `<stem>_label(v)` finds the raw value of a physical one.
pub(crate) struct NamedValues {
    pub scaling: Scaling,
    pub to_f64: ToF64,
}

/// Where a signal's bits sit in the payload.
pub(crate) struct Placement {
    /// `le` or `be`: the suffix of the runtime's `bits::read_*`/`write_*`.
    pub order: &'static str,
    /// LSB for Intel; the MSB in big-endian linear numbering for Motorola.
    pub start: u32,
    pub len: u32,
}

/// How the extracted bits (a `u64`) become the raw value, and back.
pub(crate) enum RawCodec {
    F32,
    F64,
    /// Sign-extended to `i64`; `narrow` names a smaller raw type to cast to.
    Signed {
        len: u32,
        narrow: Option<&'static str>,
    },
    /// A 64-bit unsigned raw value is the bits themselves.
    Unsigned64,
    /// Unsigned, narrowed to the raw type.
    Unsigned {
        ty: &'static str,
    },
}

/// When the signal is in the payload.
pub(crate) enum Presence {
    Always,
    /// Only when its multiplexor's raw value matches.
    When(MuxCondition),
}

/// `matches!(selector_bits, 1 | 4..=7)`.
pub(crate) struct MuxCondition {
    /// The local holding the multiplexor's bits.
    pub selector: String,
    /// The multiplexor is itself multiplexed, so its bits are an `Option`.
    pub selector_optional: bool,
    /// Inclusive ranges of selector values.
    pub ranges: Vec<(u64, u64)>,
}

impl MuxCondition {
    /// `1 | 4..=7`.
    pub(crate) fn patterns(&self) -> String {
        crate::model::MuxCondition::describe(&self.ranges, "..=", " | ")
    }
}

/// How the raw value becomes the physical value (`<field>_from_raw`) and back (`<field>_to_raw`).
pub(crate) enum Conversion {
    /// A 1-bit flag.
    Bool,
    /// Named values; `widen` is the enum's representation when wider than the raw type.
    Enum {
        widen: Option<&'static str>,
        fit: Fit,
    },
    /// Identity scaling into an integer; `convert` when the types differ.
    Int { convert: bool, fit: Fit },
    /// Whole factor and offset: exact integer arithmetic.
    IntScaled { scaling: IntScaling, fit: Fit },
    /// An IEEE float on the wire.
    Float { scaling: Scaling, wire: FloatWire },
    /// An integer on the wire scaled to a float, rounded back to the nearest raw value.
    Quantized {
        scaling: Scaling,
        phys_f32: bool,
        phys_to_f64: ToF64,
        raw_to_f64: ToF64,
        /// Raw values the bits can hold: `lo..hi` (bounds are powers of two, exact in f64).
        lo: FloatLit,
        hi: FloatLit,
        /// Set when the range check bounds the raw value enough to round it straight to an
        /// integer.
        bounded: Option<BoundedRound>,
    },
}

/// How a quantized signal whose range check bounds its raw value rounds it.
pub(crate) struct BoundedRound {
    /// The runtime's rounding to an integer: `round_i32` or `round_i64`.
    pub round: &'static str,
    /// `Some((lo, hi))` when the range still lets through values outside the signal's bits:
    /// the rounded value is checked against `lo..hi`, as an integer.
    pub bits: Option<(i64, i64)>,
}

/// Which float types meet on the wire and in the struct.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(crate) enum FloatWire {
    /// `f32` on the wire and in the struct, unscaled.
    F32Plain,
    /// `f32` on the wire and in the struct, scaled through `f64`.
    F32Scaled,
    /// `f32` on the wire, `f64` in the struct.
    F32Wide,
    /// `f64` on both sides.
    F64,
}

/// Whether an integer raw value needs a check against the signal's bit width.
pub(crate) enum Fit {
    /// The raw type is exactly as wide as the signal.
    Full,
    Range {
        lo: i128,
        hi: i128,
    },
}

/// `runtime::check_range(...)` on the physical value before it is encoded.
pub(crate) struct RangeCheck {
    pub value: PhysAsF64,
    pub min: FloatLit,
    pub max: FloatLit,
    /// A millionth of a raw step: what float arithmetic may add at the edges.
    pub tolerance: FloatLit,
}

/// The physical value `v` as `f64`, for the range check.
pub(crate) enum PhysAsF64 {
    Bool,
    Number(ToF64),
    /// A scaled signal with named values: only values without a name are checked (a named
    /// value is valid whatever the range says, as in cantools).
    NamedNumber(ToF64),
    /// Only unnamed enum values are checked (a named value is valid whatever the range says,
    /// as in cantools), scaled from their raw value.
    UnknownEnum {
        scaling: Scaling,
    },
}

/// The value a visitor sees, and how a value from a [`SignalSource`] becomes the field.
pub(crate) enum ValueKind {
    Bool,
    Int {
        ty: &'static str,
    },
    F32,
    F64,
    /// Its raw value (enums are only made for signals with identity scaling).
    Enum {
        repr: &'static str,
    },
}

impl SignalView {
    pub(crate) fn new(db: &Database, m: &Message, index: usize, s: &Signal) -> Self {
        SignalView {
            name: StrLit(s.name.clone()),
            message: StrLit(m.name.clone()),
            field: s.field.clone(),
            stem: s.field.trim_end_matches('_').to_owned(),
            index,
            docs: docs(m, s),
            raw_ty: raw_type(s),
            phys_ty: phys_rust(db, s.phys),
            placement: placement(s),
            raw: raw_codec(s),
            presence: presence(m, s),
            is_multiplexor: s.is_multiplexor,
            conversion: conversion(db, s),
            range: range_check(s),
            value: value_kind(db, s),
            named: named_values(s),
            meta: meta(db, index, s),
        }
    }

    /// The struct field's type: multiplexed signals are `Option`al.
    pub(crate) fn field_ty(&self) -> String {
        match self.presence {
            Presence::Always => self.phys_ty.clone(),
            Presence::When(_) => format!("Option<{}>", self.phys_ty),
        }
    }

    pub(crate) fn optional(&self) -> bool {
        matches!(self.presence, Presence::When(_))
    }

    /// The local holding a multiplexor's bits.
    pub(crate) fn bits_local(&self) -> String {
        format!("{}_bits", self.stem)
    }

    /// The call reading the signal's bits from `data`.
    pub(crate) fn read_expr(&self) -> String {
        let p = &self.placement;
        format!("bits::read_{}(data, {}, {})", p.order, p.start, p.len)
    }
}

fn raw_type(s: &Signal) -> &'static str {
    match s.encoding {
        Encoding::Float32 => "f32",
        Encoding::Float64 => "f64",
        _ => s.raw_int().rust(),
    }
}

fn scaling(s: &Signal) -> Scaling {
    Scaling {
        factor: s.factor,
        offset: s.offset,
    }
}

fn placement(s: &Signal) -> Placement {
    match s.byte_order {
        ByteOrder::LittleEndian => Placement {
            order: "le",
            start: s.start_bit,
            len: s.len,
        },
        ByteOrder::BigEndian => Placement {
            order: "be",
            start: be_linear(s.start_bit),
            len: s.len,
        },
    }
}

fn raw_codec(s: &Signal) -> RawCodec {
    let raw_int = s.raw_int();
    match s.encoding {
        Encoding::Float32 => RawCodec::F32,
        Encoding::Float64 => RawCodec::F64,
        Encoding::Signed => RawCodec::Signed {
            len: s.len,
            narrow: (raw_int != IntType::I64).then(|| raw_int.rust()),
        },
        Encoding::Unsigned if raw_int == IntType::U64 => RawCodec::Unsigned64,
        Encoding::Unsigned => RawCodec::Unsigned { ty: raw_int.rust() },
    }
}

fn presence(m: &Message, s: &Signal) -> Presence {
    let Some(c) = &s.mux else {
        return Presence::Always;
    };
    let selector = m.signals.get(c.selector);
    Presence::When(MuxCondition {
        selector: selector.map_or("selector".to_owned(), |x| {
            format!("{}_bits", x.field.trim_end_matches('_'))
        }),
        selector_optional: selector.is_some_and(|x| x.mux.is_some()),
        ranges: c.ranges.clone(),
    })
}

/// The width check for a raw integer of the signal's raw type.
fn fit(s: &Signal) -> Fit {
    let (lo, hi) = s.raw_range();
    if (lo, hi) == s.raw_int().range() {
        Fit::Full
    } else {
        Fit::Range { lo, hi }
    }
}

/// Whether `f64::from` takes a value of this type losslessly.
fn to_f64(t: IntType) -> ToF64 {
    match t {
        IntType::U8 | IntType::U16 | IntType::U32 | IntType::I8 | IntType::I16 | IntType::I32 => {
            ToF64::From
        }
        _ => ToF64::Cast,
    }
}

fn conversion(db: &Database, s: &Signal) -> Conversion {
    let raw_int = s.raw_int();
    let scaling = scaling(s);
    match s.phys {
        PhysType::Bool => Conversion::Bool,
        PhysType::Enum(i) => {
            let repr = db.enums.get(i).map_or(IntType::U64, |e| e.repr);
            Conversion::Enum {
                widen: (repr != raw_int).then(|| repr.rust()),
                fit: fit(s),
            }
        }
        PhysType::Int(t) if scaling.is_identity() => Conversion::Int {
            convert: t != raw_int,
            fit: fit(s),
        },
        PhysType::Int(t) => {
            let (factor, offset) = (s.factor as i128, s.offset as i128);
            let (raw_lo, raw_hi) = s.raw_range();
            let (phys_lo, phys_hi) = t.range();
            // Holds the raw type (for `From`), the physical range and the intermediate
            // `raw * factor`.
            let (type_lo, type_hi) = raw_int.range();
            let (a, b) = (raw_lo * factor, raw_hi * factor);
            Conversion::IntScaled {
                scaling: IntScaling {
                    arith: int_arith(
                        type_lo.min(phys_lo).min(a).min(b),
                        type_hi.max(phys_hi).max(a).max(b),
                    ),
                    factor,
                    offset,
                },
                fit: fit(s),
            }
        }
        PhysType::F32 | PhysType::F64 if s.is_float_raw() => Conversion::Float {
            scaling,
            wire: match (s.encoding, s.phys) {
                (Encoding::Float32, PhysType::F32) if scaling.is_identity() => FloatWire::F32Plain,
                (Encoding::Float32, PhysType::F32) => FloatWire::F32Scaled,
                (Encoding::Float32, _) => FloatWire::F32Wide,
                _ => FloatWire::F64,
            },
        },
        PhysType::F32 | PhysType::F64 => {
            let (raw_lo, _) = s.raw_range();
            let hi_excl = if s.encoding == Encoding::Signed {
                1i128 << (s.len - 1)
            } else {
                1i128 << s.len
            };
            let phys_f32 = s.phys == PhysType::F32;
            Conversion::Quantized {
                scaling,
                phys_f32,
                phys_to_f64: if phys_f32 { ToF64::From } else { ToF64::Same },
                raw_to_f64: to_f64(raw_int),
                lo: FloatLit(raw_lo as f64),
                hi: FloatLit(hi_excl as f64),
                bounded: bounded_rounding(s, scaling, raw_lo, hi_excl),
            }
        }
    }
}

/// How a quantized signal's encode may round without `round`'s special cases: when its range
/// check bounds the quotient to what the runtime's integer rounding takes exactly, and whether
/// the raw value then still needs checking against the signal's bits `lo..hi` (not when every
/// value the range lets through rounds into them). The check passes `[min - tolerance, max +
/// tolerance]`; unscaling (subtract, divide, each correctly rounded) and rounding are
/// monotonic, so the ends of that interval bound every raw value, and they are computed here
/// with the same `f64` operations as the generated code. Signals with named values skip the
/// range check for those values, so they keep the general path.
fn bounded_rounding(s: &Signal, scaling: Scaling, lo: i128, hi: i128) -> Option<BoundedRound> {
    let (min, max) = (s.min?, s.max?);
    if !s.value_labels.is_empty() || scaling.factor == 0.0 {
        return None;
    }
    let tolerance = s.factor.abs() * 1e-6;
    let a = scaling.invert_value(min - tolerance);
    let b = scaling.invert_value(max + tolerance);
    let (q_lo, q_hi) = (a.min(b), a.max(b));
    if !(q_lo.is_finite() && q_hi.is_finite()) {
        return None;
    }
    // `round_i32` truncates through `i32`: exact only while the quotient fits it.
    const I32: f64 = 2_147_483_648.0;
    const I52: f64 = 4_503_599_627_370_496.0;
    let round = if q_lo > -I32 && q_hi < I32 - 1.0 {
        "round_i32"
    } else if q_lo > -I52 && q_hi < I52 {
        "round_i64"
    } else {
        return None;
    };
    // The bits' bounds are powers of two: exact in f64.
    let fits = q_lo.round() >= lo as f64 && q_hi.round() < hi as f64;
    let bits = if fits {
        None
    } else {
        Some((i64::try_from(lo).ok()?, i64::try_from(hi).ok()?))
    };
    Some(BoundedRound { round, bits })
}

fn range_check(s: &Signal) -> Option<RangeCheck> {
    let (min, max) = (s.min?, s.max?);
    let number = |to_f64| {
        if s.value_labels.is_empty() {
            PhysAsF64::Number(to_f64)
        } else {
            PhysAsF64::NamedNumber(to_f64)
        }
    };
    let value = match s.phys {
        PhysType::Bool => PhysAsF64::Bool,
        PhysType::Int(t) => number(to_f64(t)),
        PhysType::F32 => number(ToF64::From),
        PhysType::F64 => number(ToF64::Same),
        PhysType::Enum(_) => PhysAsF64::UnknownEnum {
            scaling: scaling(s),
        },
    };
    Some(RangeCheck {
        value,
        min: FloatLit(min),
        max: FloatLit(max),
        tolerance: FloatLit(s.factor.abs() * 1e-6),
    })
}

fn named_values(s: &Signal) -> Option<NamedValues> {
    if s.value_labels.is_empty() {
        return None;
    }
    Some(NamedValues {
        scaling: scaling(s),
        to_f64: match s.phys {
            PhysType::Int(t) => to_f64(t),
            PhysType::F32 => ToF64::From,
            _ => ToF64::Same,
        },
    })
}

fn value_kind(db: &Database, s: &Signal) -> ValueKind {
    match s.phys {
        PhysType::Bool => ValueKind::Bool,
        PhysType::Int(t) => ValueKind::Int { ty: t.rust() },
        PhysType::F32 => ValueKind::F32,
        PhysType::F64 => ValueKind::F64,
        PhysType::Enum(i) => ValueKind::Enum {
            repr: db.enums.get(i).map_or("u64", |e| e.repr.rust()),
        },
    }
}

fn meta(db: &Database, index: usize, s: &Signal) -> MetaView {
    MetaView {
        name: StrLit(s.name.clone()),
        index,
        unit: StrLit(s.unit.clone()),
        comment: StrLit(s.comment.clone().unwrap_or_default()),
        start_bit: s.start_bit,
        len: s.len,
        byte_order: match s.byte_order {
            ByteOrder::LittleEndian => "LittleEndian",
            ByteOrder::BigEndian => "BigEndian",
        },
        signed: s.encoding == Encoding::Signed,
        factor: FloatLit(s.factor),
        offset: FloatLit(s.offset),
        min: OptionLit(s.min.map(FloatLit)),
        max: OptionLit(s.max.map(FloatLit)),
        labels: signal_labels(db, s),
        multiplexed: s.mux.is_some(),
    }
}

/// The schema's comment, then the wire facts, then when a multiplexed signal is present.
fn docs(m: &Message, s: &Signal) -> Vec<String> {
    let mut docs = s.comment.as_deref().map(doc_lines).unwrap_or_default();
    if !docs.is_empty() {
        docs.push(String::new());
    }
    let mut facts = format!(
        "`{}`: {} bit{} from bit {} ({}), {}",
        s.name,
        s.len,
        if s.len == 1 { "" } else { "s" },
        s.start_bit,
        match s.byte_order {
            ByteOrder::LittleEndian => "Intel",
            ByteOrder::BigEndian => "Motorola",
        },
        match s.encoding {
            Encoding::Unsigned => "unsigned",
            Encoding::Signed => "signed",
            Encoding::Float32 => "IEEE float",
            Encoding::Float64 => "IEEE double",
        }
    );
    facts.push_str(&scaling(s).doc());
    if let (Some(lo), Some(hi)) = (s.min, s.max) {
        facts.push_str(&format!(", range [{}, {}]", FloatLit(lo), FloatLit(hi)));
    }
    if !s.unit.is_empty() {
        facts.push_str(&format!(", unit `{}`", s.unit.replace('`', "'")));
    }
    facts.push('.');
    docs.push(facts);
    if !s.value_labels.is_empty() {
        let named: Vec<String> = s
            .value_labels
            .iter()
            .map(|(raw, label)| format!("raw {raw} = {}", label.replace('`', "'")))
            .collect();
        docs.push(format!(
            "Named values ({}): the value stays a number; `{}_label` names it.",
            named.join(", "),
            s.field.trim_end_matches('_')
        ));
    }
    if let Some(c) = &s.mux {
        let selector = m.signals.get(c.selector).map_or("?", |x| x.name.as_str());
        let values = crate::model::MuxCondition::describe(&c.ranges, "-", ", ");
        docs.push(format!("Present only when `{selector}` is {values}."));
    }
    docs
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{ByteOrder, Encoding, PhysType, Signal};

    fn quantized(
        len: u32,
        encoding: Encoding,
        factor: f64,
        offset: f64,
        range: (f64, f64),
    ) -> Signal {
        Signal {
            name: "S".to_owned(),
            field: "s".to_owned(),
            start_bit: 0,
            len,
            byte_order: ByteOrder::LittleEndian,
            encoding,
            factor,
            offset,
            min: Some(range.0),
            max: Some(range.1),
            unit: String::new(),
            comment: None,
            receivers: Vec::new(),
            phys: PhysType::F64,
            value_labels: Vec::new(),
            mux: None,
            is_multiplexor: false,
        }
    }

    /// The rounding and whether the raw value is still checked against the bits.
    fn rounding(s: &Signal) -> Option<(&'static str, bool)> {
        let (lo, hi) = s.raw_range();
        bounded_rounding(s, scaling(s), lo, hi + 1).map(|b| (b.round, b.bits.is_some()))
    }

    #[test]
    fn the_range_check_decides_whether_the_raw_value_needs_its_own() {
        use Encoding::{Signed, Unsigned};
        let q =
            |len, enc, factor, offset, range| rounding(&quantized(len, enc, factor, offset, range));
        // [-360, 360] / 0.01 = +-36000: beyond 16 signed bits (checked), within 17.
        assert_eq!(
            q(16, Signed, 0.01, 0.0, (-360.0, 360.0)),
            Some(("round_i32", true))
        );
        assert_eq!(
            q(17, Signed, 0.01, 0.0, (-360.0, 360.0)),
            Some(("round_i32", false))
        );
        // The top of the range rounds to 256 (255.5 up): does not fit 8 bits.
        assert_eq!(
            q(8, Unsigned, 1.0, 0.0, (0.0, 255.5)),
            Some(("round_i32", true))
        );
        assert_eq!(
            q(8, Unsigned, 1.0, 0.0, (0.0, 255.4)),
            Some(("round_i32", false))
        );
        // Offset and a negative factor: raw = (v - 10) / -0.5, v in [-100, 10] -> [0, 220].
        assert_eq!(
            q(8, Unsigned, -0.5, 10.0, (-100.0, 10.0)),
            Some(("round_i32", false))
        );
        assert_eq!(
            q(8, Unsigned, -0.5, 10.0, (-100.0, 10.5)),
            Some(("round_i32", true))
        );
        // 32 unsigned bits need the 64-bit rounding.
        assert_eq!(
            q(32, Unsigned, 0.001, 0.0, (0.0, 4_000_000.0)),
            Some(("round_i64", false))
        );
        // A quotient beyond 2^52, no range, or named values (which skip the range check): the
        // general path.
        assert_eq!(q(64, Unsigned, 1.0, 0.0, (0.0, 1e17)), None);
        let mut s = quantized(16, Unsigned, 0.1, 0.0, (0.0, 10.0));
        s.min = None;
        assert_eq!(rounding(&s), None);
        let mut s = quantized(16, Unsigned, 0.1, 0.0, (0.0, 10.0));
        s.value_labels.push((0, "Off".to_owned()));
        assert_eq!(rounding(&s), None);
    }
}
