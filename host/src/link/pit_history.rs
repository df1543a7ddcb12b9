//! What a pit that missed part of the stream asks the Pi for, and how the Pi answers: the
//! stream's own batches, by number, sent again on a topic of the asker's, marked as history
//! by that topic, in order, paced below the live stream. The Pi keeps what it published for
//! this (a bounded memory ring of the compressed batches), so the answer is exactly what the
//! pit would have received, and the pit checks each batch's number against what it asked.
//!
//! ```text
//! aer-pit/<car>/history/request    the pit -> the Pi: a Request (JSON)
//! aer-pit/<car>/history/<reply>    the Pi -> the pit: the batches, oldest first, then an
//!                                  Answer (JSON): one topic keeps them in order
//! ```

use serde::{Deserialize, Serialize};
use thiserror::Error;

/// The largest request payload the Pi reads.
pub const MAX_REQUEST: usize = 512;
/// The longest reply name.
pub const MAX_REPLY: usize = 40;

/// The history topics' root for the car below `car_prefix` (`aer/car1` ->
/// `aer-pit/car1/history`).
pub fn root(car_prefix: &str) -> String {
    format!(
        "{}/history",
        crate::formats::pit_stream::pit_root(car_prefix)
    )
}

/// Where a pit publishes its requests.
pub fn request_topic(car_prefix: &str) -> String {
    format!("{}/request", root(car_prefix))
}

/// Where the Pi answers `reply`: the batches, then the [`Answer`].
pub fn reply_topic(car_prefix: &str, reply: &str) -> String {
    format!("{}/{reply}", root(car_prefix))
}

/// A pit's request: the batches numbered `from` up to (not including) `to`, of those the Pi
/// still holds. `since_us` leaves out batches that end before it (a pit that joins
/// mid-session asks from batch 0, since the session's start).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Request {
    /// The asker's name for the answer: letters, digits, `-` and `_`, at most
    /// [`MAX_REPLY`]; the answer's topics end with it.
    pub reply: String,
    pub from: u32,
    pub to: u32,
    #[serde(default)]
    pub since_us: u64,
}

/// Why a request is not answered.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum RequestError {
    #[error("a history request is at most {MAX_REQUEST} bytes of JSON")]
    TooLong,
    #[error("not a history request: {0}")]
    Malformed(String),
    #[error("the reply name is 1-{MAX_REPLY} letters, digits, '-' or '_'")]
    BadReply,
    #[error("the range is empty (from {from} to {to})")]
    Empty { from: u32, to: u32 },
}

impl Request {
    /// Reads and checks a request's payload.
    pub fn parse(payload: &[u8]) -> Result<Self, RequestError> {
        if payload.len() > MAX_REQUEST {
            return Err(RequestError::TooLong);
        }
        let request: Self = serde_json::from_slice(payload)
            .map_err(|error| RequestError::Malformed(error.to_string()))?;
        let reply_ok = !request.reply.is_empty()
            && request.reply.len() <= MAX_REPLY
            && request
                .reply
                .bytes()
                .all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_');
        if !reply_ok {
            return Err(RequestError::BadReply);
        }
        if request.to <= request.from {
            return Err(RequestError::Empty {
                from: request.from,
                to: request.to,
            });
        }
        Ok(request)
    }

    /// The payload to publish.
    pub fn to_json(&self) -> Vec<u8> {
        serde_json::to_vec(self).unwrap_or_default()
    }
}

/// The Pi's last word on a request, after its batches (a payload starting with `{`; a
/// batch starts with `AERP`).
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Answer {
    /// Batches sent, oldest first, on the reply topic.
    pub sent: u32,
    /// Batches of the range the Pi no longer holds (older than its ring, or never published).
    pub not_held: u32,
    /// The oldest batch the Pi holds now, if any.
    pub oldest_held: Option<u32>,
    /// Why nothing was sent, when nothing was (a refused request).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub refused: Option<String>,
}

impl Answer {
    /// A refusal with its reason.
    pub fn refused(reason: impl Into<String>) -> Self {
        Self {
            refused: Some(reason.into()),
            ..Self::default()
        }
    }

    /// The payload to publish.
    pub fn to_json(&self) -> Vec<u8> {
        serde_json::to_vec(self).unwrap_or_default()
    }

    /// Reads an answer.
    pub fn parse(payload: &[u8]) -> Result<Self, RequestError> {
        serde_json::from_slice(payload).map_err(|error| RequestError::Malformed(error.to_string()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_history_topics_sit_beside_the_stream() {
        assert_eq!(request_topic("aer/car1"), "aer-pit/car1/history/request");
        assert_eq!(
            reply_topic("aer/car1", "pit-7"),
            "aer-pit/car1/history/pit-7"
        );
    }

    #[test]
    fn a_request_round_trips_and_bad_ones_are_named() {
        let request = Request {
            reply: "pit-1_a".into(),
            from: 10,
            to: 160,
            since_us: 0,
        };
        assert_eq!(Request::parse(&request.to_json()), Ok(request));
        let parse = |text: &str| Request::parse(text.as_bytes());
        assert_eq!(
            parse(r#"{"reply":"a","from":1,"to":2}"#).map(|r| r.since_us),
            Ok(0)
        );
        assert_eq!(
            parse(r#"{"reply":"a/#","from":1,"to":2}"#),
            Err(RequestError::BadReply)
        );
        assert_eq!(
            parse(r#"{"reply":"","from":1,"to":2}"#),
            Err(RequestError::BadReply)
        );
        assert_eq!(
            parse(r#"{"reply":"a","from":5,"to":5}"#),
            Err(RequestError::Empty { from: 5, to: 5 })
        );
        assert!(matches!(
            parse(r#"{"reply":"a","from":1,"to":2,"all":true}"#),
            Err(RequestError::Malformed(_))
        ));
        assert!(matches!(parse("garbage"), Err(RequestError::Malformed(_))));
        let long = format!(r#"{{"reply":"{}","from":1,"to":2}}"#, "a".repeat(600));
        assert_eq!(parse(&long), Err(RequestError::TooLong));
    }

    #[test]
    fn an_answer_round_trips() {
        let answer = Answer {
            sent: 3,
            not_held: 1,
            oldest_held: Some(4),
            refused: None,
        };
        assert_eq!(Answer::parse(&answer.to_json()), Ok(answer));
        let refused = Answer::refused("busy");
        assert_eq!(Answer::parse(&refused.to_json()), Ok(refused));
    }
}
