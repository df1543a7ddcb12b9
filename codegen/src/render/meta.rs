//! The `SignalMeta` literal's parts, shared by CAN signals and telemetry fields
//! (`templates/meta.rs` spells it out).

use super::fragment::{FloatLit, OptionLit, StrLit};
use crate::model::{Database, PhysType, Signal};

pub(crate) struct MetaView {
    pub name: StrLit,
    /// Position in the message's signals (or the packet's fields).
    pub index: usize,
    pub unit: StrLit,
    pub comment: StrLit,
    pub start_bit: u32,
    pub len: u32,
    /// `LittleEndian` or `BigEndian`.
    pub byte_order: &'static str,
    pub signed: bool,
    pub factor: FloatLit,
    pub offset: FloatLit,
    pub min: OptionLit<FloatLit>,
    pub max: OptionLit<FloatLit>,
    /// Named raw values of an enum.
    pub labels: Vec<(i128, StrLit)>,
    pub multiplexed: bool,
}

/// The named raw values of a signal: its enum's, or those a scaled signal only recognises.
pub(crate) fn signal_labels(db: &Database, s: &Signal) -> Vec<(i128, StrLit)> {
    if s.value_labels.is_empty() {
        labels(db, s.phys)
    } else {
        s.value_labels
            .iter()
            .map(|(value, label)| (*value, StrLit(label.clone())))
            .collect()
    }
}

/// The named raw values of an enum type (none for other types).
pub(crate) fn labels(db: &Database, phys: PhysType) -> Vec<(i128, StrLit)> {
    match phys {
        PhysType::Enum(i) => db.enums.get(i).map_or(Vec::new(), |e| {
            e.variants
                .iter()
                .map(|v| (v.value, StrLit(v.label.clone())))
                .collect()
        }),
        _ => Vec::new(),
    }
}
