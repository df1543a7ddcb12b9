//! A telemetry field as the templates see it: where it sits in the packet, how its physical
//! value converts to the wire type (saturating, since telemetry must keep flowing), its
//! metadata and dashboard hints.

use crate::model::{Database, PhysType, Placement, TelemetryField, WireType};
use crate::render::fragment::{FloatLit, IntScaling, OptionLit, Scaling, StrLit, ToF64, int_arith};
use crate::render::meta::{MetaView, labels};
use crate::render::{doc_lines, phys_rust};

pub(crate) struct FieldView {
    pub name: String,
    /// Position in the packet's field list (and its metadata array).
    pub index: usize,
    pub docs: Vec<String>,
    pub phys_ty: String,
    pub wire_ty: &'static str,
    pub placement: FieldPlacement,
    pub conversion: FieldConversion,
    pub is_enum: bool,
    /// The field mirrors a DBC signal (generated code fills it from frames).
    pub mirrored: bool,
    pub default: FieldDefault,
    pub meta: MetaView,
    pub display: DisplayView,
}

/// Where the field sits in the packet.
pub(crate) enum FieldPlacement {
    /// A little-endian value at this byte offset.
    Bytes { at: usize },
    /// A flag: bit `bit` of byte `byte`, which is flag byte `flag_byte` (counted from the first
    /// flag byte).
    Flag {
        byte: usize,
        bit: u8,
        flag_byte: usize,
    },
}

/// How the physical value converts to the wire value and back.
pub(crate) enum FieldConversion {
    /// The wire holds the value itself.
    Identity,
    Enum,
    /// Exact integer scaling, saturated to the wire type's range `lo..=hi`.
    IntScaled {
        scaling: IntScaling,
        lo: i128,
        hi: i128,
    },
    /// A float on the wire.
    Float {
        scaling: Scaling,
        phys_f32: bool,
        phys_to_f64: ToF64,
    },
    /// A float rounded to an integer wire type, saturated to `lo..=hi` (NaN is 0).
    Quantized {
        scaling: Scaling,
        phys_f32: bool,
        phys_to_f64: ToF64,
        lo: FloatLit,
        hi: FloatLit,
    },
}

/// The value before any data arrived.
pub(crate) enum FieldDefault {
    False,
    Zero,
    ZeroFloat,
    /// The enum's raw 0.
    RawZero,
}

/// The `FieldDisplay` literal.
pub(crate) struct DisplayView {
    pub group: StrLit,
    pub label: StrLit,
    pub warn: OptionLit<FloatLit>,
    pub critical: OptionLit<FloatLit>,
    pub warn_below: OptionLit<FloatLit>,
    pub critical_below: OptionLit<FloatLit>,
    /// The DBC message the field mirrors (`signal: MESSAGE.SIGNAL`).
    pub mirrors: OptionLit<StrLit>,
}

impl FieldView {
    pub(crate) fn new(
        db: &Database,
        first_flag_byte: usize,
        index: usize,
        f: &TelemetryField,
    ) -> Self {
        FieldView {
            name: f.name.clone(),
            index,
            docs: docs(f),
            phys_ty: phys_rust(db, f.phys),
            wire_ty: f.wire.rust(),
            placement: match f.placement {
                Placement::Bytes(at) => FieldPlacement::Bytes { at },
                Placement::Bit(byte, bit) => FieldPlacement::Flag {
                    byte,
                    bit,
                    flag_byte: byte - first_flag_byte,
                },
            },
            conversion: conversion(f),
            is_enum: matches!(f.phys, PhysType::Enum(_)),
            mirrored: f.source.is_some(),
            default: match f.phys {
                PhysType::Bool => FieldDefault::False,
                PhysType::Int(_) => FieldDefault::Zero,
                PhysType::F32 | PhysType::F64 => FieldDefault::ZeroFloat,
                PhysType::Enum(_) => FieldDefault::RawZero,
            },
            meta: meta(db, index, f),
            display: display(f),
        }
    }

    pub(crate) fn is_flag(&self) -> bool {
        matches!(self.placement, FieldPlacement::Flag { .. })
    }
}

