//! Checks a parsed DBC and builds the model from it.
//!
//! Errors are problems the generated code could not represent faithfully (bits outside the
//! frame, overlapping signals, duplicate ids or names, impossible lengths). Warnings are
//! problems a vendor's file may have that the codec can still handle safely (a range wider than
//! the raw type, a name that needs escaping); the car's own schema is built with warnings denied.
//!
//! `Builder::build` walks the messages; `message` checks a frame and names its signals;
//! `signal` checks one signal's placement, encoding and scaling and picks its physical type;
//! `enums` and `mux` resolve value tables and multiplexing.

mod enums;
mod index;
mod integrity;
mod message;
mod mux;
mod node_id;
mod overlap;
mod signal;

use std::collections::HashMap;
use std::path::Path;

use crate::diagnostic::{Code, Diagnostics, Reporter};
use crate::load::dbc::LoadedDbc;
use crate::model::{Database, Node};
use crate::naming::{camel, snake};
use index::DbcIndex;

/// Type names the generated module defines or imports itself, and the prelude's that its code
/// uses: a message or enum with one of these names would shadow them.
const RESERVED_TYPES: [&str; 19] = [
    "AnyMessage",
    "ByteOrder",
    "CanMessage",
    "DecodeError",
    "EncodeError",
    "MessageMeta",
    "SignalMeta",
    "SignalSource",
    "SignalVisitor",
    "Value",
    "Option",
    "Result",
    "Some",
    "None",
    "Ok",
    "Err",
    "From",
    "Default",
    "Iterator",
];

/// Validates `loaded` and builds the model. Returns every diagnostic (warnings too) alongside.
pub(crate) fn validate(
    path: &Path,
    loaded: &LoadedDbc,
    allow: &[Code],
) -> Result<(Database, Vec<crate::diagnostic::Diagnostic>), Diagnostics> {
    let mut r = Reporter::new(path, &loaded.text).allowing(allow);
    let mut db = Builder {
        loaded,
        index: DbcIndex::new(&loaded.dbc),
        taken: Taken::default(),
        table_enums: HashMap::new(),
        node_ids: node_id::declared(&loaded.dbc),
        r: &mut r,
    }
    .build();
    if db.messages.is_empty() && !r.has_errors() {
        r.report(
            Code::NoMessages,
            1,
            "the file defines no messages".to_owned(),
            "check that it is the whole file: an empty or cut-short DBC generates an empty codec",
        );
    }
    db.name = path
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("dbc")
        .to_owned();
    db.bit_rate = bit_rate(&loaded.dbc);
    for load in crate::bus_load::loads(&db, None) {
        report_overload(&mut r, &load, baudrate_line(&loaded.text));
    }
    if r.has_errors() {
        Err(Diagnostics(r.diagnostics))
    } else {
        Ok((db, r.diagnostics))
    }
}

/// The `Baudrate` database attribute (bit/s), if given.
fn bit_rate(dbc: &can_dbc::Dbc) -> Option<u32> {
    dbc.attribute_values_database
        .iter()
        .find(|a| a.name == "Baudrate")
        .and_then(|a| match a.value {
            can_dbc::AttributeValue::Uint(v) => u32::try_from(v).ok(),
            can_dbc::AttributeValue::Int(v) => u32::try_from(v).ok(),
            can_dbc::AttributeValue::Double(v) if v >= 1.0 => Some(v as u32),
            _ => None,
        })
        .filter(|rate| *rate > 0)
}

/// The line of `BA_ "Baudrate" ...`, else 0 (the file as a whole).
fn baudrate_line(text: &str) -> usize {
    text.lines()
        .position(|l| l.trim_start().starts_with("BA_ \"Baudrate\""))
        .map_or(0, |i| i + 1)
}

/// W0210 for a bus above the warning threshold.
pub(crate) fn report_overload(r: &mut Reporter<'_>, load: &crate::bus_load::BusLoad, line: usize) {
    if load.load <= crate::bus_load::WARN_LOAD {
        return;
    }
    r.report(
        Code::BusOverloaded,
        line,
        format!(
            "bus `{}` is {:.0} % loaded at worst-case bit stuffing ({:.0} frames/s, {:.1} kbit/s), \
             above the {:.0} % the generator allows without a warning",
            load.bus,
            load.load * 100.0,
            load.frames_per_s,
            load.bits_per_s / 1_000.0,
            crate::bus_load::WARN_LOAD * 100.0
        ),
        "lengthen cycle times, merge signals into fewer frames, or move messages to another bus",
    );
}

struct Builder<'a, 'r> {
    loaded: &'a LoadedDbc,
    index: DbcIndex<'a>,
    taken: Taken,
    /// A `VAL_TABLE_`'s values (sorted, see `enums`) -> the index of the enum they share.
    table_enums: HashMap<Vec<(i128, String)>, usize>,
    /// Nodes whose id is part of their messages' CAN ids (`node_id`).
    node_ids: HashMap<&'a str, u8>,
    r: &'r mut Reporter<'a>,
}

/// A signal before its enum and multiplexing are resolved.
struct Draft<'a> {
    sig: &'a can_dbc::Signal,
    line: usize,
}

/// A message whose id and names passed: what its signals are checked against.
struct Frame<'a> {
    msg: &'a can_dbc::Message,
    /// Line of its `BO_`.
    line: usize,
    /// The id as written (bit 31 flags an extended id).
    written_id: u64,
    id: u32,
    extended: bool,
    /// Its full name (Vector keeps names over 32 characters in an attribute).
    name: String,
    type_name: String,
    /// Unique snake-case name for its SQL table, topic and metadata static.
    item_name: String,
}

