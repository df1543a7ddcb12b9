//! The block of numbers the slave publishes about itself, for the ECU to map into its
//! measurement memory (the CCM's A2L describes it as MEASUREMENTs): the last refusal and why
//! ([`crate::LastRefusal`]), then the running totals ([`crate::Counters`]). A calibration tool
//! reads why it was refused, and a measuring one what DAQ lost, from the ECU itself.
//!
//! Layout, little-endian, [`STATUS_LEN`] bytes: the last refusal ([`LAST_REFUSAL_LEN`] bytes,
//! see [`crate::LastRefusal::to_bytes`]), then one u32 each, in [`COUNTERS`]' order.

use crate::refusal::LAST_REFUSAL_LEN;

/// How a field of the block is stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// One unsigned byte.
    U8,
    /// An unsigned 16-bit integer.
    U16,
    /// An unsigned 32-bit integer.
    U32,
    /// An IEEE 754 single.
    F32,
}

/// Which names a field's values have.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Names {
    /// A plain number.
    None,
    /// A command code ([`crate::protocol::cmd::NAMES`]).
    Command,
    /// An error code ([`crate::protocol::err::NAMES`]).
    Error,
    /// A reason ([`crate::reason::ALL`]).
    Reason,
    /// The ECU's parameter index (its own list; [`crate::Detail::NO_ITEM`] for none).
    Item,
}

/// One field of the block, as an ECU description names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Field {
    /// Its name.
    pub name: &'static str,
    /// What it holds.
    pub description: &'static str,
    /// How it is stored.
    pub kind: Kind,
    /// Its offset in the block.
    pub offset: u32,
    /// Which names its values have.
    pub names: Names,
}

const fn field(
    name: &'static str,
    description: &'static str,
    kind: Kind,
    offset: u32,
    names: Names,
) -> Field {
    Field {
        name,
        description,
        kind,
        offset,
        names,
    }
}

/// Every field of the block in order: the last refusal ([`crate::LastRefusal::to_bytes`]'s
/// layout), then the counters ([`COUNTERS`]).
pub const FIELDS: [Field; 16] = {
    const REFUSAL: [Field; 8] = [
        field(
            "refusals",
            "Refused commands since start-up (a new refusal changes it)",
            Kind::U32,
            0,
            Names::None,
        ),
        field(
            "refused_command",
            "The last refused command",
            Kind::U8,
            4,
            Names::Command,
        ),
        field(
            "refused_error",
            "The XCP error code it was answered with",
            Kind::U8,
            5,
            Names::Error,
        ),
        field(
            "refused_reason",
            "Why it was refused",
            Kind::U8,
            6,
            Names::Reason,
        ),
        field(
            "refused_element",
            "The element of the item it concerns",
            Kind::U8,
            7,
            Names::None,
        ),
        field(
            "refused_item",
            "The calibration parameter it concerns",
            Kind::U16,
            8,
            Names::Item,
        ),
        field(
            "refused_value",
            "The value refused (or what the reason says)",
            Kind::F32,
            12,
            Names::None,
        ),
        field(
            "refused_limit",
            "The limit it met (or what the reason says)",
            Kind::F32,
            16,
            Names::None,
        ),
    ];
    let mut fields = [REFUSAL[0]; 16];
    let mut index = 0;
    while index < REFUSAL.len() {
        fields[index] = REFUSAL[index];
        index += 1;
    }
    let mut counter = 0;
    while counter < COUNTERS.len() {
        let (name, description) = COUNTERS[counter];
        fields[REFUSAL.len() + counter] = field(
            name,
            description,
            Kind::U32,
            (LAST_REFUSAL_LEN + 4 * counter) as u32,
            Names::None,
        );
        counter += 1;
    }
    fields
};

/// The counters in the block, in order, with what each counts.
pub const COUNTERS: [(&str, &str); 8] = [
    ("commands", "Command packets handled"),
    ("errors", "Error packets answered"),
    ("dtos_sent", "DAQ packets the bus queue took"),
    ("dtos_dropped", "DAQ packets lost: the bus queue was full"),
    (
        "overloads",
        "Overload episodes (each announced with EV_DAQ_OVERLOAD)",
    ),
    (
        "daq_faults",
        "DAQ samples abandoned: a read the target had accepted was refused",
    ),
    (
        "idle_ends",
        "Sessions the idle time-out ended (or relocked, with DAQ running)",
    ),
    (
        "wrong_keys",
        "Wrong keys (each ended its session and delayed the next seed)",
    ),
];

/// Bytes of the block.
pub const STATUS_LEN: usize = LAST_REFUSAL_LEN + 4 * COUNTERS.len();
