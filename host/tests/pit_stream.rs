//! The pit stream's batches: every frame and packet comes back exactly, damaged input is a
//! typed error and never a panic, and the bundled session fits the pit radio's budget (beside
//! what the JSON topics take for the same data).

use aer::mqtt::{TelemetryRecord, encode_message};
use aer_host::clock::seconds;
use aer_host::decode::{Ingest, Record};
use aer_host::formats::candump::{LoggedFrame, parse_line};
use aer_host::formats::pit_stream::{
    BatchEncoder, HEADER_LEN, Item, MAX_PACKET, StreamError, decode,
};
use aer_host::reports::counters::Counters;
use embedded_can::{ExtendedId, Id, StandardId};
use proptest::prelude::*;
use std::sync::Arc;

const SESSION: &str = include_str!("../../raspi/data/session.log");
/// The radio the pit link must fit (kbit/s): issue "the pit link".
const RADIO_KBIT_S: f64 = 250.0;
/// MQTT's fixed header and topic length field, per message.
const MQTT_OVERHEAD: usize = 4;

fn session_frames() -> (Vec<Arc<str>>, Vec<LoggedFrame>) {
    let mut buses: Vec<Arc<str>> = Vec::new();
    let frames = SESSION
        .lines()
        .filter_map(|line| {
            parse_line(line, |name| {
                let index = buses.iter().position(|b| &**b == name).unwrap_or_else(|| {
                    buses.push(Arc::from(name));
                    buses.len() - 1
                });
                index as u8
            })
            .ok()
        })
        .collect();
    (buses, frames)
}

/// The session cut into batches of `window_us`, as the Pi publishes them.
fn batches(window_us: u64) -> Vec<Vec<u8>> {
    let (buses, frames) = session_frames();
    let mut out = Vec::new();
    let mut current: Option<BatchEncoder> = None;
    for frame in &frames {
        if current
            .as_ref()
            .is_some_and(|b| frame.ts_us >= b.first_us() + window_us)
        {
            out.extend(current.take().map(BatchEncoder::finish));
        }
        let number = out.len() as u32;
        current
            .get_or_insert_with(|| BatchEncoder::new(number, frame.ts_us, &buses))
            .frame(frame);
    }
    out.extend(current.map(BatchEncoder::finish));
    out
}

#[test]
fn the_bundled_session_fits_the_pit_radio_and_the_json_topics_do_not() {
    let (buses, frames) = session_frames();
    let first = frames.first().expect("frames").ts_us;
    let seconds_long = (frames.last().expect("frames").ts_us - first) as f64 / 1e6;
    let topic = |suffix: &str| format!("aer/car1/{suffix}").len();

    // Today's JSON: a message per telemetry packet and per CAN frame, as the Pi publishes.
    let mut json_bytes = 0usize;
    let mut ingest = Ingest::new(Arc::new(Counters::default()));
    for frame in &frames {
        ingest.on_frame(
            frame,
            |record| {
                json_bytes += MQTT_OVERHEAD
                    + match record {
                        Record::Telemetry {
                            ts_us,
                            header,
                            telemetry,
                            ..
                        } => {
                            let record = TelemetryRecord {
                                header,
                                telemetry: *telemetry,
                            };
                            topic("telemetry") + record.to_json(seconds(ts_us)).len()
                        }
                        Record::Can {
                            ts_us,
                            bus,
                            message,
                            ..
                        } => {
                            let bus = buses.get(usize::from(bus)).map_or("can0", |b| b);
                            let (suffix, payload) = encode_message(&message, seconds(ts_us), bus);
                            topic(suffix) + payload.len()
                        }
                    }
            },
            |_, _| {},
        );
    }
    let json_kbit_s = json_bytes as f64 * 8.0 / seconds_long / 1000.0;
    eprintln!(
        "JSON topics: {json_bytes} bytes, {json_kbit_s:.0} kbit/s for {} frames in {seconds_long:.1} s",
        frames.len()
    );
    for window_ms in [50, 100, 250] {
        let messages = batches(window_ms * 1000);
        let bytes: usize = messages
            .iter()
            .map(|m| m.len() + MQTT_OVERHEAD + topic("stream"))
            .sum();
        let kbit_s = bytes as f64 * 8.0 / seconds_long / 1000.0;
        eprintln!(
            "compact stream, {window_ms} ms batches: {} messages, {bytes} bytes, {:.2} bytes/frame, {kbit_s:.1} kbit/s ({:.0}x less)",
            messages.len(),
            bytes as f64 / frames.len() as f64,
            json_kbit_s / kbit_s
        );
        assert!(
            kbit_s < RADIO_KBIT_S / 2.0,
            "{window_ms} ms: {kbit_s:.1} kbit/s leaves no room on a {RADIO_KBIT_S} kbit/s radio"
        );
    }
    assert!(
        json_kbit_s > RADIO_KBIT_S,
        "the JSON topics: {json_kbit_s:.0} kbit/s"
    );
}

