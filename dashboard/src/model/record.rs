//! The session's telemetry in packet-time order, kept so history (what a dropout missed,
//! fetched afterwards) can be merged as if it had arrived live: the plots, the fault history
//! and the lap times are rebuilt from it. History waits beside the record until the next
//! merge, which takes it in one pass (inserting packet by packet into the middle would move
//! the whole record each time). Bounded: beyond [`MAX_PACKETS`] (an hour at 100 Hz) the
//! oldest go.

use aer::telemetry::Telemetry;
use std::collections::VecDeque;

/// Packets kept.
pub const MAX_PACKETS: usize = 360_000;

/// One packet.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Row {
    /// Receive time at the Pi (s since the epoch).
    pub ts: f64,
    pub sequence: u16,
    pub telemetry: Telemetry,
}

impl Row {
    fn same(&self, other: &Row) -> bool {
        self.ts == other.ts && self.sequence == other.sequence
    }
}

/// The packets so far, oldest first.
#[derive(Debug, Clone, Default)]
pub struct SessionRecord {
    rows: VecDeque<Row>,
    /// History (and any live packet older than the newest) not merged yet.
    pending: Vec<Row>,
    /// Lap marks (key `L`) at their packet times, replayed with the rows.
    marks: Vec<f64>,
}

impl SessionRecord {
    /// A packet that arrived live: appended, or merged later if it is older than the newest.
    pub fn live(&mut self, row: Row) {
        match self.rows.back() {
            Some(newest) if newest.same(&row) => {}
            Some(newest) if newest.ts > row.ts => self.pending.push(row),
            _ => {
                self.rows.push_back(row);
                if self.rows.len() > MAX_PACKETS {
                    self.rows.pop_front();
                }
            }
        }
    }

    /// A packet of history, merged at the next [`Self::merge`].
    pub fn history(&mut self, row: Row) {
        self.pending.push(row);
    }

    /// True while history waits to be merged.
    pub fn has_pending(&self) -> bool {
        !self.pending.is_empty()
    }

    /// Merges what waits, in time order, each packet once (history that overlaps what
    /// arrived live is left out). The packets added.
    pub fn merge(&mut self) -> usize {
        if self.pending.is_empty() {
            return 0;
        }
        let mut pending = std::mem::take(&mut self.pending);
        pending.sort_by(|a, b| a.ts.total_cmp(&b.ts));
        let held = std::mem::take(&mut self.rows);
        let before = held.len();
        let mut merged: VecDeque<Row> = VecDeque::with_capacity(before + pending.len());
        let (mut old, mut new) = (held.into_iter().peekable(), pending.into_iter().peekable());
        loop {
            let next = match (old.peek(), new.peek()) {
                (Some(a), Some(b)) if b.ts < a.ts => new.next(),
                (Some(_), _) => old.next(),
                (None, Some(_)) => new.next(),
                (None, None) => break,
            };
            let Some(row) = next else { break };
            // Packets at one time sit together: a duplicate is among them.
            let duplicate = merged
                .iter()
                .rev()
                .take_while(|held| held.ts == row.ts)
                .any(|held| held.same(&row));
            if !duplicate {
                merged.push_back(row);
            }
        }
        while merged.len() > MAX_PACKETS {
            merged.pop_front();
        }
        let added = merged.len().saturating_sub(before);
        self.rows = merged;
        added
    }

    /// Notes a lap mark at `ts`.
    pub fn mark(&mut self, ts: f64) {
        self.marks.push(ts);
    }

    /// The lap marks so far.
    pub fn marks(&self) -> &[f64] {
        &self.marks
    }

    /// Packets merged.
    pub fn len(&self) -> usize {
        self.rows.len()
    }

    /// True before the first packet.
    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// The merged packets, oldest first.
    pub fn rows(&self) -> impl Iterator<Item = &Row> {
        self.rows.iter()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(ts: f64, sequence: u16) -> Row {
        Row {
            ts,
            sequence,
            telemetry: Telemetry::zeroed(),
        }
    }

    #[test]
    fn history_is_merged_in_time_order_once() {
        let mut record = SessionRecord::default();
        record.live(row(1.0, 1));
        record.live(row(4.0, 4));
        record.history(row(3.0, 3));
        record.history(row(2.0, 2));
        record.history(row(4.0, 4));
        record.history(row(2.0, 9));
        assert!(record.has_pending());
        assert_eq!(record.len(), 2, "history waits for the merge");
        assert_eq!(
            record.merge(),
            3,
            "the live packet at 4.0 is not taken twice"
        );
        let order: Vec<u16> = record.rows().map(|r| r.sequence).collect();
        assert_eq!(order, [1, 2, 9, 3, 4]);
        assert_eq!(record.merge(), 0);
        record.live(row(0.5, 0));
        assert_eq!(record.merge(), 1, "a late live packet is merged too");
        assert_eq!(record.rows().next().map(|r| r.sequence), Some(0));
    }
}
