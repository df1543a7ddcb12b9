//! CAN messages on the pit view, read from the Pi's typed CAN topics: the messages picked, each
//! one's newest signals with the schema's units and value names, and its age against the
//! message's own generated freshness limit. Everything comes from the generated tables
//! (`aer::mqtt::CAN_TOPICS`), so a message added to the DBC can be shown after `cargo build`,
//! with no telemetry change and no reflash.

use super::Freshness;
use super::fields::FieldValue;
use aer::can::AnyMessage;
use aer::mqtt::{CAN_TOPICS, CanTopic, Sample};
use aer::runtime::{MessageMeta, SignalMeta, SignalVisitor, Value};
use std::time::{Duration, Instant};

/// One signal of a received frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CanSignal {
    pub meta: &'static SignalMeta,
    pub value: FieldValue,
}

/// A message's newest frame.
#[derive(Debug, Clone, PartialEq)]
pub struct CanFrame {
    /// When the Pi received it (s since the epoch).
    pub ts: f64,
    /// When it reached this dashboard.
    pub received: Instant,
    /// Every signal present in the frame, in schema order.
    pub signals: Vec<CanSignal>,
}

/// The CAN messages picked for the pit view and their newest frames.
#[derive(Debug, Clone, Default)]
pub struct CanMessages {
    /// Positions in [`CAN_TOPICS`], in the order picked.
    shown: Vec<usize>,
    /// The newest frame of each shown message, by position in [`CAN_TOPICS`].
    latest: Vec<Option<CanFrame>>,
}

impl CanMessages {
    /// Showing the messages called `names` (unknown names are skipped; the configuration
    /// refuses them).
    pub fn new(names: &[String]) -> Self {
        let mut messages = Self {
            shown: Vec::new(),
            latest: vec![None; CAN_TOPICS.len()],
        };
        for name in names {
            if let Some(index) = CAN_TOPICS.iter().position(|t| t.meta.name == name) {
                if !messages.shown.contains(&index) {
                    messages.shown.push(index);
                }
            }
        }
        messages
    }

    /// Every message the schema has, in schema order.
    pub fn topics() -> &'static [CanTopic] {
        &CAN_TOPICS
    }

    /// The message at `index` of [`Self::topics`].
    pub fn meta(index: usize) -> Option<&'static MessageMeta> {
        CAN_TOPICS.get(index).map(|t| t.meta)
    }

    /// Positions of the shown messages, in the order picked.
    pub fn shown(&self) -> &[usize] {
        &self.shown
    }

    /// The topic suffixes the link must subscribe to: the shown messages' only.
    pub fn suffixes(&self) -> Vec<&'static str> {
        self.shown
            .iter()
            .filter_map(|&index| CAN_TOPICS.get(index))
            .map(|t| t.suffix)
            .collect()
    }

    /// Shows message `index`, or hides it (and forgets its frame).
    pub fn toggle(&mut self, index: usize) {
        if let Some(at) = self.shown.iter().position(|&i| i == index) {
            self.shown.remove(at);
            if let Some(slot) = self.latest.get_mut(index) {
                *slot = None;
            }
        } else if index < CAN_TOPICS.len() {
            self.shown.push(index);
        }
    }

    /// Takes a frame received at `now`. Frames of messages not shown (still in flight after
    /// the unsubscribe) are ignored.
    pub fn take(&mut self, sample: &Sample<AnyMessage>, now: Instant) {
        let meta = sample.value.meta();
        let Some(index) = CAN_TOPICS
            .iter()
            .position(|t| (t.meta.id, t.meta.extended) == (meta.id, meta.extended))
        else {
            return;
        };
        if !self.shown.contains(&index) {
            return;
        }
        let mut signals = match self.latest.get_mut(index).and_then(Option::take) {
            Some(old) => old.signals,
            None => Vec::with_capacity(meta.signals.len()),
        };
        signals.clear();
        sample.value.visit(&mut Collect(&mut signals));
        if let Some(slot) = self.latest.get_mut(index) {
            *slot = Some(CanFrame {
                ts: sample.ts,
                received: now,
                signals,
            });
        }
    }

    /// The newest frame of message `index`.
    pub fn latest(&self, index: usize) -> Option<&CanFrame> {
        self.latest.get(index).and_then(Option::as_ref)
    }

    /// How current message `index` is at `now`: stale once its newest frame is older than the
    /// message's generated freshness limit (`TIMEOUT_MS`); a message sent on demand has none
    /// and never goes stale.
    pub fn freshness(&self, index: usize, now: Instant) -> Freshness {
        let Some(frame) = self.latest(index) else {
            return Freshness::NoData;
        };
        let age = now.saturating_duration_since(frame.received);
        match Self::meta(index).and_then(|m| m.timeout_ms) {
            Some(limit) if age > Duration::from_millis(u64::from(limit)) => Freshness::Stale(age),
            _ => Freshness::Fresh,
        }
    }
}

struct Collect<'a>(&'a mut Vec<CanSignal>);

impl SignalVisitor for Collect<'_> {
    fn signal(&mut self, meta: &'static SignalMeta, value: Value, label: Option<&'static str>) {
        self.0.push(CanSignal {
            meta,
            value: FieldValue {
                value: value.to_f64(),
                label,
            },
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use aer::can::{DtiTemperatures, PccStatus};

    /// A frame of all-zero bytes of `meta`'s message.
    fn frame(meta: &MessageMeta) -> Sample<AnyMessage> {
        Sample {
            ts: 1_795_348_800.0,
            value: AnyMessage::decode(meta.id, meta.extended, &[0; 64]).unwrap(),
        }
    }

    #[test]
    fn only_shown_messages_are_kept_and_subscribed() {
        let mut can = CanMessages::new(&["DTI_Temperatures".into(), "NoSuchMessage".into()]);
        assert_eq!(can.suffixes(), ["can/dti_temperatures"]);
        let t0 = Instant::now();
        can.take(&frame(PccStatus::META), t0);
        let pcc = CAN_TOPICS
            .iter()
            .position(|t| t.meta.name == "PCC_Status")
            .unwrap();
        assert!(can.latest(pcc).is_none());
        can.toggle(pcc);
        assert_eq!(can.suffixes(), ["can/dti_temperatures", "can/pcc_status"]);
        can.take(&frame(PccStatus::META), t0);
        assert_eq!(
            can.latest(pcc).unwrap().signals.len(),
            PccStatus::META.signals.len()
        );
        can.toggle(pcc);
        assert!(can.latest(pcc).is_none());
        assert_eq!(can.suffixes(), ["can/dti_temperatures"]);
    }

    #[test]
    fn a_message_is_stale_after_exactly_its_generated_limit() {
        let mut can = CanMessages::new(&["DTI_Temperatures".into()]);
        let index = can.shown()[0];
        let limit = Duration::from_millis(u64::from(DtiTemperatures::TIMEOUT_MS));
        let t0 = Instant::now();
        assert_eq!(can.freshness(index, t0), Freshness::NoData);
        can.take(&frame(DtiTemperatures::META), t0);
        assert_eq!(can.freshness(index, t0 + limit), Freshness::Fresh);
        let late = limit + Duration::from_millis(1);
        assert_eq!(can.freshness(index, t0 + late), Freshness::Stale(late));
    }
}
