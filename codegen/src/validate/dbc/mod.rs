//! Checks a parsed DBC and builds the model from it.
//!
//! Errors are problems the generated code could not represent faithfully (bits outside the
//! frame, overlapping signals, duplicate ids or names, impossible lengths). Warnings are
//! problems a vendor's file may have that the codec can still handle safely (a range wider than
//! the raw type, a name that needs escaping); the car's own schema is built with warnings denied.

use std::collections::HashMap;
use std::path::Path;

use can_dbc::{
    AttributeValue, ByteOrder as DbcByteOrder, MessageId, MultiplexIndicator, NumericValue,
    SignalExtendedValueType, ValueDescription, ValueType,
};

use crate::diagnostic::{Code, Diagnostics, Reporter};
use crate::load::dbc::LoadedDbc;
use crate::model::{
    ByteOrder, Database, Encoding, EnumType, IntType, Message, Node, PhysType, Signal,
};
use crate::naming::{camel, is_keyword, snake};

/// Payload lengths a CAN FD frame can carry.
const FD_LENGTHS: [usize; 15] = [0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48];

/// Type names the generated module defines itself.
const RESERVED_TYPES: [&str; 1] = ["AnyMessage"];

/// Signal attribute a schema can set to `"f32"` to ask for a single-precision physical value.
pub const PHYS_TYPE_ATTRIBUTE: &str = "AerPhysType";

/// Validates `loaded` and builds the model. Returns every diagnostic (warnings too) alongside.
pub fn validate(
    path: &Path,
    loaded: &LoadedDbc,
) -> Result<(Database, Vec<crate::diagnostic::Diagnostic>), Diagnostics> {
    let mut r = Reporter::new(path, &loaded.text);
    let mut db = Builder { loaded, r: &mut r }.build();
    db.name = path
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("dbc")
        .to_owned();
    if r.has_errors() {
        Err(Diagnostics(r.diagnostics))
    } else {
        Ok((db, r.diagnostics))
    }
}

struct Builder<'a, 'r> {
    loaded: &'a LoadedDbc,
    r: &'r mut Reporter<'a>,
}

/// A signal before its enum and multiplexing are resolved.
struct Draft<'a> {
    sig: &'a can_dbc::Signal,
    line: usize,
}

