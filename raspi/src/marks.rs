//! The dashboards' lap marks (`aer-pit/<car>/marks`), checked and stored as `mark` events of
//! the running session, where the run report times laps with them.

use crate::store::NoteSender;
use crate::store::events::{Event, Kind};
use aer_host::link::marks::Mark;
use aer_host::reports::counters::{Counters, worth_logging};
use std::sync::Arc;
use tokio::sync::mpsc::Receiver;
use tokio_util::sync::CancellationToken;
use tracing::{info, warn};

/// The closest two marks may come: closer ones are refused (counted), so a hostile or
/// stuck client cannot fill the session's record.
pub const MIN_GAP: std::time::Duration = std::time::Duration::from_millis(500);

/// Stores each mark that arrives until `cancel`; a payload that is no mark is counted
/// (`marks_refused`) and logged.
pub async fn run(
    mut marks: Receiver<Vec<u8>>,
    store: NoteSender,
    counters: Arc<Counters>,
    cancel: CancellationToken,
) {
    let mut throttle = Throttle::default();
    loop {
        let payload = tokio::select! {
            received = marks.recv() => match received {
                Some(payload) => payload,
                None => return,
            },
            () = cancel.cancelled() => return,
        };
        match Mark::parse(&payload) {
            // A client on the broker that floods marks fills no store: a lap is seconds long.
            Ok(_) if !throttle.admit(std::time::Instant::now()) => {
                let count = Counters::bump(&counters.marks_refused);
                if worth_logging(count) {
                    warn!(
                        count,
                        "lap marks closer than {} ms: refused",
                        MIN_GAP.as_millis()
                    );
                }
            }
            Ok(mark) => {
                info!(by = %mark.by, ts = mark.ts, "lap mark");
                store.send(event(&mark));
            }
            Err(error) => {
                let count = Counters::bump(&counters.marks_refused);
                if worth_logging(count) {
                    warn!(%error, count, "a lap mark refused");
                }
            }
        }
    }
}

/// At most one mark per [`MIN_GAP`].
#[derive(Debug, Default)]
pub struct Throttle {
    last: Option<std::time::Instant>,
}

impl Throttle {
    /// Whether a mark arriving at `now` is taken (and, if so, counts as the last).
    pub fn admit(&mut self, now: std::time::Instant) -> bool {
        let taken = self
            .last
            .is_none_or(|last| now.saturating_duration_since(last) >= MIN_GAP);
        if taken {
            self.last = Some(now);
        }
        taken
    }
}

/// The event a mark is stored as.
pub fn event(mark: &Mark) -> Event {
    Event {
        at_us: mark.at_us(),
        kind: Kind::Mark,
        name: mark.by.clone(),
        text: "lap ends".to_owned(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::writer::Note;

    #[test]
    fn marks_closer_than_the_gap_are_refused() {
        let start = std::time::Instant::now();
        let mut throttle = Throttle::default();
        assert!(throttle.admit(start));
        assert!(!throttle.admit(start + MIN_GAP / 2));
        assert!(throttle.admit(start + MIN_GAP));
        assert!(
            !throttle.admit(start + MIN_GAP + MIN_GAP / 2),
            "counted from the last taken"
        );
    }

    #[tokio::test]
    async fn a_mark_is_stored_as_an_event_and_a_bad_one_counted() {
        let counters = Arc::new(Counters::default());
        let (notes, stored) = std::sync::mpsc::sync_channel(16);
        let (payloads, marks) = tokio::sync::mpsc::channel(16);
        let mark = Mark {
            ts: 1_764_000_000.5,
            by: "driver".into(),
        };
        payloads.send(mark.to_payload()).await.expect("send");
        payloads.send(b"not a mark".to_vec()).await.expect("send");
        drop(payloads);
        run(
            marks,
            NoteSender::new(notes, counters.clone()),
            counters.clone(),
            CancellationToken::new(),
        )
        .await;
        let stored: Vec<Note> = stored.try_iter().collect();
        assert_eq!(stored, vec![Note::Event(event(&mark))]);
        let Note::Event(e) = &stored[0] else {
            unreachable!()
        };
        assert_eq!(
            (e.kind, e.at_us, e.name.as_str()),
            (Kind::Mark, 1_764_000_000_500_000, "driver")
        );
        assert_eq!(counters.snapshot().marks_refused, 1);
    }
}
