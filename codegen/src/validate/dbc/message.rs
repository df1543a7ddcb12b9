//! One message: its frame length and format, cycle time, and its signals' Rust names.

use std::collections::HashMap;

use can_dbc::{AttributeValue, MessageId};

use super::{Builder, Draft, Frame, first_free};
use crate::diagnostic::Code;
use crate::model::{DEFAULT_MISSED_FRAMES, EnumType, Message, Signal};
use crate::naming::{is_keyword, snake};

/// Field names the store's tables use for their own columns.
const RESERVED_FIELDS: [&str; 4] = ["ts", "car_id", "bus", "schema_fingerprint"];

/// The generated code's local for a field's raw bits.
fn bits_local(field: &str) -> String {
    format!("{}_bits", field.trim_end_matches('_'))
}

/// Payload lengths a CAN FD frame can carry.
const FD_LENGTHS: [usize; 15] = [0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48];

impl<'a> Builder<'a, '_> {
    /// The message with its signals, or `None` (reported) when any part is unusable.
    pub(super) fn message(
        &mut self,
        frame: Frame<'a>,
        enums: &mut Vec<EnumType>,
    ) -> Option<Message> {
        let msg = frame.msg;
        let len = self.frame_len(&frame)?;
        // The n-th signal of a name takes the n-th `SG_` line of that name.
        let mut seen: HashMap<&str, usize> = HashMap::new();
        let drafts: Vec<Draft<'a>> = msg
            .signals
            .iter()
            .map(|sig| {
                let nth = seen.entry(sig.name.as_str()).or_default();
                let line = self
                    .loaded
                    .lines
                    .signals
                    .get(&(frame.written_id, sig.name.clone()))
                    .and_then(|lines| lines.get(*nth))
                    .copied()
                    .unwrap_or(frame.line);
                *nth += 1;
                Draft { sig, line }
            })
            .collect();
        let mut signals = self.signals(&frame, len, &drafts, enums)?;
        self.resolve_multiplexing(msg, frame.written_id, &drafts, &mut signals)?;
        let eval_order = self.eval_order(msg, frame.line, &signals)?;
        self.check_overlaps(msg, &drafts, &signals, &eval_order);
        let (counter, checksum) = self.integrity(&frame, &drafts, &signals)?;
        let cycle_time_ms = self.cycle_time(msg.id);
        self.check_send_type(&frame, cycle_time_ms);
        Some(Message {
            fd: self.is_fd(msg.id, len),
            cycle_time_ms,
            timeout_ms: self.timeout(msg.id, cycle_time_ms),
            counter,
            checksum,
            buses: self.buses(msg.id),
            comment: self.index.message_comment(msg.id).map(str::to_owned),
            name: frame.name,
            type_name: frame.type_name,
            item_name: frame.item_name,
            id: frame.id,
            extended: frame.extended,
            len,
            transmitter: msg.transmitter.clone(),
            signals,
            eval_order,
        })
    }

    /// The payload length: at most 64 bytes, and one a CAN FD frame carries exactly.
    fn frame_len(&mut self, frame: &Frame<'_>) -> Option<usize> {
        let msg = frame.msg;
        let len = usize::try_from(msg.size).unwrap_or(usize::MAX);
        if len > 64 {
            self.r.report(
                Code::FrameLength,
                frame.line,
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
                frame.line,
                format!("message `{}` is {len} bytes long, which no CAN FD frame carries exactly (12, 16, 20, 24, 32, 48, 64)", msg.name),
                "use the next valid CAN FD length; frames on the bus are padded to it",
            );
        }
        Some(len)
    }

    /// Every signal, named for Rust; `None` when any is unusable (each one is reported).
    fn signals(
        &mut self,
        frame: &Frame<'a>,
        len: usize,
        drafts: &[Draft<'a>],
        enums: &mut Vec<EnumType>,
    ) -> Option<Vec<Signal>> {
        let mut signals = Vec::new();
        let mut fields: HashMap<String, (String, usize)> = HashMap::new();
        let mut ok = true;
        for d in drafts {
            let name = self.long_signal_name(frame.msg, d.sig);
            let Some(field) = self.field_name(frame.msg, d, &name, &mut fields) else {
                ok = false;
                continue;
            };
            match self.signal(frame, len, d, field, enums) {
                Some(mut s) => {
                    s.name = name;
                    signals.push(s);
                }
                None => ok = false,
            }
        }
        ok.then_some(signals)
    }

    /// The signal's Rust field: its name in snake_case, renamed (with a warning) where two
    /// names meet; `None` (an error) for a name used twice.
    fn field_name(
        &mut self,
        msg: &can_dbc::Message,
        d: &Draft<'_>,
        name: &str,
        fields: &mut HashMap<String, (String, usize)>,
    ) -> Option<String> {
        let wanted = snake(name);
        if let Some((other, other_line)) = fields.get(&wanted).cloned() {
            if other == name {
                self.r.report(
                    Code::DuplicateSignal,
                    d.line,
                    format!("signal `{name}` is defined twice in message `{}` (first on line {other_line})", msg.name),
                    "signal names must be unique within a message; rename or remove one",
                );
                return None;
            }
        }
        // A field also takes the name of its raw bits' local in the generated code
        // (`<field>_bits`); the store's fixed columns are taken from the start.
        let free = |f: &str| {
            !RESERVED_FIELDS.contains(&f)
                && !fields.contains_key(f)
                && !fields.contains_key(&bits_local(f))
        };
        let field = first_free(&wanted, [], free);
        if field != wanted {
            let why = match fields
                .get(&wanted)
                .or_else(|| fields.get(&bits_local(&wanted)))
            {
                Some((other, other_line)) => {
                    format!("signal `{other}` (line {other_line}) already takes it")
                }
                None => "the store reserves it for its own column".to_owned(),
            };
            self.r.report(
                Code::Renamed,
                d.line,
                format!(
                    "signal `{name}` would be the Rust field `{wanted}`, but {why}; it is `{field}`"
                ),
                "keep signal names distinct after conversion to snake_case",
            );
        }
        fields.insert(field.clone(), (name.to_owned(), d.line));
        fields.insert(bits_local(&field), (name.to_owned(), d.line));
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
        Some(field)
    }

    fn cycle_time(&self, id: MessageId) -> Option<u32> {
        match self.message_attribute("GenMsgCycleTime", id) {
            Some(AttributeValue::Uint(v)) if *v > 0 => u32::try_from(*v).ok(),
            Some(AttributeValue::Int(v)) if *v > 0 => u32::try_from(*v).ok(),
            Some(AttributeValue::Double(v)) if *v >= 1.0 && *v <= f64::from(u32::MAX) => {
                Some(v.round() as u32)
            }
            _ => None,
        }
    }

    /// The freshness limit: `AerTimeoutMs` where given (and positive), else a few cycle times.
    fn timeout(&self, id: MessageId, cycle_time_ms: Option<u32>) -> Option<u32> {
        let declared = match self.message_attribute("AerTimeoutMs", id) {
            Some(AttributeValue::Uint(v)) if *v > 0 => u32::try_from(*v).ok(),
            Some(AttributeValue::Int(v)) if *v > 0 => u32::try_from(*v).ok(),
            _ => None,
        };
        declared.or_else(|| cycle_time_ms.map(|ms| ms.saturating_mul(DEFAULT_MISSED_FRAMES)))
    }

    /// The buses the `AerBus` attribute names (comma-separated), none when it is absent.
    fn buses(&self, id: MessageId) -> Vec<String> {
        match self.message_attribute("AerBus", id) {
            Some(AttributeValue::String(names)) => names
                .split(',')
                .map(str::trim)
                .filter(|name| !name.is_empty())
                .map(str::to_owned)
                .collect(),
            _ => Vec::new(),
        }
    }

    /// The message's full name: Vector keeps names over 32 characters in an attribute.
    pub(super) fn long_message_name(&self, msg: &can_dbc::Message) -> String {
        self.index
            .message_attributes("SystemMessageLongSymbol", msg.id)
            .iter()
            .find_map(|value| match value {
                AttributeValue::String(long) if !long.is_empty() => Some(long.clone()),
                _ => None,
            })
            .unwrap_or_else(|| msg.name.clone())
    }

    /// The signal's full name (see [`Self::long_message_name`]).
    fn long_signal_name(&self, msg: &can_dbc::Message, sig: &can_dbc::Signal) -> String {
        self.index
            .signal_attributes("SystemSignalLongSymbol", msg.id, &sig.name)
            .iter()
            .find_map(|value| match value {
                AttributeValue::String(long) if !long.is_empty() => Some(long.clone()),
                _ => None,
            })
            .unwrap_or_else(|| sig.name.clone())
    }

    pub(super) fn message_attribute(
        &self,
        name: &str,
        id: MessageId,
    ) -> Option<&'a AttributeValue> {
        self.index
            .message_attributes(name, id)
            .first()
            .copied()
            .or_else(|| self.index.attribute_default(name))
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
}
