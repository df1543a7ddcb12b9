//! The ingest service's counters: one list, from which both the live counters (atomic, any
//! thread bumps them) and the published snapshot ([`ServiceCounters`], the metrics payload)
//! are made, so the two cannot drift apart.

use serde::{Deserialize, Serialize};
use std::sync::atomic::{AtomicU64, Ordering};

macro_rules! counters {
    ($($(#[doc = $doc:literal])+ $name:ident,)+) => {
        /// Everything the ingest service counted since it started, as published.
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
        pub struct ServiceCounters {
            $($(#[doc = $doc])+ pub $name: u64,)+
        }

        /// The live counters, and the two last-seen values the status reports.
        #[derive(Debug, Default)]
        pub struct Counters {
            $($(#[doc = $doc])+ pub $name: AtomicU64,)+
            /// Receive time of the last telemetry packet (us since the epoch, 0 = none yet).
            pub last_packet_us: AtomicU64,
            /// When a looping replay last started its log again (us since the epoch, 0 =
            /// never), for the loop point's event.
            pub last_replay_pass_us: AtomicU64,
            /// Telemetry fingerprint the firmware sent last (0 = none yet).
            pub firmware_fingerprint: AtomicU64,
            /// The last fingerprint that was not the service's (0 = none yet).
            pub mismatched_fingerprint: AtomicU64,
            /// The same integrity and lateness counts, per message name (only messages
            /// with any), for the status.
            pub message_health: std::sync::Mutex<std::collections::BTreeMap<String, MessageHealth>>,
            /// Each bus's and each message's traffic since the last status.
            pub traffic: std::sync::Mutex<crate::reports::traffic::Traffic>,
            /// When each message and the telemetry first came, since the service started.
            pub arrivals: std::sync::Mutex<crate::reports::arrivals::Arrivals>,
        }

        impl Counters {
            /// Reads every counter, as the metrics topic publishes them.
            pub fn snapshot(&self) -> ServiceCounters {
                ServiceCounters {
                    $($name: self.$name.load(Ordering::Relaxed),)+
                }
            }
        }
    };
}

counters! {
    /// CAN frames taken from a source.
    frames,
    /// Log lines that were not frames (truncated, garbage).
    bad_lines,
    /// CAN error frames the interfaces reported (bus errors, error passive, bus off).
    can_error_frames,
    /// CAN and ISO-TP sockets reopened after a read failed or their interface went away.
    can_reopened,
    /// Frames (ISO-TP: packets) the kernel dropped because a socket's receive queue was full.
    can_rx_overflows,
    /// Telemetry packets decoded.
    packets,
    /// DBC messages decoded.
    messages,
    /// ISO-TP errors: lost or repeated consecutive frames, timeouts, malformed frames,
    /// interrupted messages.
    isotp_errors,
    /// Packets whose fingerprint is not the service's (firmware and Pi disagree).
    fingerprint_mismatches,
    /// Packets of the wrong length.
    packet_errors,
    /// Frames of known ids that failed to decode.
    decode_errors,
    /// Frames whose id the schema does not know.
    unknown_ids,
    /// Frames whose checksum does not match their payload (the schema's
    /// `ChecksumAlgorithm`); kept and published, only counted.
    checksum_failures,
    /// Frames whose rolling counter repeated the previous frame's (a stuck sender).
    counter_repeats,
    /// Frames whose rolling counter skipped (frames lost on the way, or a restarted sender).
    counter_jumps,
    /// Frames that came later than their message's freshness limit after the previous one
    /// (`TIMEOUT_MS`): a gap in which receivers counted the message lost.
    late_frames,
    /// MQTT messages handed to the broker.
    published,
    /// MQTT messages dropped because the broker's queue was full.
    publish_dropped,
    /// Batches of the pit stream published (`aer-pit/<car>/stream`).
    pit_batches,
    /// Frames and packets the pit stream could not take (its task behind): they are in the
    /// raw log and the store, not on the pit's stream.
    pit_dropped,
    /// History requests a pit sent (`aer-pit/<car>/history/request`).
    history_requests,
    /// History requests refused: malformed, or more waiting than the Pi serves.
    history_refused,
    /// Batches sent again as history.
    history_batches,
    /// Rows committed to the local store.
    stored,
    /// Rows the local store could not take (behind or failing); their frames stay in the
    /// raw log.
    store_dropped,
    /// Failed commits to the local store (retried with backoff).
    store_errors,
    /// Rows removed from the store to keep it within its budget.
    pruned_rows,
    /// Rows of closed sessions compacted into the store's compressed blocks.
    compacted_rows,
    /// Compacted blocks that did not decode when read (their rows are not forwarded).
    damaged_blocks,
    /// Frames written to the raw log.
    raw_frames,
    /// Frames the raw log could not keep (writer behind, disk full or failing).
    raw_dropped,
    /// Failed raw log writes (the segment is given up; the next one is tried after a backoff).
    raw_errors,
    /// Raw log segments removed to keep it within its budget.
    pruned_segments,
    /// Rows forwarded to TDengine.
    forwarded,
    /// TDengine write failures (retried).
    forward_errors,
    /// Rows TDengine refused outright, set aside in the store instead of blocking the rest.
    forward_set_aside,
    /// Broker connections the gate refused (reserved client id, bad credentials, no room,
    /// a publish under the car's prefix).
    mqtt_refused,
    /// Broker clients disconnected for not reading what they subscribed to.
    mqtt_slow_clients,
    /// Live messages the gate dropped for clients that could not keep up (each got the
    /// newest instead; the status names the clients).
    mqtt_client_dropped,
    /// XCP masters the gateway refused: an address outside its allow list, or another
    /// master while one is connected.
    xcp_refused,
    /// XCP command packets the gateway forwarded from the pit to the CCM.
    xcp_commands,
    /// XCP packets (responses, events, DAQ) the gateway forwarded from the CCM to the pit.
    xcp_responses,
    /// XCP packets from the CCM with no master to take them (after a master vanished: the
    /// answer to the DISCONNECT the gateway sent for it, DAQ still running), packets a master
    /// sent that were not XCP on TCP, and commands the bus would not take (for both, the
    /// master is disconnected).
    xcp_dropped,
    /// Calibration changes the CCM accepted from a master through the gateway (each
    /// parameter element changed, each revert, page switch and save).
    calibration_changes,
    /// Calibration changes the CCM refused (out of range, not in this vehicle state, locked).
    calibration_refusals,
    /// Calibration entries the store could not record (behind, failing, or no session open);
    /// the journal and the status still show the changes.
    calibration_unrecorded,
    /// Lap marks from the dashboards that were not marks (malformed, out of range) or came
    /// faster than they are stored.
    marks_refused,
    /// Times a looping replay (the demo) started its log again: its loop points, where the
    /// counters and the telemetry sequence start over (not faults of the car).
    replay_passes,
    /// Session events (marks, problems, counts that grew, loop points) the store could not
    /// record (behind, failing, or no session open).
    events_unrecorded,
}

/// What went wrong with one message's frames, as the status reports it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct MessageHealth {
    /// Frames with a wrong checksum.
    pub checksum_failures: u64,
    /// Frames repeating the previous frame's counter.
    pub counter_repeats: u64,
    /// Frames whose counter skipped.
    pub counter_jumps: u64,
    /// Frames later than the message's freshness limit.
    pub late_frames: u64,
}

impl Counters {
    /// Adds one to `counter`; returns the new count.
    pub fn bump(counter: &AtomicU64) -> u64 {
        counter.fetch_add(1, Ordering::Relaxed) + 1
    }
}

/// True for the counts worth a log line (1, 2, 4, 8, ...): every kind of fault is logged the
/// first time and then ever more rarely, so a flood cannot drown the log.
pub fn worth_logging(count: u64) -> bool {
    count.is_power_of_two()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_snapshot_reads_every_counter() {
        let counters = Counters::default();
        Counters::bump(&counters.frames);
        Counters::bump(&counters.forward_errors);
        Counters::bump(&counters.forward_errors);
        let snapshot = counters.snapshot();
        assert_eq!((snapshot.frames, snapshot.forward_errors), (1, 2));
        assert_eq!(snapshot.packets, 0);
    }

    #[test]
    fn logging_thins_out_as_a_count_grows() {
        let logged: Vec<u64> = (1..=20).filter(|c| worth_logging(*c)).collect();
        assert_eq!(logged, [1, 2, 4, 8, 16]);
    }
}
