//! Faults and warnings: the schema's alarm flags (flags with thresholds), which are active now,
//! and when each was raised or cleared.

use super::fields::{FieldValue, Schema};
use aer::telemetry::Level;
use std::collections::VecDeque;

/// Entries the fault history keeps (the oldest go first).
pub const HISTORY_LEN: usize = 500;

/// A change of one alarm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AlarmEvent {
    /// Packet time (s since the epoch).
    pub ts: f64,
    /// Field index in the schema.
    pub field: usize,
    pub label: &'static str,
    /// The new level: [`Level::Normal`] when it cleared.
    pub level: Level,
}

/// The alarms' state and history.
#[derive(Debug, Clone)]
pub struct Alarms {
    schema: Schema,
    /// Level of every field (only alarm fields change).
    levels: Vec<Level>,
    history: VecDeque<AlarmEvent>,
    seen_packet: bool,
}

impl Alarms {
    /// No alarm active, no history.
    pub fn new(schema: Schema) -> Self {
        Self {
            schema,
            levels: vec![Level::Normal; schema.fields.len()],
            history: VecDeque::new(),
            seen_packet: false,
        }
    }

    /// Takes one packet's values; records every alarm that was raised or cleared.
    pub fn update(&mut self, ts: f64, values: &[FieldValue]) {
        for field in self.schema.fields().filter(|f| f.is_alarm()) {
            let Some(value) = values.get(field.index) else {
                continue;
            };
            let level = field.level(value.value);
            let Some(slot) = self.levels.get_mut(field.index) else {
                continue;
            };
            // The first packet sets the state; only a raised alarm is history-worthy then.
            if *slot != level && (self.seen_packet || level != Level::Normal) {
                if self.history.len() == HISTORY_LEN {
                    self.history.pop_front();
                }
                self.history.push_back(AlarmEvent {
                    ts,
                    field: field.index,
                    label: field.display.label,
                    level,
                });
            }
            *slot = level;
        }
        self.seen_packet = true;
    }

    /// The alarms active now, critical ones first, then in schema order.
    pub fn active(&self) -> Vec<(&'static str, Level)> {
        let mut active: Vec<(usize, &'static str, Level)> = self
            .schema
            .fields()
            .filter_map(|f| {
                let level = *self.levels.get(f.index)?;
                (level != Level::Normal).then_some((f.index, f.display.label, level))
            })
            .collect();
        active.sort_by(|a, b| b.2.cmp(&a.2).then(a.0.cmp(&b.0)));
        active
            .into_iter()
            .map(|(_, label, level)| (label, level))
            .collect()
    }

    /// Raised and cleared alarms, newest first.
    pub fn history(&self) -> impl Iterator<Item = &AlarmEvent> {
        self.history.iter().rev()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::fields::read;
    use aer::telemetry::Telemetry;

    fn values(telemetry: &Telemetry) -> Vec<FieldValue> {
        let mut values = Vec::new();
        read(telemetry, &mut values);
        values
    }

    #[test]
    fn raising_and_clearing_is_recorded_with_times() {
        let mut alarms = Alarms::new(Schema::TELEMETRY);
        let mut telemetry = Telemetry::zeroed();
        alarms.update(1.0, &values(&telemetry));
        assert!(alarms.active().is_empty());
        assert_eq!(alarms.history().count(), 0);

        telemetry.fault_bse = true;
        telemetry.dc_low_volt_warning = true;
        alarms.update(2.0, &values(&telemetry));
        let active = alarms.active();
        assert_eq!(active.len(), 2);
        assert_eq!(active[0].1, Level::Critical, "critical first: {active:?}");

        telemetry.fault_bse = false;
        alarms.update(3.5, &values(&telemetry));
        let history: Vec<_> = alarms.history().map(|e| (e.ts, e.level)).collect();
        assert_eq!(history.first(), Some(&(3.5, Level::Normal)));
        assert_eq!(history.len(), 3);
        assert_eq!(alarms.active().len(), 1);
    }

    #[test]
    fn the_history_is_bounded() {
        let mut alarms = Alarms::new(Schema::TELEMETRY);
        let mut telemetry = Telemetry::zeroed();
        for i in 0..HISTORY_LEN * 2 {
            telemetry.fault_apps = i % 2 == 0;
            alarms.update(i as f64, &values(&telemetry));
        }
        assert_eq!(alarms.history().count(), HISTORY_LEN);
        assert_eq!(
            alarms.history().next().map(|e| e.ts),
            Some((HISTORY_LEN * 2 - 1) as f64)
        );
    }
}