#[test]
fn the_bundled_session_comes_back_frame_for_frame() {
    let (buses, frames) = session_frames();
    let mut read = Vec::new();
    for (number, message) in batches(100_000).iter().enumerate() {
        let batch = decode(message).expect("a batch");
        assert_eq!(batch.number, number as u32);
        assert_eq!(batch.buses, buses);
        read.extend(batch.items);
    }
    let written: Vec<Item> = frames.into_iter().map(Item::Frame).collect();
    assert_eq!(read, written);
}

fn frame_strategy() -> impl Strategy<Value = Item> {
    let frame = (
        0u64..1 << 40,
        0u8..3,
        any::<bool>(),
        any::<u32>(),
        proptest::collection::vec(any::<u8>(), 0..=8),
    )
        .prop_map(|(ts_us, bus, extended, raw, data)| {
            let id = if extended {
                Id::Extended(ExtendedId::new(raw & 0x1FFF_FFFF).expect("29 bits"))
            } else {
                Id::Standard(StandardId::new((raw & 0x7FF) as u16).expect("11 bits"))
            };
            Item::Frame(LoggedFrame::new(ts_us, bus, id, &data).expect("8 bytes at most"))
        });
    let packet = (
        0u64..1 << 40,
        0u8..3,
        proptest::collection::vec(any::<u8>(), 0..200),
    )
        .prop_map(|(ts_us, bus, packet)| Item::Packet { ts_us, bus, packet });
    prop_oneof![4 => frame, 1 => packet]
}

proptest! {
    /// Any frames and packets, in any order of time, come back exactly.
    #[test]
    fn any_items_come_back_exactly(
        number in any::<u32>(),
        items in proptest::collection::vec(frame_strategy(), 0..200),
    ) {
        let buses: Vec<Arc<str>> = vec!["can0".into(), "can1".into(), "vcan9".into()];
        let first = items.first().map_or(0, Item::ts_us);
        let mut encoder = BatchEncoder::new(number, first, &buses);
        for item in &items {
            match item {
                Item::Frame(frame) => encoder.frame(frame),
                Item::Packet { ts_us, bus, packet } => encoder.packet(*ts_us, *bus, packet),
            }
        }
        let batch = decode(&encoder.finish()).expect("a batch");
        prop_assert_eq!(batch.number, number);
        prop_assert_eq!(batch.buses, buses);
        prop_assert_eq!(batch.items, items);
    }

    /// Any bytes after a valid header, and any damage to a valid batch: a typed error or a
    /// batch, never a panic.
    #[test]
    fn damaged_batches_are_errors_not_panics(
        tail in proptest::collection::vec(any::<u8>(), 0..300),
        items in proptest::collection::vec(frame_strategy(), 1..50),
        at in any::<usize>(),
        flip in 1u8..,
    ) {
        let mut message = b"AERP\\x01".to_vec();
        message.extend_from_slice(&tail);
        let _ = decode(&message);
        let mut encoder = BatchEncoder::new(0, 0, &["can0".into()]);
        for item in &items {
            if let Item::Frame(frame) = item {
                encoder.frame(frame);
            }
        }
        let mut message = encoder.finish();
        let at = at % message.len();
        message[at] ^= flip;
        let _ = decode(&message);
    }
}

#[test]
fn what_is_not_a_batch_says_so() {
    assert_eq!(decode(b"{\"ts\":1}"), Err(StreamError::NotABatch));
    assert_eq!(decode(b"AERP\x07"), Err(StreamError::Version(7)));
    let mut message = BatchEncoder::new(0, 0, &[]).finish();
    message.truncate(HEADER_LEN);
    assert!(matches!(
        decode(&message),
        Err(StreamError::Compression(_) | StreamError::Length { .. })
    ));
    // A packet longer than ISO-TP allows is cut, as no receiver would take it whole.
    let mut encoder = BatchEncoder::new(0, 0, &[]);
    encoder.packet(0, 0, &vec![7; MAX_PACKET + 10]);
    let batch = decode(&encoder.finish()).expect("a batch");
    assert!(matches!(&batch.items[0], Item::Packet { packet, .. } if packet.len() == MAX_PACKET));
}
