//! Counters every stage updates; the metrics topic, the status topic and the live console
//! read them. Lock-free, so any thread can count.

use serde::Serialize;
use std::sync::atomic::{AtomicU64, Ordering};

/// Everything counted since start-up.
#[derive(Debug, Default)]
pub struct Counters {
    /// CAN frames taken from a source.
    pub frames: AtomicU64,
    /// Log lines that were not frames (truncated, garbage).
    pub bad_lines: AtomicU64,
    /// Telemetry packets decoded.
    pub packets: AtomicU64,
    /// DBC messages decoded.
    pub messages: AtomicU64,
    /// ISO-TP errors: lost/repeated consecutive frames, timeouts, malformed frames,
    /// interrupted messages.
    pub isotp_errors: AtomicU64,
    /// Packets whose fingerprint is not this build's (firmware and Pi disagree).
    pub fingerprint_mismatches: AtomicU64,
    /// Packets of the wrong length.
    pub packet_errors: AtomicU64,
    /// Frames of known ids that failed to decode.
    pub decode_errors: AtomicU64,
    /// Frames whose id the schema does not know.
    pub unknown_ids: AtomicU64,
    /// MQTT messages handed to the client.
    pub published: AtomicU64,
    /// MQTT messages dropped because the client's queue was full.
    pub publish_dropped: AtomicU64,
    /// Rows committed to the local store.
    pub stored: AtomicU64,
    /// Rows forwarded to TDengine.
    pub forwarded: AtomicU64,
    /// TDengine write failures (retried).
    pub forward_errors: AtomicU64,
    /// Receive time of the last telemetry packet (us since the epoch, 0 = none yet).
    pub last_packet_us: AtomicU64,
    /// Telemetry fingerprint the firmware sent last (0 = none yet).
    pub firmware_fingerprint: AtomicU64,
}

/// A point-in-time copy, as published on the metrics topic.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub struct Snapshot {
    pub frames: u64,
    pub bad_lines: u64,
    pub packets: u64,
    pub messages: u64,
    pub isotp_errors: u64,
    pub fingerprint_mismatches: u64,
    pub packet_errors: u64,
    pub decode_errors: u64,
    pub unknown_ids: u64,
    pub published: u64,
    pub publish_dropped: u64,
    pub stored: u64,
    pub forwarded: u64,
    pub forward_errors: u64,
}

impl Counters {
    /// Adds one to `counter`.
    pub fn bump(counter: &AtomicU64) -> u64 {
        counter.fetch_add(1, Ordering::Relaxed) + 1
    }

    /// Reads every counter.
    pub fn snapshot(&self) -> Snapshot {
        let get = |c: &AtomicU64| c.load(Ordering::Relaxed);
        Snapshot {
            frames: get(&self.frames),
            bad_lines: get(&self.bad_lines),
            packets: get(&self.packets),
            messages: get(&self.messages),
            isotp_errors: get(&self.isotp_errors),
            fingerprint_mismatches: get(&self.fingerprint_mismatches),
            packet_errors: get(&self.packet_errors),
            decode_errors: get(&self.decode_errors),
            unknown_ids: get(&self.unknown_ids),
            published: get(&self.published),
            publish_dropped: get(&self.publish_dropped),
            stored: get(&self.stored),
            forwarded: get(&self.forwarded),
            forward_errors: get(&self.forward_errors),
        }
    }
}

/// True for the counts worth a log line (1, 2, 4, 8, ...): every kind of fault is logged the
/// first time and then ever more rarely, so a flood cannot drown the log.
pub fn worth_logging(count: u64) -> bool {
    count.is_power_of_two()
}