/// Ids and names already taken, with the line that took them.
#[derive(Default)]
struct Taken {
    ids: HashMap<(u32, bool), usize>,
    names: HashMap<String, usize>,
    /// Rust type names (messages and enums share one namespace).
    type_names: HashMap<String, usize>,
    /// Per-message item names in snake case (SQL tables, topics, metadata statics).
    item_names: HashMap<String, usize>,
}

/// `wanted` if `is_free` says so, else `wanted` with the first of `suffixes` that is: the same
/// schema always gives the same names.
fn first_free(
    wanted: &str,
    suffixes: impl IntoIterator<Item = String>,
    is_free: impl Fn(&str) -> bool,
) -> String {
    if is_free(wanted) {
        return wanted.to_owned();
    }
    suffixes
        .into_iter()
        .map(|suffix| format!("{wanted}{suffix}"))
        .chain((2u64..).map(|n| format!("{wanted}{n}")))
        .find(|name| is_free(name))
        .unwrap_or_else(|| wanted.to_owned())
}

impl<'a> Builder<'a, '_> {
    fn build(mut self) -> Database {
        let dbc = &self.loaded.dbc;
        for name in RESERVED_TYPES {
            self.taken.type_names.insert(name.to_owned(), 0);
        }
        let mut enums = self.value_tables();
        let mut messages = Vec::new();
        for (index, msg) in dbc.messages.iter().enumerate() {
            // Vector's container for signals not yet placed in a frame; it never goes on a bus.
            if msg.name == "VECTOR__INDEPENDENT_SIG_MSG" {
                continue;
            }
            let Some(frame) = self.identify(index, msg) else {
                continue;
            };
            self.check_node_id(&frame);
            if let Some(m) = self.message(frame, &mut enums) {
                messages.push(m);
            }
        }
        Database {
            name: String::new(),
            nodes: self.nodes(),
            enums,
            messages,
            bit_rate: None,
        }
    }

    fn nodes(&self) -> Vec<Node> {
        let dbc = &self.loaded.dbc;
        dbc.nodes
            .iter()
            .map(|n| Node {
                name: n.0.clone(),
                comment: self.index.node_comment(&n.0).map(str::to_owned),
            })
            .collect()
    }

    /// Checks the message's id and names against the limits and what earlier messages took.
    fn identify(&mut self, index: usize, msg: &'a can_dbc::Message) -> Option<Frame<'a>> {
        let (line, written_id) = self
            .loaded
            .lines
            .messages
            .get(index)
            .copied()
            .unwrap_or((0, u64::from(msg.id.raw())));
        let (id, extended) = self.check_id(line, written_id, &msg.name)?;
        if let Some(first) = self.taken.ids.insert((id, extended), line) {
            self.r.report(
                Code::DuplicateId,
                line,
                format!(
                    "message `{}` reuses id 0x{id:X}, already used on line {first}",
                    msg.name
                ),
                "every message needs its own id on the bus; give one of them a free id",
            );
            return None;
        }
        let name = self.long_message_name(msg);
        if let Some(first) = self.taken.names.insert(name.clone(), line) {
            self.r.report(
                Code::DuplicateMessageName,
                line,
                format!("message name `{name}` is already used on line {first}"),
                "every message needs its own name; rename one of them",
            );
            return None;
        }
        let type_name = self.claim_type_name(&camel(&name), [format!("0x{id:X}")], line, || {
            format!("message `{name}`")
        });
        let wanted_item = snake(&type_name).trim_end_matches('_').to_owned();
        let item_name = first_free(&wanted_item, [format!("_0x{id:x}")], |n| {
            !self.taken.item_names.contains_key(n)
        });
        if item_name != wanted_item {
            self.r.report(
                Code::Renamed,
                line,
                format!("message `{name}` would have the table, topic and constant name `{wanted_item}`, already taken; it is `{item_name}`"),
                "keep message names distinct after conversion to snake_case",
            );
        }
        self.taken.item_names.insert(item_name.clone(), line);
        Some(Frame {
            msg,
            line,
            written_id,
            id,
            extended,
            name,
            type_name,
            item_name,
        })
    }

    /// Checks the id as written (can-dbc truncates standard ids above 0xFFFF).
    fn check_id(&mut self, line: usize, written: u64, name: &str) -> Option<(u32, bool)> {
        const EXTENDED_FLAG: u64 = 1 << 31;
        if written & EXTENDED_FLAG != 0 {
            let id = written & !EXTENDED_FLAG;
            if id > 0x1FFF_FFFF {
                self.r.report(
                    Code::IdOutOfRange,
                    line,
                    format!("message `{name}` has extended id 0x{id:X}, above the 29-bit limit 0x1FFFFFFF"),
                    "write the id as 0x80000000 + (29-bit id) in decimal",
                );
                return None;
            }
            u32::try_from(id).ok().map(|id| (id, true))
        } else if written > 0x7FF {
            let extended = self.r.allows(Code::IdOutOfRange) && written <= 0x1FFF_FFFF;
            self.r.report(
                Code::IdOutOfRange,
                line,
                format!(
                    "message `{name}` has standard id 0x{written:X}, above the 11-bit limit 0x7FF"
                ),
                "for a 29-bit id add 2147483648 (bit 31, Vector's extended-frame flag) to the id",
            );
            extended
                .then(|| u32::try_from(written).ok().map(|id| (id, true)))
                .flatten()
        } else {
            u32::try_from(written).ok().map(|id| (id, false))
        }
    }
}
