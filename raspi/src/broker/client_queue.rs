//! What the broker sent one client and the client has not taken yet: the client's backlog,
//! measured here (its oldest packet's age is the client's lag).
//!
//! For a network client ([`ClientQueue::newest_first`]) the gate reads the broker without
//! waiting on the client, so the connection behind the gate never backs up, and the backlog
//! is bounded here: a client that cannot keep up is served the newest data, and what it loses
//! is counted (a pit fetches it again from the Pi's history). Only QoS 0 publishes that are
//! not retained are ever dropped: a QoS 1/2 publish is owed an acknowledgement to the broker,
//! and a retained one (the status, the topic schemas) is sent once per subscription.
//!
//! A loopback client ([`ClientQueue::everything`]) loses nothing: the gate stops reading the
//! broker for it while its backlog is over the bound.

use super::packet::PUBLISH;
use std::collections::VecDeque;

/// A packet waiting for its client, and when the gate read it.
struct Waiting {
    at_us: u64,
    packet: Vec<u8>,
    droppable: bool,
}

/// One client's backlog.
pub(crate) struct ClientQueue {
    waiting: VecDeque<Waiting>,
    bytes: usize,
    /// The most it holds; beyond it the oldest droppable packets go (`None`: nothing is
    /// dropped, the caller waits for room).
    max_bytes: Option<usize>,
    /// A droppable packet older than this when its turn comes is dropped (us).
    max_lag_us: u64,
    dropped: u64,
}

/// The backlog is over its bound with nothing it may drop: the client is disconnected.
#[derive(Debug, PartialEq, Eq)]
pub(crate) struct Overflow;

impl ClientQueue {
    /// A network client's: live data older than `max_lag_us`, or beyond `max_bytes`, is dropped.
    pub(crate) fn newest_first(max_bytes: usize, max_lag_us: u64) -> Self {
        Self {
            waiting: VecDeque::new(),
            bytes: 0,
            max_bytes: Some(max_bytes),
            max_lag_us,
            dropped: 0,
        }
    }

    /// A loopback client's: nothing is dropped.
    pub(crate) fn everything() -> Self {
        Self {
            max_bytes: None,
            max_lag_us: u64::MAX,
            ..Self::newest_first(0, 0)
        }
    }

    /// Queues a packet the broker sent at `now_us`, dropping the oldest droppable ones while
    /// the backlog is over its bound; the bytes then held.
    pub(crate) fn push(&mut self, now_us: u64, packet: Vec<u8>) -> Result<usize, Overflow> {
        let droppable = packet
            .first()
            .is_some_and(|first| first >> 4 == PUBLISH && first & 0x07 == 0);
        self.bytes += packet.len();
        self.waiting.push_back(Waiting {
            at_us: now_us,
            packet,
            droppable,
        });
        if let Some(max_bytes) = self.max_bytes {
            while self.bytes > max_bytes {
                let Some(oldest) = self.waiting.iter().position(|w| w.droppable) else {
                    return Err(Overflow);
                };
                self.remove(oldest);
            }
        }
        Ok(self.bytes)
    }

    /// The next packet for the client at `now_us`: droppable packets that waited longer than
    /// the lag bound are dropped on the way.
    pub(crate) fn pop(&mut self, now_us: u64) -> Option<Vec<u8>> {
        while let Some(next) = self.waiting.pop_front() {
            self.bytes -= next.packet.len();
            if next.droppable && now_us.saturating_sub(next.at_us) > self.max_lag_us {
                self.dropped += 1;
                continue;
            }
            return Some(next.packet);
        }
        None
    }

    fn remove(&mut self, index: usize) {
        if let Some(gone) = self.waiting.remove(index) {
            self.bytes -= gone.packet.len();
            self.dropped += 1;
        }
    }

    /// When the oldest waiting packet came (us), if any waits.
    pub(crate) fn oldest_us(&self) -> Option<u64> {
        self.waiting.front().map(|w| w.at_us)
    }

    pub(crate) fn bytes(&self) -> usize {
        self.bytes
    }

    /// Packets dropped since the client connected.
    pub(crate) fn dropped(&self) -> u64 {
        self.dropped
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn publish(qos: u8, retain: bool, len: usize) -> Vec<u8> {
        let mut packet = vec![(PUBLISH << 4) | (qos << 1) | u8::from(retain)];
        packet.resize(len, 0);
        packet
    }

    #[test]
    fn a_client_that_keeps_up_gets_everything_in_order() {
        let mut queue = ClientQueue::newest_first(1000, 2_000_000);
        for i in 0..5u8 {
            let mut packet = publish(0, false, 10);
            packet[1] = i;
            assert_eq!(
                queue.push(u64::from(i), packet),
                Ok(10 * usize::from(i + 1))
            );
        }
        assert_eq!(queue.oldest_us(), Some(0));
        let order: Vec<u8> = std::iter::from_fn(|| queue.pop(10)).map(|p| p[1]).collect();
        assert_eq!(order, [0, 1, 2, 3, 4]);
        assert_eq!(
            (queue.bytes(), queue.dropped(), queue.oldest_us()),
            (0, 0, None)
        );
    }

    #[test]
    fn over_its_size_the_backlog_drops_the_oldest_live_data_and_keeps_what_it_must() {
        let mut queue = ClientQueue::newest_first(100, u64::MAX);
        queue.push(0, publish(0, true, 40)).expect("retained");
        queue.push(1, publish(1, false, 40)).expect("QoS 1");
        queue.push(2, publish(0, false, 40)).expect("live");
        assert_eq!(
            queue.dropped(),
            1,
            "the live publish went, not the retained or QoS 1"
        );
        assert_eq!(queue.bytes(), 80);
        for at in 3..10 {
            queue.push(at, publish(0, false, 10)).expect("live");
        }
        assert!(queue.bytes() <= 100);
        assert_eq!(queue.push(10, publish(1, false, 40)), Err(Overflow));
    }

    #[test]
    fn live_data_older_than_the_lag_bound_is_dropped_when_its_turn_comes() {
        let mut queue = ClientQueue::newest_first(10_000, 1_000_000);
        queue.push(0, publish(0, false, 10)).expect("old live");
        queue.push(0, publish(0, true, 10)).expect("old retained");
        queue
            .push(1_500_000, publish(0, false, 11))
            .expect("new live");
        let kept: Vec<usize> = std::iter::from_fn(|| queue.pop(2_000_000))
            .map(|p| p.len())
            .collect();
        assert_eq!(kept, [10, 11], "the retained publish and the fresh one");
        assert_eq!(queue.dropped(), 1);
    }

    #[test]
    fn a_loopback_clients_queue_drops_nothing_however_old_or_large() {
        let mut queue = ClientQueue::everything();
        for at in 0..100 {
            assert!(queue.push(at, publish(0, false, 1000)).is_ok());
        }
        assert_eq!(queue.bytes(), 100_000, "the caller waits for room instead");
        assert_eq!(std::iter::from_fn(|| queue.pop(u64::MAX)).count(), 100);
        assert_eq!(queue.dropped(), 0);
    }
}
