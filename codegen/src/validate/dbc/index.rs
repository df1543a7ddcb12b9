//! Lookups into the parsed DBC by node, message and signal, built once per file. can-dbc's own
//! helpers scan every comment, attribute or value list on each call, which made validation
//! quadratic in the file's size (10,000 signals with comments took a second, 30,000 six).

use std::collections::HashMap;

use can_dbc::{
    AttributeValue, Comment, Dbc, ExtendedMultiplex, MessageId, SignalExtendedValueType,
    ValDescription, ValueDescription,
};

/// By message, then by signal name as written in the `SG_` line. (Nested rather than keyed by
/// a pair so that lookups take any `&str`.)
type BySignal<'a, V> = HashMap<MessageId, HashMap<&'a str, V>>;

/// Everything the checks look up per message or signal. Where the file says something twice,
/// the lists keep the file's order so lookups pick what can-dbc's helpers would.
#[derive(Default)]
pub(super) struct DbcIndex<'a> {
    node_comments: HashMap<&'a str, &'a str>,
    message_comments: HashMap<MessageId, &'a str>,
    signal_comments: BySignal<'a, &'a str>,
    value_descriptions: BySignal<'a, &'a [ValDescription]>,
    /// By attribute name, then message.
    message_attributes: HashMap<&'a str, HashMap<MessageId, Vec<&'a AttributeValue>>>,
    /// By attribute name, then signal.
    signal_attributes: HashMap<&'a str, BySignal<'a, Vec<&'a AttributeValue>>>,
    attribute_defaults: HashMap<&'a str, &'a AttributeValue>,
    extended_multiplex: BySignal<'a, Vec<&'a ExtendedMultiplex>>,
    value_types: BySignal<'a, &'a SignalExtendedValueType>,
}

impl<'a> DbcIndex<'a> {
    pub(super) fn new(dbc: &'a Dbc) -> Self {
        let mut index = Self::default();
        for comment in &dbc.comments {
            match comment {
                Comment::Node { name, comment } => {
                    index.node_comments.entry(name.as_str()).or_insert(comment);
                }
                Comment::Message { id, comment } => {
                    index.message_comments.entry(*id).or_insert(comment);
                }
                Comment::Signal {
                    message_id,
                    name,
                    comment,
                } => {
                    index
                        .signal_comments
                        .entry(*message_id)
                        .or_default()
                        .entry(name.as_str())
                        .or_insert(comment);
                }
                _ => {}
            }
        }
        for values in &dbc.value_descriptions {
            if let ValueDescription::Signal {
                message_id,
                name,
                value_descriptions,
            } = values
            {
                index
                    .value_descriptions
                    .entry(*message_id)
                    .or_default()
                    .entry(name.as_str())
                    .or_insert(value_descriptions);
            }
        }
        for a in &dbc.attribute_values_message {
            index
                .message_attributes
                .entry(a.name.as_str())
                .or_default()
                .entry(a.message_id)
                .or_default()
                .push(&a.value);
        }
        for a in &dbc.attribute_values_signal {
            index
                .signal_attributes
                .entry(a.name.as_str())
                .or_default()
                .entry(a.message_id)
                .or_default()
                .entry(a.signal_name.as_str())
                .or_default()
                .push(&a.value);
        }
        for d in &dbc.attribute_defaults {
            index
                .attribute_defaults
                .entry(d.name.as_str())
                .or_insert(&d.value);
        }
        for e in &dbc.extended_multiplex {
            index
                .extended_multiplex
                .entry(e.message_id)
                .or_default()
                .entry(e.signal_name.as_str())
                .or_default()
                .push(e);
        }
        for v in &dbc.signal_extended_value_type_list {
            index
                .value_types
                .entry(v.message_id)
                .or_default()
                .entry(v.signal_name.as_str())
                .or_insert(&v.signal_extended_value_type);
        }
        index
    }

    /// The signal's `SIG_VALTYPE_` (IEEE float), if any.
    pub(super) fn value_type(
        &self,
        id: MessageId,
        signal: &str,
    ) -> Option<&'a SignalExtendedValueType> {
        self.value_types.get(&id)?.get(signal).copied()
    }

    pub(super) fn node_comment(&self, node: &str) -> Option<&'a str> {
        self.node_comments.get(node).copied()
    }

    pub(super) fn message_comment(&self, id: MessageId) -> Option<&'a str> {
        self.message_comments.get(&id).copied()
    }

    pub(super) fn signal_comment(&self, id: MessageId, signal: &str) -> Option<&'a str> {
        self.signal_comments.get(&id)?.get(signal).copied()
    }

    /// The signal's `VAL_` list.
    pub(super) fn value_descriptions(
        &self,
        id: MessageId,
        signal: &str,
    ) -> Option<&'a [ValDescription]> {
        self.value_descriptions.get(&id)?.get(signal).copied()
    }

    /// The message's values of attribute `name`, in the file's order.
    pub(super) fn message_attributes(&self, name: &str, id: MessageId) -> &[&'a AttributeValue] {
        self.message_attributes
            .get(name)
            .and_then(|by_message| by_message.get(&id))
            .map_or(&[], Vec::as_slice)
    }

    /// The signal's values of attribute `name`, in the file's order.
    pub(super) fn signal_attributes(
        &self,
        name: &str,
        id: MessageId,
        signal: &str,
    ) -> &[&'a AttributeValue] {
        self.signal_attributes
            .get(name)
            .and_then(|by_message| by_message.get(&id))
            .and_then(|by_signal| by_signal.get(signal))
            .map_or(&[], Vec::as_slice)
    }

    /// The attribute's default (`BA_DEF_DEF_`).
    pub(super) fn attribute_default(&self, name: &str) -> Option<&'a AttributeValue> {
        self.attribute_defaults.get(name).copied()
    }

    /// The signal's `SG_MUL_VAL_` lines.
    pub(super) fn extended_multiplex(
        &self,
        id: MessageId,
        signal: &str,
    ) -> &[&'a ExtendedMultiplex] {
        self.extended_multiplex
            .get(&id)
            .and_then(|by_signal| by_signal.get(signal))
            .map_or(&[], Vec::as_slice)
    }
}
