//! The pit's history (`aer_host::link::pit_history`): every batch the stream published stays in a
//! bounded ring of the compressed messages, and a pit that missed some asks for them by
//! number. The answer is the very messages it missed, oldest first, on its own reply topic,
//! then a done note; it goes out paced at the configured rate and only while the broker's
//! queue has room, so the live stream keeps its place. Ingest and the store never wait on it
//! (the ring is filled by the stream's task). One request is served at a time, a few more
//! wait, the rest are refused with the reason: a slow or hostile asker cannot starve anything.

use crate::sink::mqtt::Publisher;
use aer_host::link::pit_history::{Answer, Request, reply_topic};
use aer_host::reports::counters::{Counters, worth_logging};
use std::collections::VecDeque;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::sync::mpsc::Receiver;
use tokio::time::Instant;
use tokio_util::sync::CancellationToken;
use tracing::{info, warn};

/// Requests that may wait while one is served.
pub const WAITING: usize = 4;

/// One published batch.
struct Held {
    number: u32,
    last_us: u64,
    message: Arc<[u8]>,
}

/// The stream's published batches, newest last, within a byte budget.
pub struct Ring {
    held: VecDeque<Held>,
    bytes: usize,
    capacity: usize,
}

/// What a request selects.
pub struct Selection {
    pub messages: Vec<Arc<[u8]>>,
    pub not_held: u32,
    pub oldest_held: Option<u32>,
}

impl Ring {
    /// A ring keeping at most `capacity` bytes of messages (0: none, history off).
    pub fn new(capacity: usize) -> Self {
        Self {
            held: VecDeque::new(),
            bytes: 0,
            capacity,
        }
    }

    /// Keeps batch `number` (its newest record at `last_us`), forgetting the oldest beyond
    /// the budget. Numbers follow each other; one that does not (numbering wrapped) starts
    /// the ring anew, so the ring stays a run of consecutive numbers.
    pub fn push(&mut self, number: u32, last_us: u64, message: Arc<[u8]>) {
        if message.len() > self.capacity {
            return;
        }
        if self
            .held
            .back()
            .is_some_and(|newest| newest.number.wrapping_add(1) != number)
        {
            self.held.clear();
            self.bytes = 0;
        }
        self.bytes += message.len();
        self.held.push_back(Held {
            number,
            last_us,
            message,
        });
        while self.bytes > self.capacity {
            match self.held.pop_front() {
                Some(oldest) => self.bytes -= oldest.message.len(),
                None => break,
            }
        }
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        self.bytes
    }

    /// The batches of `request`'s range that it holds, oldest first.
    pub fn select(&self, request: &Request) -> Selection {
        let oldest_held = self.held.front().map(|held| held.number);
        let wanted = u64::from(request.to) - u64::from(request.from);
        let (mut messages, mut in_range) = (Vec::new(), 0u64);
        if let Some(oldest) = oldest_held {
            // Consecutive numbers: the range maps onto indices without a search.
            let start = request.from.saturating_sub(oldest) as usize;
            let end = request.to.saturating_sub(oldest) as usize;
            for held in self
                .held
                .range(start.min(self.held.len())..end.min(self.held.len()))
            {
                in_range += 1;
                if held.last_us >= request.since_us {
                    messages.push(held.message.clone());
                }
            }
        }
        Selection {
            messages,
            not_held: u32::try_from(wanted - in_range).unwrap_or(u32::MAX),
            oldest_held,
        }
    }
}

/// How the history is served.
#[derive(Debug, Clone)]
pub struct Settings {
    /// The car's topic prefix (`aer/car1`).
    pub car_prefix: String,
    /// The pace of answers (bytes per second on the broker).
    pub bytes_per_s: u64,
    /// The gate's clients (embedded broker): a requester whose link is full (what the gate
    /// holds for it over [`REQUESTER_ROOM`]) gets no more history until it drains, so history
    /// only takes what its radio has spare and the gate never drops it as stale live data.
    pub clients: Option<Arc<crate::broker::gate::Clients>>,
}

/// What the gate may hold for a requester before its history waits (bytes): a few batches.
pub const REQUESTER_ROOM: u64 = 8 * 1024;

