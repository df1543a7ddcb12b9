//! Filling what the pit missed (`aer_host::link::pit_history`): the link notes every live batch's
//! number; a gap in the numbering (a dropout, a radio that lost batches) becomes a request to
//! the Pi for those batches, and a pit that joins mid-session asks for the session so far
//! (up to `[link] join_history_s` back). A gap is asked for with one batch more on each
//! side: a telemetry packet whose ISO-TP frames straddle the gap's edge (user-space ISO-TP,
//! as in replays) is then whole in the history, and what arrives twice is merged once.
//! Requests go one at a time; the answer's
//! batches are checked against the range asked (number and time: a restarted Pi's numbering
//! is not taken for the old one), decoded by a history decoder of their own, and handed on as
//! history. Batches lost on the way back are asked for again; a link that drops mid-answer
//! asks for the rest when it is back.

use crate::model::{BackfillProgress, Update};
use crate::pit_stream::{Received, StreamDecoder};
use aer_host::link::pit_history::{Answer, Request, request_topic};
use std::collections::VecDeque;

/// Tries at one range before it is given up (a Pi that keeps refusing, or keeps losing it).
const ATTEMPTS: u8 = 5;
/// Live batches (about 100 ms each) to wait after a refusal before asking again.
const AFTER_REFUSAL: u32 = 20;
/// Live batches without a word of the answer before the request counts as lost (it went
/// at QoS 0) and is sent again.
const ANSWER_WAIT: u32 = 50;
/// The Pi's metrics (one a second) in a row without a live batch before a tail they show is
/// asked for: over a slow radio a batch may still be on its way when the metrics overtake it.
const QUIET_METRICS: u32 = 3;

/// A run of missing batches.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Gap {
    from: u32,
    to: u32,
    /// Leave out batches that ended before this (a join's horizon; 0 otherwise).
    since_us: u64,
    /// The time the gap starts (after the last batch held before it) and ends (the first
    /// batch held after it).
    start_us: u64,
    end_us: u64,
    /// A join's gap: the Pi's oldest batches are older than anything the pit asked for.
    join: bool,
    attempts: u8,
}

/// The range being answered.
#[derive(Debug, Clone, Copy)]
struct Asking {
    gap: Gap,
    /// The number expected next.
    next: u32,
}

/// The link's side of the history.
pub struct Backfill {
    prefix: String,
    reply: String,
    join_history_us: u64,
    decoder: StreamDecoder,
    todo: VecDeque<Gap>,
    asking: Option<Asking>,
    /// The newest live batch, and when the span the pit follows began.
    newest: Option<Received>,
    span_start_us: Option<u64>,
    /// Live batches seen since the last refusal (asking waits a while after one).
    since_refusal: u32,
    refused: bool,
    /// Live batches since the answer last said anything.
    quiet: u32,
    /// The end of the highest range asked for (what is below it is not asked again).
    asked_to: u32,
    /// The Pi's metrics in a row without a live batch.
    quiet_metrics: u32,
    recovered: u64,
    not_held: u64,
    /// History batches that were not what was asked (a duplicate, another numbering).
    unexpected: u64,
}

impl Backfill {
    /// The history of the car below `prefix`, answered on `reply`'s topic; a pit that joins
    /// asks for up to `join_history_s` before its first batch (0: nothing).
    pub fn new(prefix: &str, reply: &str, join_history_s: u64) -> Self {
        Self {
            prefix: prefix.to_owned(),
            reply: reply.to_owned(),
            join_history_us: join_history_s.saturating_mul(1_000_000),
            decoder: StreamDecoder::new(false),
            todo: VecDeque::new(),
            asking: None,
            newest: None,
            span_start_us: None,
            since_refusal: 0,
            refused: false,
            quiet: 0,
            asked_to: 0,
            quiet_metrics: 0,
            recovered: 0,
            not_held: 0,
            unexpected: 0,
        }
    }

    /// The topic the answers come on (subscribe to it before asking).
    pub fn reply_topic(&self) -> String {
        aer_host::link::pit_history::reply_topic(&self.prefix, &self.reply)
    }

