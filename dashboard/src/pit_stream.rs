//! Reads the Pi's compact pit stream (`aer_host::formats::pit_stream`) with the same ingest and
//! generated decoders the Pi runs: frames and packets in, the same telemetry and CAN samples
//! the JSON topics would have carried out. Telemetry from firmware of another schema is named,
//! as on the Pi.

use crate::model::Update;
use aer::mqtt::{Sample, TelemetryRecord};
use aer::telemetry::TELEMETRY_FINGERPRINT;
use aer_host::clock::seconds;
use aer_host::decode::{Ingest, Record};
use aer_host::formats::pit_stream::{Item, decode};
use aer_host::reports::counters::Counters;
use std::sync::Arc;
use std::sync::atomic::Ordering;

/// The decoder's state across batches (an ISO-TP transfer may span two).
pub struct StreamDecoder {
    ingest: Ingest,
    counters: Arc<Counters>,
    /// Fingerprint mismatches already reported.
    mismatches: u64,
    /// The batch number expected next (the live stream's: history arrives in ranges).
    next: Option<u32>,
    live: bool,
}

impl Default for StreamDecoder {
    fn default() -> Self {
        Self::new(true)
    }
}

/// A batch as it arrived, for the history's bookkeeping.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Received {
    pub number: u32,
    /// Its first and newest records' times (us since the epoch).
    pub first_us: u64,
    pub last_us: u64,
    /// The first number missing before it, when batches went missing (live only).
    pub missed_from: Option<u32>,
}

fn update(record: Record) -> Update {
    match record {
        Record::Telemetry {
            ts_us,
            header,
            telemetry,
            ..
        } => Update::Telemetry(Box::new(Sample {
            ts: seconds(ts_us),
            value: TelemetryRecord {
                header,
                telemetry: *telemetry,
            },
        })),
        Record::Can { ts_us, message, .. } => Update::Can(Box::new(Sample {
            ts: seconds(ts_us),
            value: message,
        })),
    }
}

impl StreamDecoder {
    /// A decoder for the live stream (`live`: its numbering gaps are reported) or for history.
    pub fn new(live: bool) -> Self {
        let counters = Arc::new(Counters::default());
        Self {
            ingest: Ingest::new(counters.clone()),
            counters,
            mismatches: 0,
            next: None,
            live,
        }
    }