/// Serves the requests arriving on `requests` from `ring` until `cancel` fires or the intake
/// ends.
pub async fn serve(
    publisher: Publisher,
    ring: Arc<Mutex<Ring>>,
    counters: Arc<Counters>,
    settings: Settings,
    mut requests: Receiver<Vec<u8>>,
    cancel: CancellationToken,
) {
    let mut waiting: VecDeque<Request> = VecDeque::new();
    loop {
        let request = match waiting.pop_front() {
            Some(request) => request,
            None => tokio::select! {
                () = cancel.cancelled() => return,
                payload = requests.recv() => match payload {
                    Some(payload) => match admit(&payload, &counters) {
                        Some(request) => request,
                        None => continue,
                    },
                    None => return,
                },
            },
        };
        let selection = match ring.lock() {
            Ok(ring) => ring.select(&request),
            Err(_) => return,
        };
        info!(
            reply = %request.reply,
            from = request.from,
            to = request.to,
            batches = selection.messages.len(),
            "sending a pit the batches it missed"
        );
        let topic = reply_topic(&settings.car_prefix, &request.reply);
        let mut next_at = Instant::now();
        let mut sent = 0u32;
        for message in &selection.messages {
            // Paced, and only into a broker queue with room: the live stream goes first.
            loop {
                let wait = tokio::time::sleep_until(next_at);
                tokio::select! {
                    () = cancel.cancelled() => return,
                    () = wait => {
                        // A pit's dashboard names its answers after its client id.
                        let requester_full = settings.clients.as_ref().is_some_and(|clients| {
                            clients
                                .queued_for(&request.reply)
                                .is_some_and(|queued| queued > REQUESTER_ROOM)
                        });
                        if publisher.has_room() && !requester_full {
                            break;
                        }
                        next_at = Instant::now() + Duration::from_millis(10);
                    }
                    payload = requests.recv(), if waiting.len() <= WAITING => match payload {
                        Some(payload) => {
                            if let Some(request) = admit(&payload, &counters) {
                                if waiting.len() < WAITING {
                                    waiting.push_back(request);
                                } else {
                                    refuse(&publisher, &settings, &request, &counters);
                                }
                            }
                        }
                        None => return,
                    },
                }
            }
            publisher.publish_bytes(&topic, message.to_vec());
            Counters::bump(&counters.history_batches);
            sent += 1;
            let cost =
                Duration::from_secs_f64(message.len() as f64 / settings.bytes_per_s.max(1) as f64);
            next_at = Instant::now() + cost;
        }
        let answer = Answer {
            sent,
            not_held: selection.not_held,
            oldest_held: selection.oldest_held,
            refused: None,
        };
        // On the reply topic itself, after the batches: one topic keeps the order.
        publisher.publish_bytes(&topic, answer.to_json());
    }
}

/// Reads a request, counting it; a malformed one is refused (without an answer: its reply
/// topic is not known).
fn admit(payload: &[u8], counters: &Counters) -> Option<Request> {
    Counters::bump(&counters.history_requests);
    match Request::parse(payload) {
        Ok(request) => Some(request),
        Err(error) => {
            let count = Counters::bump(&counters.history_refused);
            if worth_logging(count) {
                warn!(%error, count, "history request refused");
            }
            None
        }
    }
}

fn refuse(publisher: &Publisher, settings: &Settings, request: &Request, counters: &Counters) {
    let count = Counters::bump(&counters.history_refused);
    if worth_logging(count) {
        warn!(reply = %request.reply, count, "history request refused: too many waiting");
    }
    let answer = Answer::refused(format!(
        "{WAITING} requests are waiting already: ask again once yours are answered"
    ));
    publisher.publish_bytes(
        &reply_topic(&settings.car_prefix, &request.reply),
        answer.to_json(),
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ring_of(numbers: std::ops::Range<u32>, capacity: usize) -> Ring {
        let mut ring = Ring::new(capacity);
        for number in numbers {
            ring.push(
                number,
                u64::from(number) * 100_000,
                Arc::from(vec![0u8; 10]),
            );
        }
        ring
    }

    fn request(from: u32, to: u32, since_us: u64) -> Request {
        Request {
            reply: "pit".into(),
            from,
            to,
            since_us,
        }
    }

    #[test]
    fn the_ring_keeps_the_newest_within_its_budget() {
        let ring = ring_of(0..100, 250);
        assert_eq!(ring.bytes(), 250);
        let selection = ring.select(&request(0, 100, 0));
        assert_eq!(selection.oldest_held, Some(75));
        assert_eq!(selection.messages.len(), 25);
        assert_eq!(selection.not_held, 75);
    }

    #[test]
    fn a_range_selects_exactly_its_batches() {
        let ring = ring_of(10..20, 1_000);
        let selection = ring.select(&request(12, 15, 0));
        assert_eq!((selection.messages.len(), selection.not_held), (3, 0));
        // Partly before the ring, partly after what was published.
        let selection = ring.select(&request(5, 25, 0));
        assert_eq!((selection.messages.len(), selection.not_held), (10, 10));
        // A hostile range costs what the ring holds, no more.
        let selection = ring.select(&request(0, u32::MAX, 0));
        assert_eq!(selection.messages.len(), 10);
        assert_eq!(selection.not_held, u32::MAX - 10);
        // Since the session's start: batches that ended before it are left out.
        let selection = ring.select(&request(0, 20, 1_500_000));
        assert_eq!(selection.messages.len(), 5);
    }

    #[test]
    fn numbering_that_restarts_starts_the_ring_anew() {
        let mut ring = ring_of(10..20, 1_000);
        ring.push(0, 0, Arc::from(vec![0u8; 10]));
        assert_eq!(ring.select(&request(0, 30, 0)).oldest_held, Some(0));
        assert_eq!(ring.bytes(), 10);
        let mut off = Ring::new(0);
        off.push(0, 0, Arc::from(vec![0u8; 10]));
        assert_eq!(off.select(&request(0, 1, 0)).oldest_held, None);
    }
}
