//! Multiplexing: conditions from `mN` indicators and `SG_MUL_VAL_` lines, the order in which
//! multiplexors must be decoded, and overlaps between signals that can share a frame.

use std::collections::{BTreeSet, HashMap};

use can_dbc::MultiplexIndicator;

use super::{Builder, Draft, overlap};
use crate::diagnostic::Code;
use crate::model::{MuxCondition, Signal};

/// A finding that has been reported; the caller only needs to know it failed.
struct Reported;

/// The signals that can select others: by their name as written, and the `M` ones.
struct Selectors {
    by_name: HashMap<String, usize>,
    multiplexors: Vec<usize>,
}

impl<'a> Builder<'a, '_> {
    /// Attaches mux conditions from `mN` indicators and `SG_MUL_VAL_` lines.
    pub(super) fn resolve_multiplexing(
        &mut self,
        msg: &can_dbc::Message,
        written_id: u64,
        drafts: &[Draft<'a>],
        signals: &mut [Signal],
    ) -> Option<()> {
        let selectors = Selectors {
            // SG_MUL_VAL_ lines use the short names as written in the SG_ lines.
            by_name: drafts
                .iter()
                .enumerate()
                .map(|(i, d)| (d.sig.name.clone(), i))
                .collect(),
            multiplexors: signals
                .iter()
                .enumerate()
                .filter(|(_, s)| s.is_multiplexor)
                .map(|(i, _)| i)
                .collect(),
        };
        let mut ok = true;
        for (i, d) in drafts.iter().enumerate() {
            let where_ = format!("signal `{}` of message `{}`", d.sig.name, msg.name);
            let condition = match self.mux_condition(msg, written_id, i, d, &where_, &selectors) {
                Ok(Some(condition)) => condition,
                Ok(None) => continue,
                Err(Reported) => {
                    ok = false;
                    continue;
                }
            };
            if self
                .check_selector(d, &where_, &condition, signals)
                .is_err()
            {
                ok = false;
                continue;
            }
            if let Some(signal) = signals.get_mut(i) {
                signal.mux = Some(condition);
            }
        }
        ok.then_some(())
    }

    /// When signal `i` is present: from its `SG_MUL_VAL_` lines, else from its `mN` indicator
    /// and the message's one multiplexor; `None` for a signal that is always present.
    fn mux_condition(
        &mut self,
        msg: &can_dbc::Message,
        written_id: u64,
        i: usize,
        d: &Draft<'_>,
        where_: &str,
        selectors: &Selectors,
    ) -> Result<Option<MuxCondition>, Reported> {
        let extended = self.index.extended_multiplex(msg.id, &d.sig.name);
        // An SG_MUL_VAL_ line defines the condition whatever the indicator says (tools that
        // dump extended multiplexing often write a nested multiplexor as plain `M`).
        let value = match d.sig.multiplexer_indicator {
            MultiplexIndicator::MultiplexedSignal(v)
            | MultiplexIndicator::MultiplexorAndMultiplexedSignal(v) => v,
            _ if !extended.is_empty() => 0,
            _ => return Ok(None),
        };
        let Some(first) = extended.first() else {
            return self
                .implicit_condition(i, d, value, where_, selectors)
                .map(Some);
        };
        let line = self
            .loaded
            .lines
            .mux_values
            .get(&(written_id, d.sig.name.clone()))
            .copied()
            .unwrap_or(d.line);
        let Some(&selector) = selectors.by_name.get(&first.multiplexor_signal_name) else {
            self.r.report(
                Code::Multiplexing,
                line,
                format!(
                    "{where_} is multiplexed by `{}`, which is not a signal of the message",
                    first.multiplexor_signal_name
                ),
                "name an existing multiplexor signal in the SG_MUL_VAL_ line",
            );
            return Err(Reported);
        };
        Ok(Some(MuxCondition {
            selector,
            ranges: extended
                .iter()
                .flat_map(|e| e.mappings.iter().map(|m| (m.min_value, m.max_value)))
                .collect(),
        }))
    }

    /// `mN` without `SG_MUL_VAL_`: selected by the message's only other multiplexor.
    fn implicit_condition(
        &mut self,
        i: usize,
        d: &Draft<'_>,
        value: u64,
        where_: &str,
        selectors: &Selectors,
    ) -> Result<MuxCondition, Reported> {
        let candidates: Vec<usize> = selectors
            .multiplexors
            .iter()
            .copied()
            .filter(|&m| m != i)
            .collect();
        match candidates.as_slice() {
            [selector] => Ok(MuxCondition {
                selector: *selector,
                ranges: vec![(value, value)],
            }),
            [] => {
                self.r.report(
                    Code::Multiplexing,
                    d.line,
                    format!("{where_} is multiplexed (m{value}) but the message has no multiplexor signal (M)"),
                    "mark the selector signal with `M`, or remove the `m` indicator",
                );
                Err(Reported)
            }
            _ => {
                self.r.report(
                    Code::Multiplexing,
                    d.line,
                    format!("{where_} is multiplexed (m{value}) but the message has several multiplexors and no SG_MUL_VAL_ line says which one selects it"),
                    "add `SG_MUL_VAL_ <id> <signal> <multiplexor> <lo>-<hi>;` for this signal",
                );
                Err(Reported)
            }
        }
    }

    /// The selector must be an integer multiplexor that can take every value it selects on.
    fn check_selector(
        &mut self,
        d: &Draft<'_>,
        where_: &str,
        condition: &MuxCondition,
        signals: &[Signal],
    ) -> Result<(), Reported> {
        let Some(sel) = signals.get(condition.selector) else {
            return Err(Reported);
        };
        if !sel.is_multiplexor || sel.is_float_raw() {
            self.r.report(
                Code::Multiplexing,
                d.line,
                format!("{where_} is selected by `{}`, which is not an integer multiplexor signal (M)", sel.name),
                "mark the selector with `M` (or `mNM` when it is itself multiplexed); selectors must be integers",
            );
            return Err(Reported);
        }
        let (_, sel_hi) = sel.raw_range();
        if let Some(&(lo, hi)) = condition
            .ranges
            .iter()
            .find(|(lo, hi)| lo > hi || i128::from(*hi) > sel_hi)
        {
            self.r.report(
                Code::MuxValueOutOfRange,
                d.line,
                format!("{where_} is selected by `{}` values {lo}-{hi}, which its {}-bit multiplexor cannot take", sel.name, sel.len),
                "use multiplexor values between 0 and the multiplexor's largest raw value",
            );
            return Err(Reported);
        }
        Ok(())
    }

    /// Orders signals so that each multiplexor is decoded before what it selects.
    pub(super) fn eval_order(
        &mut self,
        msg: &can_dbc::Message,
        line: usize,
        signals: &[Signal],
    ) -> Option<Vec<usize>> {
        let order = overlap::decode_order(signals);
        if order.is_none() {
            self.r.report(
                Code::Multiplexing,
                line,
                format!("the multiplexors of message `{}` select each other in a cycle", msg.name),
                "a multiplexor must not be selected, directly or indirectly, by a signal it selects",
            );
        }
        order
    }

    /// Reports signals that share bits and can be present in the same frame (`order`: the
    /// decoding order).
    pub(super) fn check_overlaps(
        &mut self,
        msg: &can_dbc::Message,
        drafts: &[Draft<'a>],
        signals: &[Signal],
        order: &[usize],
    ) {
        // One finding per signal, naming every earlier signal it overlaps.
        let mut by_signal: std::collections::BTreeMap<usize, Vec<usize>> = Default::default();
        for (a, b) in overlap::overlaps(signals, order) {
            by_signal.entry(b).or_default().push(a);
        }
        for (b, earlier) in by_signal {
            let (Some(second), Some(draft)) = (signals.get(b), drafts.get(b)) else {
                continue;
            };
            let ours: BTreeSet<u32> = second.bits().into_iter().collect();
            let with: Vec<(&str, Vec<u32>)> = earlier
                .iter()
                .filter_map(|&a| signals.get(a))
                .map(|first| {
                    let shared: BTreeSet<u32> = first
                        .bits()
                        .into_iter()
                        .filter(|bit| ours.contains(bit))
                        .collect();
                    (first.name.as_str(), shared.into_iter().collect())
                })
                .collect();
            let message = match with.as_slice() {
                [(first, shared)] => format!(
                    "signals `{first}` and `{}` of message `{}` overlap in bit(s) {shared:?}",
                    second.name, msg.name
                ),
                _ => format!(
                    "signal `{}` of message `{}` overlaps {} signals: {}",
                    second.name,
                    msg.name,
                    with.len(),
                    with.iter()
                        .map(|(name, shared)| format!("`{name}` in bit(s) {shared:?}"))
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            };
            self.r.report(
                Code::SignalOverlap,
                draft.line,
                message,
                "move one of them, or make them alternatives of the same multiplexor",
            );
        }
    }
}
