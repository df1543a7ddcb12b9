//! Counters every stage updates; the metrics topic, the status topic and the live console
//! read them. Lock-free, so any thread can count.

use aer::mqtt::ServiceCounters;
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

impl Counters {
    /// Adds one to `counter`.
    pub fn bump(counter: &AtomicU64) -> u64 {
        counter.fetch_add(1, Ordering::Relaxed) + 1
    }

    /// Reads every counter, as the metrics topic publishes them.
    pub fn snapshot(&self) -> ServiceCounters {
        let get = |c: &AtomicU64| c.load(Ordering::Relaxed);
        ServiceCounters {
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