    /// The topic requests go to.
    pub fn request_topic(&self) -> String {
        request_topic(&self.prefix)
    }

    /// A live batch arrived; the request to publish now, if any.
    pub fn live(&mut self, batch: Received) -> Option<Vec<u8>> {
        if self
            .newest
            .is_some_and(|newest| batch.number < newest.number)
        {
            // The Pi restarted (numbering from 0): what was asked of the old numbering is
            // gone with its memory, and the new numbering is asked for afresh.
            self.todo.clear();
            self.asking = None;
            self.asked_to = 0;
        }
        match (self.newest, batch.missed_from) {
            (None, _) => {
                self.span_start_us = Some(batch.first_us);
                if batch.number > 0 && self.join_history_us > 0 {
                    let since_us = batch.first_us.saturating_sub(self.join_history_us);
                    self.todo.push_back(Gap {
                        from: 0,
                        to: batch.number,
                        since_us,
                        start_us: since_us,
                        end_us: batch.first_us,
                        join: true,
                        attempts: 0,
                    });
                }
            }
            (Some(previous), Some(from)) => {
                // What the tail's request (below) asked for already is not asked again.
                let from = from.saturating_sub(1).max(self.asked_to.saturating_sub(1));
                if from < batch.number {
                    self.todo.push_back(Gap {
                        from,
                        to: batch.number.saturating_add(1),
                        since_us: 0,
                        start_us: previous.last_us,
                        end_us: batch.first_us,
                        join: false,
                        attempts: 0,
                    });
                }
            }
            (Some(_), None) => {}
        }
        self.newest = Some(batch);
        self.quiet_metrics = 0;
        self.since_refusal = self.since_refusal.saturating_add(1);
        if self.asking.is_some() {
            self.quiet += 1;
            if self.quiet >= ANSWER_WAIT {
                return self.resume();
            }
        }
        self.ask()
    }

    /// The Pi's metrics (every second) say it has published `published` batches. When no
    /// live batch came for `QUIET_METRICS` (3) of them and the newest held is not the last
    /// published, the tail is missing: a dropout that lasted past the session's end leaves no
    /// later batch to show the gap. `now_us` is the wall clock.
    pub fn published(&mut self, published: u64, now_us: u64) -> Option<Vec<u8>> {
        self.quiet_metrics = self.quiet_metrics.saturating_add(1);
        let newest = self.newest?;
        let published = u32::try_from(published).ok()?;
        let next = newest.number.saturating_add(1).max(self.asked_to);
        if self.quiet_metrics <= QUIET_METRICS || published <= next {
            return None;
        }
        self.todo.push_back(Gap {
            from: next.saturating_sub(1),
            to: published,
            since_us: 0,
            start_us: newest.last_us,
            end_us: now_us.max(newest.last_us),
            join: false,
            attempts: 0,
        });
        // Asked once: what the answer brings is the tail.
        self.asked_to = published;
        self.ask()
    }

    /// The link is back: a range that was being answered is asked for again from where its
    /// answer stopped (the Pi's answer may have been lost with the connection).
    pub fn reconnected(&mut self) -> Option<Vec<u8>> {
        self.resume()
    }

    /// Asks for the rest of the range being answered again.
    fn resume(&mut self) -> Option<Vec<u8>> {
        let asking = self.asking.take()?;
        self.retry(asking.gap, asking.next);
        self.ask()
    }