impl<'a> Builder<'a, '_> {
    fn build(mut self) -> Database {
        let dbc = &self.loaded.dbc;
        let nodes = dbc
            .nodes
            .iter()
            .map(|n| Node {
                name: n.0.clone(),
                comment: dbc.comments.iter().find_map(|c| match c {
                    can_dbc::Comment::Node { name, comment } if *name == n.0 => {
                        Some(comment.clone())
                    }
                    _ => None,
                }),
            })
            .collect();

        let mut enums = self.value_tables();
        let mut messages = Vec::new();
        let mut ids: HashMap<(u32, bool), usize> = HashMap::new();
        let mut names: HashMap<String, usize> = HashMap::new();
        let mut type_names: HashMap<String, usize> =
            enums.iter().map(|e| (e.type_name.clone(), 0)).collect();
        for reserved in RESERVED_TYPES {
            type_names.insert(reserved.to_owned(), 0);
        }

        for (index, msg) in dbc.messages.iter().enumerate() {
            let (line, written_id) = self
                .loaded
                .lines
                .messages
                .get(index)
                .copied()
                .unwrap_or((0, u64::from(msg.id.raw())));
            // Vector's container for signals not yet placed in a frame; it never goes on a bus.
            if msg.name == "VECTOR__INDEPENDENT_SIG_MSG" {
                continue;
            }
            let Some((id, extended)) = self.check_id(line, written_id, &msg.name) else {
                continue;
            };
            if let Some(first) = ids.insert((id, extended), line) {
                self.r.report(
                    Code::DuplicateId,
                    line,
                    format!(
                        "message `{}` reuses id 0x{id:X}, already used on line {first}",
                        msg.name
                    ),
                    "every message needs its own id on the bus; give one of them a free id",
                );
                continue;
            }
            let msg_name = self.long_message_name(msg);
            if let Some(first) = names.insert(msg_name.clone(), line) {
                self.r.report(
                    Code::DuplicateMessageName,
                    line,
                    format!(
                        "message name `{}` is already used on line {first}",
                        msg_name
                    ),
                    "every message needs its own name; rename one of them",
                );
                continue;
            }
            let mut type_name = camel(&msg_name);
            if let Some(first) = type_names.get(&type_name).copied() {
                let renamed = format!("{type_name}0x{id:X}");
                self.r.report(
                    Code::Renamed,
                    line,
                    format!("message `{msg_name}` would be named `{type_name}` in Rust, a name already taken (line {first}); it is named `{renamed}`"),
                    "keep message and value-table names distinct after conversion to CamelCase",
                );
                type_name = renamed;
            }
            type_names.insert(type_name.clone(), line);
            if let Some(mut m) =
                self.message(msg, line, written_id, id, extended, type_name, &mut enums)
            {
                m.name = msg_name;
                messages.push(m);
            }
        }
        Database {
            name: String::new(),
            nodes,
            enums,
            messages,
        }
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
            self.r.report(
                Code::IdOutOfRange,
                line,
                format!(
                    "message `{name}` has standard id 0x{written:X}, above the 11-bit limit 0x7FF"
                ),
                "for a 29-bit id add 2147483648 (bit 31, Vector's extended-frame flag) to the id",
            );
            None
        } else {
            u32::try_from(written).ok().map(|id| (id, false))
        }
    }

    /// The message's full name: Vector keeps names over 32 characters in an attribute.
    fn long_message_name(&self, msg: &can_dbc::Message) -> String {
        self.loaded
            .dbc
            .attribute_values_message
            .iter()
            .find_map(|a| match &a.value {
                AttributeValue::String(long)
                    if a.name == "SystemMessageLongSymbol"
                        && a.message_id == msg.id
                        && !long.is_empty() =>
                {
                    Some(long.clone())
                }
                _ => None,
            })
            .unwrap_or_else(|| msg.name.clone())
    }

    /// The signal's full name (see [`Self::long_message_name`]).
    fn long_signal_name(&self, msg: &can_dbc::Message, sig: &can_dbc::Signal) -> String {
        self.loaded
            .dbc
            .attribute_values_signal
            .iter()
            .find_map(|a| match &a.value {
                AttributeValue::String(long)
                    if a.name == "SystemSignalLongSymbol"
                        && a.message_id == msg.id
                        && a.signal_name == sig.name
                        && !long.is_empty() =>
                {
                    Some(long.clone())
                }
                _ => None,
            })
            .unwrap_or_else(|| sig.name.clone())
    }

    fn message_attribute(&self, name: &str, id: MessageId) -> Option<&'a AttributeValue> {
        let dbc = &self.loaded.dbc;
        dbc.attribute_values_message
            .iter()
            .find(|a| a.name == name && a.message_id == id)
            .map(|a| &a.value)
            .or_else(|| {
                dbc.attribute_defaults
                    .iter()
                    .find(|d| d.name == name)
                    .map(|d| &d.value)
            })
    }

    fn is_fd(&self, id: MessageId, len: usize) -> bool {
        let declared = match self.message_attribute("VFrameFormat", id) {
            Some(AttributeValue::Uint(v)) => matches!(v, 14 | 15),
            Some(AttributeValue::Int(v)) => matches!(v, 14 | 15),
            Some(AttributeValue::String(s)) => s.ends_with("_FD"),
            _ => false,
        };
        declared || len > 8
    }

    #[allow(clippy::too_many_arguments)]
    fn message(
        &mut self,
        msg: &'a can_dbc::Message,
        line: usize,
        written_id: u64,
        id: u32,
        extended: bool,
        type_name: String,
        enums: &mut Vec<EnumType>,
    ) -> Option<Message> {
        let len = usize::try_from(msg.size).unwrap_or(usize::MAX);
        if len > 64 {
            self.r.report(
                Code::FrameLength,
                line,
                format!(
                    "message `{}` is {} bytes long; a CAN frame carries 0-8 bytes, CAN FD up to 64",
                    msg.name, msg.size
                ),
                "set the length (the number after the colon) to a valid frame length",
            );
            return None;
        }
        if !FD_LENGTHS.contains(&len) && len != 64 {
            self.r.report(
                Code::FdLength,
                line,
                format!("message `{}` is {len} bytes long, which no CAN FD frame carries exactly (12, 16, 20, 24, 32, 48, 64)", msg.name),
                "use the next valid CAN FD length; frames on the bus are padded to it",
            );
        }
        let fd = self.is_fd(msg.id, len);
        let cycle_time_ms = match self.message_attribute("GenMsgCycleTime", msg.id) {
            Some(AttributeValue::Uint(v)) if *v > 0 => u32::try_from(*v).ok(),
            Some(AttributeValue::Int(v)) if *v > 0 => u32::try_from(*v).ok(),
            Some(AttributeValue::Double(v)) if *v >= 1.0 && *v <= f64::from(u32::MAX) => {
                Some(v.round() as u32)
            }
            _ => None,
        };
        let comment = self.loaded.dbc.message_comment(msg.id).map(str::to_owned);

        let drafts: Vec<Draft<'a>> = msg
            .signals
            .iter()
            .map(|sig| Draft {
                sig,
                line: self
                    .loaded
                    .lines
                    .signals
                    .get(&(written_id, sig.name.clone()))
                    .copied()
                    .unwrap_or(line),
            })
            .collect();

        let mut signals = Vec::new();
        let mut fields: HashMap<String, (String, usize)> = HashMap::new();
        let mut ok = true;
        for d in &drafts {
            let sig_name = self.long_signal_name(msg, d.sig);
            let mut field = snake(&sig_name);
            if let Some((other, other_line)) = fields.get(&field).cloned() {
                if other == sig_name {
                    self.r.report(
                        Code::DuplicateSignal,
                        d.line,
                        format!("signal `{}` is defined twice in message `{}` (first on line {other_line})", sig_name, msg.name),
                        "signal names must be unique within a message; rename or remove one",
                    );
                    ok = false;
                    continue;
                }
                let renamed = format!("{field}_{}", fields.len());
                self.r.report(
                    Code::Renamed,
                    d.line,
                    format!("signals `{other}` (line {other_line}) and `{sig_name}` would both be the Rust field `{field}`; this one is `{renamed}`"),
                    "keep signal names distinct after conversion to snake_case",
                );
                field = renamed;
            }
            fields.insert(field.clone(), (sig_name.clone(), d.line));
            if is_keyword(&d.sig.name) || is_keyword(&field) || field.ends_with('_') {
                self.r.report(
                    Code::KeywordName,
                    d.line,
                    format!(
                        "signal name `{}` is a Rust keyword; its field is named `{field}`",
                        d.sig.name
                    ),
                    "rename the signal so that generated code reads naturally",
                );
            }
            match self.signal(msg, written_id, len, d, field, &type_name, enums) {
                Some(mut s) => {
                    s.name = sig_name;
                    signals.push(s);
                }
                None => ok = false,
            }
        }
        if !ok {
            return None;
        }
        self.resolve_multiplexing(msg, written_id, &drafts, &mut signals)?;
        let eval_order = self.eval_order(msg, line, &signals)?;
        self.check_overlaps(msg, &drafts, &signals);

        Some(Message {
            name: msg.name.clone(),
            type_name,
            id,
            extended,
            len,
            fd,
            cycle_time_ms,
            transmitter: msg.transmitter.clone(),
            comment,
            signals,
            eval_order,
        })
    }

    #[allow(clippy::too_many_arguments)]
    fn signal(
        &mut self,
        msg: &'a can_dbc::Message,
        written_id: u64,
        msg_len: usize,
        d: &Draft<'a>,
        field: String,
        type_name: &str,
        enums: &mut Vec<EnumType>,
    ) -> Option<Signal> {
        let sig = d.sig;
        let line = d.line;
        let where_ = format!("signal `{}` of message `{}`", sig.name, msg.name);
        if sig.size == 0 || sig.size > 64 {
            self.r.report(
                Code::SignalLength,
                line,
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
                start_bit < frame_bits && crate::model::be_linear(start_bit) + len <= frame_bits
            }
        };
        if !in_frame {
            let hint = match byte_order {
                ByteOrder::BigEndian => {
                    "for Motorola (@0) signals the start bit is the MSB in sawtooth numbering (byte*8 + 7 for the top bit of a byte); check it, the length and the message length"
                }
                ByteOrder::LittleEndian => {
                    "for Intel (@1) signals the start bit is the LSB; start + length must not exceed 8 * message length"
                }
            };
            self.r.report(
                Code::SignalOutsideFrame,
                line,
                format!(
                    "{where_} ({}|{}@{}) has bits outside the {msg_len}-byte frame",
                    sig.start_bit,
                    sig.size,
                    if byte_order == ByteOrder::LittleEndian {
                        1
                    } else {
                        0
                    }
                ),
                hint,
            );
            return None;
        }

        let value_type_line = self
            .loaded
            .lines
            .value_types
            .get(&(written_id, sig.name.clone()))
            .copied()
            .unwrap_or(line);
        let ext = self
            .loaded
            .dbc
            .signal_extended_value_type_list
            .iter()
            .find(|e| e.message_id == msg.id && e.signal_name == sig.name)
            .map(|e| &e.signal_extended_value_type);
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
                line,
                format!("{where_} has factor {} and offset {}; the factor must be a non-zero finite number", sig.factor, sig.offset),
                "fix the `(factor,offset)` pair in the SG_ line",
            );
            return None;
        }

        let min = numeric(&sig.min);
        let max = numeric(&sig.max);
        let (min, max) = if min == 0.0 && max == 0.0 {
            (None, None)
        } else {
            (Some(min), Some(max))
        };
        if let (Some(lo), Some(hi)) = (min, max) {
            if lo > hi {
                self.r.report(
                    Code::RangeInverted,
                    line,
                    format!("{where_} has minimum {lo} above its maximum {hi}"),
                    "swap the numbers in `[min|max]`",
                );
                return None;
            }
        }

        let mut s = Signal {
            name: sig.name.clone(),
            field,
            start_bit,
            len,
            byte_order,
            encoding,
            factor: sig.factor,
            offset: sig.offset,
            min,
            max,
            unit: sig.unit.clone(),
            comment: self
                .loaded
                .dbc
                .signal_comment(msg.id, &sig.name)
                .map(str::to_owned),
            receivers: sig
                .receivers
                .iter()
                .filter(|r| r.as_str() != "Vector__XXX")
                .cloned()
                .collect(),
            phys: PhysType::F64,
            mux: None,
            is_multiplexor: matches!(
                sig.multiplexer_indicator,
                MultiplexIndicator::Multiplexor
                    | MultiplexIndicator::MultiplexorAndMultiplexedSignal(_)
            ),
        };
        self.check_range(&s, line, &where_);
        s.phys = self.phys_type(msg, written_id, &s, line, &where_, type_name, enums)?;
        Some(s)
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

    #[allow(clippy::too_many_arguments)]
    fn phys_type(
        &mut self,
        msg: &can_dbc::Message,
        written_id: u64,
        s: &Signal,
        line: usize,
        where_: &str,
        type_name: &str,
        enums: &mut Vec<EnumType>,
    ) -> Option<PhysType> {
        let dbc = &self.loaded.dbc;
        let wants_f32 = dbc.attribute_values_signal.iter().any(|a| {
            a.name == PHYS_TYPE_ATTRIBUTE
                && a.message_id == msg.id
                && a.signal_name == s.name
                && matches!(&a.value, AttributeValue::String(v) if v == "f32")
        });
        let choices = dbc.value_descriptions.iter().find_map(|v| match v {
            ValueDescription::Signal {
                message_id,
                name,
                value_descriptions,
            } if *message_id == msg.id && *name == s.name => Some(value_descriptions),
            _ => None,
        });
        let integral = |v: f64| v.fract() == 0.0 && v.abs() < 9.0e18;

        if wants_f32 {
            let attr_line = self
                .loaded
                .lines
                .signal_attributes
                .get(&(PHYS_TYPE_ATTRIBUTE.to_owned(), written_id, s.name.clone()))
                .copied()
                .unwrap_or(line);
            if s.encoding == Encoding::Float64 || (!s.is_float_raw() && s.len > 24) {
                self.r.report(
                    Code::F32TooNarrow,
                    attr_line,
                    format!("{where_} asks for an f32 physical value, but its {}-bit raw value does not fit f32's 24-bit mantissa", s.len),
                    "remove the AerPhysType attribute (f64 is used) or shorten the signal to 24 bits",
                );
                return None;
            }
            return Some(PhysType::F32);
        }
        match s.encoding {
            Encoding::Float32 if s.factor == 1.0 && s.offset == 0.0 => return Some(PhysType::F32),
            Encoding::Float32 | Encoding::Float64 => return Some(PhysType::F64),
            _ => {}
        }
        if let Some(choices) = choices.filter(|c| !c.is_empty()) {
            let val_line = self
                .loaded
                .lines
                .values
                .get(&(written_id, s.name.clone()))
                .copied()
                .unwrap_or(line);
            return self
                .enum_for(s, choices, val_line, where_, type_name, enums)
                .map(PhysType::Enum);
        }
        if s.len == 1 && s.encoding == Encoding::Unsigned && s.factor == 1.0 && s.offset == 0.0 {
            return Some(PhysType::Bool);
        }
        if integral(s.factor) && integral(s.offset) {
            let (lo, hi) = s.raw_range();
            let f = s.factor as i128;
            let o = s.offset as i128;
            let (a, b) = (lo * f + o, hi * f + o);
            return Some(PhysType::Int(IntType::smallest_for(a.min(b), a.max(b))));
        }
        Some(PhysType::F64)
    }
}

fn numeric(v: &NumericValue) -> f64 {
    match *v {
        NumericValue::Uint(u) => u as f64,
        NumericValue::Int(i) => i as f64,
        NumericValue::Double(d) => d,
    }
}

mod enums;
mod mux;