    /// Decodes one batch published on `topic` into `out`, in the order the Pi took it in;
    /// what it was, unless it did not decode.
    pub fn decode(
        &mut self,
        topic: &str,
        payload: &[u8],
        out: &mut Vec<Update>,
    ) -> Option<Received> {
        let batch = match decode(payload) {
            Ok(batch) => batch,
            Err(error) => {
                out.push(Update::Undecodable {
                    topic: topic.to_owned(),
                    error: error.to_string(),
                });
                return None;
            }
        };
        let mut missed_from = None;
        if let Some(expected) = self.next.filter(|_| self.live) {
            let missed = batch.number.wrapping_sub(expected);
            // A number behind the expected one is a restarted Pi (numbering from 0), not a gap.
            if missed != 0 && missed < u32::MAX / 2 {
                out.push(Update::StreamGap(missed));
                missed_from = Some(expected);
                // A transfer cut by the gap must not be completed with another's frames.
                self.ingest = Ingest::new(self.counters.clone());
            }
        }
        self.next = Some(batch.number.wrapping_add(1));
        let first_us = batch.items.first().map_or(0, Item::ts_us);
        let received = Received {
            number: batch.number,
            first_us,
            last_us: batch.items.last().map_or(first_us, Item::ts_us),
            missed_from,
        };
        for (index, name) in batch.buses.iter().enumerate() {
            if let Ok(index) = u8::try_from(index) {
                self.ingest.name_bus(index, name);
            }
        }
        for item in &batch.items {
            match item {
                Item::Frame(frame) => {
                    self.ingest
                        .on_frame(frame, |record| out.push(update(record)), |_, _| {})
                }
                Item::Packet { ts_us, bus, packet } => {
                    self.ingest
                        .on_packet(*ts_us, *bus, packet, |record| out.push(update(record)))
                }
            }
        }
        let mismatches = self.counters.fingerprint_mismatches.load(Ordering::Relaxed);
        if mismatches > self.mismatches {
            self.mismatches = mismatches;
            let found = self.counters.mismatched_fingerprint.load(Ordering::Relaxed);
            out.push(Update::Undecodable {
                topic: topic.to_owned(),
                error: format!(
                    "telemetry from firmware built from another schema ({found:#010x}; this \
                     dashboard reads {TELEMETRY_FINGERPRINT:#010x}): flash the CCM and install \
                     the dashboard from the same commit"
                ),
            });
        }
        Some(received)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use aer::telemetry::{Telemetry, TelemetryHeader};
    use aer_host::formats::pit_stream::BatchEncoder;

    fn packet(sequence: u16) -> [u8; Telemetry::LEN] {
        let mut out = [0u8; Telemetry::LEN];
        let header = TelemetryHeader {
            sequence,
            timestamp_us: 0,
        };
        Telemetry::zeroed().pack(header, &mut out);
        out
    }

    fn batch(packets: &[[u8; Telemetry::LEN]]) -> Vec<u8> {
        numbered(0, packets)
    }

    fn numbered(number: u32, packets: &[[u8; Telemetry::LEN]]) -> Vec<u8> {
        let mut encoder = BatchEncoder::new(number, 1_000_000, &["can0".into()]);
        for (i, packet) in packets.iter().enumerate() {
            encoder.packet(1_000_000 + i as u64 * 10_000, 0, packet);
        }
        encoder.finish()
    }

    #[test]
    fn packets_become_telemetry_samples_in_order() {
        let mut out = Vec::new();
        StreamDecoder::default().decode(
            "aer-pit/car1/stream",
            &batch(&[packet(1), packet(2)]),
            &mut out,
        );
        let sequences: Vec<u16> = out
            .iter()
            .filter_map(|u| match u {
                Update::Telemetry(sample) => Some(sample.value.header.sequence),
                _ => None,
            })
            .collect();
        assert_eq!(sequences, [1, 2]);
        assert!(matches!(&out[0], Update::Telemetry(s) if s.ts == 1.0));
    }

    #[test]
    fn another_schemas_telemetry_is_named_once_per_batch() {
        let mut foreign = packet(1);
        foreign[..4].copy_from_slice(&0x1234_5678u32.to_le_bytes());
        let mut out = Vec::new();
        StreamDecoder::default().decode(
            "aer-pit/car1/stream",
            &batch(&[foreign, foreign]),
            &mut out,
        );
        assert_eq!(out.len(), 1, "{out:?}");
        match &out[0] {
            Update::Undecodable { topic, error } => {
                assert_eq!(topic, "aer-pit/car1/stream");
                assert!(error.contains("0x12345678"), "{error}");
                assert!(
                    error.contains(&format!("{TELEMETRY_FINGERPRINT:#010x}")),
                    "{error}"
                );
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn a_damaged_batch_is_undecodable_with_the_reason() {
        let mut message = batch(&[packet(1)]);
        message.truncate(message.len() - 3);
        let mut out = Vec::new();
        StreamDecoder::default().decode("aer-pit/car1/stream", &message, &mut out);
        assert!(
            matches!(&out[..], [Update::Undecodable { error, .. }] if !error.is_empty()),
            "{out:?}"
        );
    }

    /// Batches that never arrived are reported by count; a Pi that restarts its numbering is
    /// not a gap.
    #[test]
    fn missing_batches_are_counted_and_a_restart_is_not() {
        let mut decoder = StreamDecoder::default();
        let gaps = |decoder: &mut StreamDecoder, number| {
            let mut out = Vec::new();
            decoder.decode("aer-pit/car1/stream", &numbered(number, &[]), &mut out);
            out.into_iter()
                .filter_map(|u| match u {
                    Update::StreamGap(n) => Some(n),
                    _ => None,
                })
                .collect::<Vec<_>>()
        };
        assert_eq!(
            gaps(&mut decoder, 7),
            Vec::<u32>::new(),
            "the first batch seen"
        );
        assert_eq!(gaps(&mut decoder, 8), Vec::<u32>::new());
        assert_eq!(gaps(&mut decoder, 158), [149]);
        assert_eq!(gaps(&mut decoder, 0), Vec::<u32>::new(), "the Pi restarted");
        assert_eq!(gaps(&mut decoder, 3), [2]);
        let mut decoder = StreamDecoder::default();
        assert_eq!(gaps(&mut decoder, u32::MAX), Vec::<u32>::new());
        assert_eq!(gaps(&mut decoder, 0), Vec::<u32>::new(), "numbers wrap");
        assert_eq!(gaps(&mut decoder, 2), [1]);
    }
}
