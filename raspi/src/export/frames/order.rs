//! Frames in receive-time order. The raw log holds them in the order ingest took them, and
//! two buses, read by two sockets, interleave a little out of time order; the bus tools'
//! formats are read as a timeline (MDF's master channel must not go back). A frame is held
//! until one a window newer has come, then written; frames with equal times keep their order.

use crate::export::ExportError;
use aer_host::formats::raw_format::Frame;
use std::cmp::{Ordering, Reverse};
use std::collections::BinaryHeap;

/// How far out of time order frames may come and still be sorted (a frame later than this is
/// written where it comes: lossless, if out of order).
const WINDOW_US: u64 = 1_000_000;

#[derive(Default)]
pub struct TimeOrder {
    held: BinaryHeap<Reverse<Held>>,
    newest_us: u64,
    arrived: u64,
}

struct Held {
    ts_us: u64,
    arrived: u64,
    frame: Frame,
}

impl PartialEq for Held {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}

impl Eq for Held {}

impl PartialOrd for Held {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Held {
    fn cmp(&self, other: &Self) -> Ordering {
        (self.ts_us, self.arrived).cmp(&(other.ts_us, other.arrived))
    }
}

impl TimeOrder {
    /// Takes `frame`; hands `emit` every held frame a window older than the newest.
    pub fn push(
        &mut self,
        frame: &Frame,
        emit: &mut impl FnMut(&Frame) -> Result<(), ExportError>,
    ) -> Result<(), ExportError> {
        let ts_us = frame.frame.ts_us;
        self.newest_us = self.newest_us.max(ts_us);
        self.held.push(Reverse(Held {
            ts_us,
            arrived: self.arrived,
            frame: frame.clone(),
        }));
        self.arrived += 1;
        while let Some(Reverse(oldest)) = self.held.peek() {
            if oldest.ts_us.saturating_add(WINDOW_US) >= self.newest_us {
                break;
            }
            if let Some(Reverse(oldest)) = self.held.pop() {
                emit(&oldest.frame)?;
            }
        }
        Ok(())
    }

    /// Hands `emit` every frame still held, in order.
    pub fn finish(
        mut self,
        emit: &mut impl FnMut(&Frame) -> Result<(), ExportError>,
    ) -> Result<(), ExportError> {
        while let Some(Reverse(held)) = self.held.pop() {
            emit(&held.frame)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use aer_host::formats::candump::LoggedFrame;
    use embedded_can::{Id, StandardId};
    use std::sync::Arc;

    fn frame(ts_us: u64, id: u16) -> Frame {
        let id = Id::Standard(StandardId::new(id).expect("standard"));
        Frame {
            interface: Arc::from("can0"),
            frame: LoggedFrame::new(ts_us, 0, id, &[]).expect("frame"),
        }
    }

    #[test]
    fn frames_come_out_in_time_order_with_ties_in_arrival_order() {
        let arrivals = [
            frame(1_000, 1),
            frame(900, 2),
            frame(1_000, 3),
            frame(2_500_000, 4),
            frame(2_400_000, 5),
            // Later than the window allows: written where it comes, nothing lost.
            frame(100, 6),
        ];
        let mut out = Vec::new();
        let mut emit = |f: &Frame| {
            out.push(match f.frame.id {
                Id::Standard(id) => id.as_raw(),
                Id::Extended(_) => 0,
            });
            Ok(())
        };
        let mut order = TimeOrder::default();
        for f in &arrivals {
            order.push(f, &mut emit).expect("pushed");
        }
        order.finish(&mut emit).expect("finished");
        assert_eq!(out, [2, 1, 3, 6, 5, 4]);
    }
}