    /// A message on the reply topic: history batches go into `out` as history; the request
    /// to publish next, if any.
    pub fn history(
        &mut self,
        topic: &str,
        payload: &[u8],
        out: &mut Vec<Update>,
    ) -> Option<Vec<u8>> {
        self.quiet = 0;
        if payload.first() == Some(&b'{') {
            return match Answer::parse(payload) {
                Ok(answer) => self.answered(&answer),
                Err(error) => {
                    out.push(Update::Undecodable {
                        topic: topic.to_owned(),
                        error: error.to_string(),
                    });
                    None
                }
            };
        }
        let mut decoded = Vec::new();
        let received = self.decoder.decode(topic, payload, &mut decoded);
        let Some(asking) = self.asking.as_mut() else {
            self.unexpected += 1;
            return None;
        };
        let Some(batch) = received else {
            // Undecodable: named as such; the range is asked for again at the answer.
            out.extend(decoded);
            return None;
        };
        let expected = batch.number >= asking.next
            && batch.number < asking.gap.to
            && batch.first_us <= asking.gap.end_us;
        if !expected {
            self.unexpected += 1;
            return None;
        }
        if batch.number > asking.next {
            // Lost on the way back: asked for again once this range is answered.
            self.todo.push_back(Gap {
                from: asking.next.saturating_sub(1),
                to: batch.number.saturating_add(1),
                since_us: asking.gap.since_us,
                start_us: asking.gap.start_us,
                end_us: batch.first_us,
                join: false,
                attempts: 0,
            });
        }
        if asking.gap.join && asking.next == asking.gap.from {
            self.span_start_us = Some(batch.first_us.min(self.span_start_us.unwrap_or(u64::MAX)));
        }
        asking.next = batch.number.wrapping_add(1);
        asking.gap.start_us = batch.last_us;
        self.recovered += 1;
        out.extend(decoded.into_iter().filter_map(|update| match update {
            Update::Telemetry(sample) => Some(Update::PastTelemetry(sample)),
            // The CAN view shows each message's newest frame: older ones change nothing.
            Update::Can(_) => None,
            other => Some(other),
        }));
        None
    }

    fn answered(&mut self, answer: &Answer) -> Option<Vec<u8>> {
        let asking = self.asking.take()?;
        if answer.refused.is_some() {
            self.refused = true;
            self.since_refusal = 0;
            self.retry(asking.gap, asking.next);
            return None;
        }
        if !asking.gap.join {
            self.not_held += u64::from(answer.not_held);
        }
        // Sent but not all arrived (lost after the Pi sent them): the rest again.
        let got = asking.next.saturating_sub(asking.gap.from);
        if got < answer.sent && asking.next < asking.gap.to {
            self.retry(asking.gap, asking.next);
        }
        self.ask()
    }

    fn retry(&mut self, mut gap: Gap, from: u32) {
        gap.from = from;
        gap.attempts += 1;
        if gap.attempts < ATTEMPTS {
            self.todo.push_front(gap);
        }
    }

    fn ask(&mut self) -> Option<Vec<u8>> {
        if self.asking.is_some() || (self.refused && self.since_refusal < AFTER_REFUSAL) {
            return None;
        }
        self.refused = false;
        self.quiet = 0;
        let gap = self.todo.pop_front()?;
        self.asked_to = self.asked_to.max(gap.to);
        self.asking = Some(Asking {
            gap,
            next: gap.from,
        });
        Some(
            Request {
                reply: self.reply.clone(),
                from: gap.from,
                to: gap.to,
                since_us: gap.since_us,
            }
            .to_json(),
        )
    }

