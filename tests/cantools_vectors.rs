//! The generated codec for `schema/aer.dbc` against cantools, the reference implementation.
//!
//! `tests/vectors/aer.jsonl` holds frames cantools encoded from random raw values, the physical
//! values cantools decodes from them, and what cantools' strict encoder makes of those values
//! (regenerate with `tools/cantools_vectors.py`). Decoding must match exactly; encoding must be
//! byte-exact, or refuse exactly where cantools refuses. `tests/vectors/session_dti.jsonl` is
//! the same for every distinct DTI frame of the recorded comp-car session
//! (`raspi/data/session.log`; `tools/cantools_vectors.py --candump`).

use std::collections::BTreeMap;

use aer::can::AnyMessage;
use aer::runtime::{SignalMeta, SignalSource, SignalVisitor, Value};
use serde::Deserialize;

#[derive(Deserialize)]
struct Vector {
    name: String,
    id: u32,
    extended: bool,
    data: String,
    signals: BTreeMap<String, serde_json::Number>,
    encoded: Option<String>,
}

fn vectors() -> Vec<Vector> {
    parse(include_str!("vectors/aer.jsonl"))
}

fn parse(text: &str) -> Vec<Vector> {
    text.lines()
        .map(|l| serde_json::from_str(l).expect("vector lines are valid JSON"))
        .collect()
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

fn unhex(text: &str) -> Vec<u8> {
    (0..text.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&text[i..i + 2], 16).expect("hex"))
        .collect()
}

/// A JSON number as the codec's `Value`: integers stay integers.
fn value_of(n: &serde_json::Number) -> Value {
    n.as_i64()
        .map(|i| Value::Int(i.into()))
        .or_else(|| n.as_u64().map(|u| Value::Int(u.into())))
        .unwrap_or_else(|| Value::Float(n.as_f64().expect("finite number")))
}

struct Collect(BTreeMap<String, Value>);

impl SignalVisitor for Collect {
    fn signal(&mut self, signal: &'static SignalMeta, value: Value, _label: Option<&'static str>) {
        self.0.insert(signal.name.to_owned(), value);
    }
}

struct FromVector<'a>(&'a BTreeMap<String, serde_json::Number>);

impl SignalSource for FromVector<'_> {
    fn value(&mut self, signal: &'static SignalMeta) -> Option<Value> {
        self.0.get(signal.name).map(value_of)
    }
}

/// The vectors cover the schema as it is now: every message has vectors, and each vector
/// carries exactly its message's signals. A message or signal added, renamed or removed after
/// the vectors were made fails here with the command that remakes them, instead of passing
/// against vectors that never exercise it.
#[test]
fn the_vectors_are_of_the_schema_as_it_is() {
    const REMAKE: &str = "remake them: .venv/bin/python tools/cantools_vectors.py --frames 100 \
                          --out tests/vectors schema/aer.dbc (docs/schema.md, \"Changing the schema\")";
    let vectors = vectors();
    let mut stale = Vec::new();
    for meta in aer::can::MESSAGES {
        let of_message: Vec<&Vector> = vectors.iter().filter(|v| v.name == meta.name).collect();
        if of_message.is_empty() {
            stale.push(format!("{}: no vectors", meta.name));
            continue;
        }
        let declared: std::collections::BTreeSet<&str> =
            meta.signals.iter().map(|s| s.name).collect();
        for v in of_message {
            let carried: std::collections::BTreeSet<&str> =
                v.signals.keys().map(String::as_str).collect();
            // A multiplexed message's vector carries the signals its multiplexor selects.
            if !carried.is_subset(&declared)
                || (carried.len() < declared.len() && !multiplexed(meta))
            {
                stale.push(format!(
                    "{}: a vector with signals {carried:?}, the schema has {declared:?}",
                    meta.name
                ));
                break;
            }
        }
    }
    let known: std::collections::BTreeSet<&str> =
        aer::can::MESSAGES.iter().map(|m| m.name).collect();
    for v in &vectors {
        if !known.contains(v.name.as_str()) {
            stale.push(format!(
                "{}: vectors of a message the schema no longer has",
                v.name
            ));
            break;
        }
    }
    assert!(
        stale.is_empty(),
        "stale vectors, {REMAKE}:\n{}",
        stale.join("\n")
    );
}

fn multiplexed(meta: &aer::runtime::MessageMeta) -> bool {
    meta.signals.iter().any(|s| s.multiplexed)
}

#[test]
fn decoding_matches_cantools_exactly() {
    let vectors = vectors();
    assert!(vectors.len() >= 1000, "too few vectors: {}", vectors.len());
    decodes_as_cantools_does(&vectors);
}

fn decodes_as_cantools_does(vectors: &[Vector]) {
    for v in vectors {
        let message = AnyMessage::decode(v.id, v.extended, &unhex(&v.data))
            .unwrap_or_else(|e| panic!("{} {}: {e}", v.name, v.data));
        assert_eq!(message.meta().name, v.name);
        let mut got = Collect(BTreeMap::new());
        message.visit(&mut got);
        let want: BTreeMap<String, Value> = v
            .signals
            .iter()
            .map(|(k, n)| (k.clone(), value_of(n)))
            .collect();
        assert_eq!(
            got.0.keys().collect::<Vec<_>>(),
            want.keys().collect::<Vec<_>>(),
            "{} {}",
            v.name,
            v.data
        );
        for (name, w) in &want {
            let g = got.0[name];
            // cantools gives whole numbers as floats when the DBC writes a factor like `1.0`;
            // compare numerically, exactly.
            assert_eq!(g.to_f64(), w.to_f64(), "{}.{name} from {}", v.name, v.data);
        }
    }
}

#[test]
fn encoding_matches_cantools_byte_for_byte() {
    // The vectors include out-of-range values on purpose: both encoders must refuse them.
    assert!(
        encodes_as_cantools_does(&vectors()) > 0,
        "no vector exercised a range refusal"
    );
}

#[test]
fn every_dti_frame_of_the_recorded_comp_car_session_matches_cantools() {
    let vectors = parse(include_str!("vectors/session_dti.jsonl"));
    let messages: std::collections::BTreeSet<&str> =
        vectors.iter().map(|v| v.name.as_str()).collect();
    // Every periodic DTI message of the schema: the CCM's commands and the DTI's status.
    let periodic: std::collections::BTreeSet<&str> = aer::can::MESSAGES
        .iter()
        .filter(|m| m.name.starts_with("DTI_") && m.timeout_ms.is_some())
        .map(|m| m.name)
        .collect();
    assert_eq!(messages, periodic);
    assert!(vectors.len() >= 1000, "too few frames: {}", vectors.len());
    decodes_as_cantools_does(&vectors);
    // Recorded frames are in range: cantools re-encodes every one, and so must we.
    assert_eq!(encodes_as_cantools_does(&vectors), 0);
}

/// Checks every vector's encoding; returns how many both encoders refused.
fn encodes_as_cantools_does(vectors: &[Vector]) -> usize {
    let mut refused = 0;
    for v in vectors {
        let built = AnyMessage::from_signals(v.id, v.extended, &mut FromVector(&v.signals));
        let mut out = [0u8; 64];
        let encoded = built.and_then(|m| m.encode(&mut out).map(|n| hex(&out[..n])));
        match (&v.encoded, encoded) {
            (Some(want), Ok(got)) => assert_eq!(&got, want, "{} {:?}", v.name, v.signals),
            (None, Err(_)) => refused += 1,
            (want, got) => panic!(
                "{} {:?}: cantools {want:?}, ours {got:?}",
                v.name, v.signals
            ),
        }
    }
    refused
}