fn conversion(f: &TelemetryField) -> FieldConversion {
    let scaling = Scaling {
        factor: f.scale,
        offset: f.offset,
    };
    let (lo, hi) = f.wire.range();
    let phys_f32 = f.phys == PhysType::F32;
    let phys_to_f64 = if phys_f32 { ToF64::From } else { ToF64::Same };
    match (f.phys, f.wire) {
        (PhysType::Bool, _) => FieldConversion::Identity,
        (PhysType::Enum(_), _) => FieldConversion::Enum,
        (PhysType::Int(t), w) if scaling.is_identity() && t.rust() == w.rust() => {
            FieldConversion::Identity
        }
        (PhysType::Int(t), _) => {
            let (factor, offset) = (f.scale as i128, f.offset as i128);
            let (phys_lo, phys_hi) = t.range();
            // Holds the wire and physical ranges and the intermediate `raw * factor`.
            let (a, b) = (lo * factor, hi * factor);
            FieldConversion::IntScaled {
                scaling: IntScaling {
                    arith: int_arith(lo.min(phys_lo).min(a).min(b), hi.max(phys_hi).max(a).max(b)),
                    factor,
                    offset,
                },
                lo,
                hi,
            }
        }
        (PhysType::F32, WireType::F32) if scaling.is_identity() => FieldConversion::Identity,
        (_, WireType::F32) => FieldConversion::Float {
            scaling,
            phys_f32,
            phys_to_f64,
        },
        _ => FieldConversion::Quantized {
            scaling,
            phys_f32,
            phys_to_f64,
            lo: FloatLit(lo as f64),
            hi: FloatLit(hi as f64),
        },
    }
}

fn meta(db: &Database, index: usize, f: &TelemetryField) -> MetaView {
    let start_bit = match f.placement {
        Placement::Bytes(at) => at * 8,
        Placement::Bit(byte, bit) => byte * 8 + usize::from(bit),
    };
    MetaView {
        name: StrLit(f.name.clone()),
        index,
        unit: StrLit(f.unit.clone()),
        comment: StrLit(f.description.clone()),
        start_bit: u32::try_from(start_bit).unwrap_or(u32::MAX),
        len: f.wire.bits(),
        byte_order: "LittleEndian",
        signed: matches!(f.wire, WireType::I8 | WireType::I16 | WireType::I32),
        factor: FloatLit(f.scale),
        offset: FloatLit(f.offset),
        min: OptionLit(f.min.map(FloatLit)),
        max: OptionLit(f.max.map(FloatLit)),
        labels: labels(db, f.phys),
        multiplexed: false,
    }
}

fn display(f: &TelemetryField) -> DisplayView {
    let limit = |v: Option<f64>| OptionLit(v.map(FloatLit));
    DisplayView {
        group: StrLit(f.group.clone()),
        label: StrLit(f.display.label.clone().unwrap_or_else(|| f.name.clone())),
        warn: limit(f.display.warn),
        critical: limit(f.display.critical),
        warn_below: limit(f.display.warn_below),
        critical_below: limit(f.display.critical_below),
        mirrors: OptionLit(
            f.source
                .as_deref()
                .and_then(|source| source.split_once('.'))
                .map(|(message, _)| StrLit(message.to_owned())),
        ),
    }
}

/// The description, then the wire facts.
fn docs(f: &TelemetryField) -> Vec<String> {
    let mut docs = doc_lines(&f.description);
    if !docs.is_empty() {
        docs.push(String::new());
    }
    let mut facts = match f.placement {
        Placement::Bytes(at) => format!("Wire: `{}` at byte {at}", f.wire.rust()),
        Placement::Bit(byte, bit) => format!("Wire: flag in bit {bit} of byte {byte}"),
    };
    let scaling = Scaling {
        factor: f.scale,
        offset: f.offset,
    };
    facts.push_str(&scaling.doc());
    if !f.unit.is_empty() {
        facts.push_str(&format!(", unit `{}`", f.unit));
    }
    if let Some(src) = &f.source {
        facts.push_str(&format!(", mirrors `{src}`"));
    }
    facts.push('.');
    docs.push(facts);
    docs
}