    /// How far behind the pit is, and how complete its copy of the session.
    pub fn progress(&self) -> BackfillProgress {
        let missing_us: u64 = self
            .asking
            .iter()
            .map(|asking| asking.gap)
            .chain(self.todo.iter().copied())
            .map(|gap| gap.end_us.saturating_sub(gap.start_us))
            .sum();
        let span_us = match (self.span_start_us, self.newest) {
            (Some(start), Some(newest)) => newest.last_us.saturating_sub(start).max(1),
            _ => 1,
        };
        BackfillProgress {
            behind_s: missing_us as f64 / 1e6,
            complete: (1.0 - missing_us as f64 / span_us as f64).clamp(0.0, 1.0),
            catching_up: self.asking.is_some() || !self.todo.is_empty(),
            recovered: self.recovered,
            not_held: self.not_held,
            unexpected: self.unexpected,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn live(number: u32, missed_from: Option<u32>) -> Received {
        Received {
            number,
            first_us: u64::from(number) * 100_000,
            last_us: u64::from(number) * 100_000 + 90_000,
            missed_from,
        }
    }

    fn request(json: Option<Vec<u8>>) -> Request {
        Request::parse(&json.expect("a request")).expect("a valid request")
    }

    #[test]
    fn a_gap_is_asked_for_exactly_and_its_answer_closes_it() {
        let mut backfill = Backfill::new("aer/car1", "pit", 0);
        assert_eq!(backfill.live(live(0, None)), None);
        assert_eq!(backfill.live(live(1, None)), None);
        let asked = request(backfill.live(live(151, Some(2))));
        // One batch more each side: a packet straddling an edge is whole in the history.
        assert_eq!((asked.from, asked.to, asked.since_us), (1, 152, 0));
        let progress = backfill.progress();
        assert!(progress.catching_up);
        assert!((progress.behind_s - 14.91).abs() < 1e-6, "{progress:?}");
        assert_eq!(
            backfill.reply_topic(),
            "aer-pit/car1/history/pit",
            "the answers' topic"
        );
        // A second gap waits for the first answer.
        assert_eq!(backfill.live(live(160, Some(152))), None);
        let done = Answer {
            sent: 0,
            not_held: 149,
            oldest_held: Some(300),
            refused: None,
        };
        let next = request(backfill.history("t", &done.to_json(), &mut Vec::new()));
        assert_eq!((next.from, next.to), (151, 161));
        assert_eq!(backfill.progress().not_held, 149);
    }

    /// A dropout that outlasts the session leaves no later batch: the Pi's published count
    /// (its metrics) shows the missing tail, asked for once the live stream is quiet.
    #[test]
    fn a_missing_tail_is_seen_in_the_pis_metrics() {
        let mut backfill = Backfill::new("aer/car1", "pit", 0);
        backfill.live(live(0, None));
        backfill.live(live(1, None));
        assert_eq!(backfill.published(2, 0), None, "nothing missing");
        for _ in 1..QUIET_METRICS {
            assert_eq!(backfill.published(30, 0), None, "a batch may be on its way");
        }
        let asked = request(backfill.published(30, 3_000_000));
        assert_eq!((asked.from, asked.to), (1, 30));
        // The live batch after it does not ask for the same again.
        assert_eq!(backfill.live(live(31, Some(2))), None);
        let done = Answer {
            not_held: 29,
            ..Answer::default()
        };
        // Only the batches past the tail's range (one more before, for a packet across).
        let next = request(backfill.history("t", &done.to_json(), &mut Vec::new()));
        assert_eq!((next.from, next.to), (29, 32));
    }

    /// A restarted Pi numbers from 0 again: gaps in the new numbering are asked for, not
    /// taken for ranges asked of the old one.
    #[test]
    fn a_restarted_pi_is_asked_afresh() {
        let mut backfill = Backfill::new("aer/car1", "pit", 0);
        backfill.live(live(500, None));
        request(backfill.live(live(600, Some(501))));
        assert_eq!(backfill.live(live(0, None)), None, "a restart, not a gap");
        let asked = request(backfill.live(live(20, Some(1))));
        assert_eq!((asked.from, asked.to), (0, 21));
    }

    #[test]
    fn a_pit_that_joins_asks_for_the_session_so_far() {
        let mut backfill = Backfill::new("aer/car1", "pit", 60);
        let asked = request(backfill.live(live(1_000, None)));
        assert_eq!((asked.from, asked.to), (0, 1_000));
        assert_eq!(asked.since_us, 100_000_000 - 60_000_000);
        // The first batch of a fresh Pi needs no history.
        let mut fresh = Backfill::new("aer/car1", "pit", 60);
        assert_eq!(fresh.live(live(0, None)), None);
    }

    #[test]
    fn a_refusal_waits_then_asks_again_and_a_reconnect_resumes() {
        let mut backfill = Backfill::new("aer/car1", "pit", 0);
        backfill.live(live(0, None));
        request(backfill.live(live(10, Some(1))));
        let refused = Answer::refused("busy");
        assert_eq!(
            backfill.history("t", &refused.to_json(), &mut Vec::new()),
            None
        );
        let mut asked = None;
        for number in 11..11 + AFTER_REFUSAL {
            asked = asked.or(backfill.live(live(number, None)));
        }
        let asked = request(asked);
        assert_eq!((asked.from, asked.to), (0, 11));
        let again = request(backfill.reconnected());
        assert_eq!((again.from, again.to), (0, 11));
    }
}
