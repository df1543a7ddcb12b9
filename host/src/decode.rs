//! Frames in, records out: ISO-TP reassembly of the telemetry packet (per bus), fingerprint
//! check, the generated decoders (the packet with its Deku structs, frames with the DBC
//! codec). Every failure is counted and logged. Decoding only: where records go is the
//! caller's business.

use crate::formats::candump::{LoggedFrame, parse_line};
use crate::reports::counters::{Counters, worth_logging};
use aer::can::AnyMessage;
use aer::runtime::{CounterCheck, DecodeError, IntegrityError};
use aer::telemetry::{Telemetry, TelemetryError, TelemetryHeader};
use aer::telemetry_deku::{TelemetryDecodeError, TelemetryFrame};
use aer_isotp::{Config, Frame, Received, Receiver};
use embedded_can::Id;
use std::collections::HashMap;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use tracing::warn;

/// Largest ISO-TP message accepted (the protocol's limit; the packet is much smaller).
const MAX_MESSAGE: usize = aer_isotp::MAX_PAYLOAD;

/// A decoded unit of data.
#[derive(Debug, Clone, PartialEq)]
pub enum Record {
    /// A telemetry packet.
    Telemetry {
        /// When its last frame arrived (us since the epoch).
        ts_us: u64,
        /// Bus it came on.
        bus: u8,
        header: TelemetryHeader,
        telemetry: Box<Telemetry>,
    },
    /// A regular DBC frame.
    Can {
        /// When it arrived (us since the epoch).
        ts_us: u64,
        /// Bus it came on.
        bus: u8,
        message: AnyMessage,
        /// What the message's counter, checksum and freshness limit say of the frame.
        check: FrameCheck,
    },
}

/// What the schema's counter, checksum and freshness limit say of one frame. The frame is
/// kept whatever they say (records are the bus as it was); the store sums these per session
/// and message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FrameCheck {
    /// Its checksum does not match its payload.
    pub checksum_failed: bool,
    /// Its counter repeats the previous frame's.
    pub counter_repeated: bool,
    /// Its counter skipped.
    pub counter_jumped: bool,
    /// It came later than the message's freshness limit after the previous one.
    pub late: bool,
}

/// The decoder state: one ISO-TP receiver per bus.
pub struct Ingest {
    counters: Arc<Counters>,
    receivers: Vec<Receiver<MAX_MESSAGE>>,
    /// Reassemble ISO-TP from raw frames (replays, and buses without the kernel's ISO-TP
    /// socket); `false` when the kernel delivers whole packets through [`Ingest::on_packet`].
    userspace_isotp: bool,
    /// Per bus and message (id, extended): the last counter accepted and when the last frame
    /// came (us), for the integrity and lateness counts.
    watches: HashMap<(u8, u32, bool), Watch>,
}

/// One message's last counter and arrival on one bus.
#[derive(Debug, Default)]
struct Watch {
    counter: CounterCheck,
    last_us: Option<u64>,
}

impl Ingest {
    /// A decoder counting into `counters`.
    pub fn new(counters: Arc<Counters>) -> Self {
        Self {
            counters,
            receivers: Vec::new(),
            userspace_isotp: true,
            watches: HashMap::new(),
        }
    }

    /// The recording starts again (a looping replay's next pass, the demo's loop point): the
    /// counters and arrival times learned so far, and any packet half reassembled, belong to
    /// the pass before, so the first frames of this one are not counted as counter jumps,
    /// late frames or broken packets.
    pub fn restart(&mut self) {
        self.watches.clear();
        self.receivers.clear();
    }

    /// Names bus `index` (its interface) in the measured traffic.
    pub fn name_bus(&self, index: u8, name: &str) {
        if let Ok(mut traffic) = self.counters.traffic.lock() {
            traffic.name_bus(index, name);
        }
    }

    /// Leaves ISO-TP to the kernel: raw 0x666/0x777 frames are then ignored.
    pub fn use_kernel_isotp(&mut self) {
        self.userspace_isotp = false;
    }

    /// Decodes a telemetry packet the kernel's ISO-TP socket reassembled.
    pub fn on_packet(&self, ts_us: u64, bus: u8, packet: &[u8], mut emit: impl FnMut(Record)) {
        packet_record(&self.counters, ts_us, bus, packet, &mut emit);
    }

    /// Decodes one frame. `emit` gets every record; `reply` gets the ISO-TP flow-control
    /// frames to send back on the frame's bus (live buses only; replays ignore them).
    pub fn on_frame(
        &mut self,
        frame: &LoggedFrame,
        mut emit: impl FnMut(Record),
        mut reply: impl FnMut(u8, Frame),
    ) {
        Counters::bump(&self.counters.frames);
        let (id, extended) = match frame.id {
            Id::Standard(id) => (u32::from(id.as_raw()), false),
            Id::Extended(id) => (id.as_raw(), true),
        };
        if let Ok(mut traffic) = self.counters.traffic.lock() {
            traffic.frame(frame.bus, frame.ts_us, frame.payload().len(), extended);
        }
        if !extended && id == u32::from(Telemetry::TX_ID) {
            if self.userspace_isotp {
                self.isotp(frame, &mut emit, &mut reply);
            }
            return;
        }
        if !extended && id == u32::from(Telemetry::FLOW_CONTROL_ID) {
            // Our own (or a logged) flow control: not data.
            return;
        }
        match AnyMessage::decode(id, extended, frame.payload()) {
            Ok(message) => {
                Counters::bump(&self.counters.messages);
                let check = self.watch(frame, id, extended, &message);
                emit(Record::Can {
                    ts_us: frame.ts_us,
                    bus: frame.bus,
                    message,
                    check,
                });
            }
            Err(DecodeError::UnknownId { .. }) => {
                let count = Counters::bump(&self.counters.unknown_ids);
                if worth_logging(count) {
                    warn!(
                        id = format_args!("{id:#x}"),
                        extended, count, "frame of an id the schema does not know"
                    );
                }
            }
            Err(error) => {
                let count = Counters::bump(&self.counters.decode_errors);
                if worth_logging(count) {
                    warn!(%error, count, "frame failed to decode");
                }
            }
        }
    }

    /// Counts a frame whose checksum or counter says it is not fresh, intact data, and one
    /// that comes later than its message's freshness limit, and says which it is. The frame
    /// is kept all the same (records are the bus as it was; the CCM is the one that refuses
    /// them).
    fn watch(
        &mut self,
        frame: &LoggedFrame,
        id: u32,
        extended: bool,
        message: &AnyMessage,
    ) -> FrameCheck {
        let meta = message.meta();
        if let Ok(mut traffic) = self.counters.traffic.lock() {
            traffic.message(frame.bus, meta, frame.ts_us);
        }
        if let Ok(mut arrivals) = self.counters.arrivals.lock() {
            arrivals.message(meta, frame.ts_us);
        }
        if meta.counter.is_none() && meta.checksum.is_none() && meta.timeout_ms.is_none() {
            return FrameCheck::default();
        }
        let watch = self.watches.entry((frame.bus, id, extended)).or_default();
        let late = meta.timeout_ms.is_some_and(|limit| {
            watch
                .last_us
                .is_some_and(|last| frame.ts_us.saturating_sub(last) > u64::from(limit) * 1_000)
        });
        watch.last_us = Some(frame.ts_us);
        let verdict = meta.verify(&mut watch.counter, frame.payload());
        let check = FrameCheck {
            checksum_failed: matches!(verdict, Err(IntegrityError::Checksum { .. })),
            counter_repeated: matches!(verdict, Err(IntegrityError::CounterRepeated { .. })),
            counter_jumped: matches!(verdict, Err(IntegrityError::CounterJumped { .. })),
            late,
        };
        if verdict.is_ok() && !late {
            return check;
        }
        let counters = &self.counters;
        if let Err(error) = verdict {
            let counter = match error {
                IntegrityError::Checksum { .. } => &counters.checksum_failures,
                IntegrityError::CounterRepeated { .. } => &counters.counter_repeats,
                IntegrityError::CounterJumped { .. } => &counters.counter_jumps,
            };
            let count = Counters::bump(counter);
            if worth_logging(count) {
                warn!(%error, count, "frame refused by its counter or checksum (kept)");
            }
        }
        if late {
            Counters::bump(&counters.late_frames);
        }
        if let Ok(mut health) = counters.message_health.lock() {
            let entry = health.entry(meta.name.to_owned()).or_default();
            entry.checksum_failures += u64::from(check.checksum_failed);
            entry.counter_repeats += u64::from(check.counter_repeated);
            entry.counter_jumps += u64::from(check.counter_jumped);
            entry.late_frames += u64::from(check.late);
        }
        check
    }

    fn isotp(
        &mut self,
        frame: &LoggedFrame,
        emit: &mut impl FnMut(Record),
        reply: &mut impl FnMut(u8, Frame),
    ) {
        let bus = usize::from(frame.bus);
        while self.receivers.len() <= bus {
            self.receivers.push(Receiver::new(Config::CAR));
        }
        let Some(receiver) = self.receivers.get_mut(bus) else {
            return;
        };
        let counters = &self.counters;
        match receiver.on_frame(frame.payload(), frame.ts_us as u32) {
            Ok(Received::Nothing) => {}
            Ok(Received::FlowControl(fc)) => reply(frame.bus, fc),
            Ok(Received::Message(packet)) => {
                packet_record(counters, frame.ts_us, frame.bus, packet, emit)
            }
            Err(error) => {
                let count = Counters::bump(&counters.isotp_errors);
                if worth_logging(count) {
                    warn!(bus, ?error, count, "ISO-TP frame rejected");
                }
            }
        }
        // Reported after the frame is taken, so a new message is never held up.
        if receiver.take_interrupted() {
            let count = Counters::bump(&counters.isotp_errors);
            if worth_logging(count) {
                warn!(bus, count, "ISO-TP message interrupted by a new one");
            }
        }
    }
}

/// Decodes a reassembled telemetry packet with the generated Deku structs (length and
/// fingerprint checked) into a record.
fn packet_record(
    counters: &Counters,
    ts_us: u64,
    bus: u8,
    packet: &[u8],
    emit: &mut impl FnMut(Record),
) {
    match TelemetryFrame::decode(packet).map(|frame| frame.to_telemetry()) {
        Ok((header, telemetry)) => {
            Counters::bump(&counters.packets);
            counters.last_packet_us.store(ts_us, Ordering::Relaxed);
            if let Ok(mut arrivals) = counters.arrivals.lock() {
                arrivals.packet(ts_us);
            }
            counters.firmware_fingerprint.store(
                u64::from(aer::telemetry::TELEMETRY_FINGERPRINT),
                Ordering::Relaxed,
            );
            emit(Record::Telemetry {
                ts_us,
                bus,
                header,
                telemetry: Box::new(telemetry),
            });
        }
        Err(TelemetryDecodeError::Packet(TelemetryError::FingerprintMismatch {
            expected,
            found,
        })) => {
            counters
                .firmware_fingerprint
                .store(u64::from(found), Ordering::Relaxed);
            counters
                .mismatched_fingerprint
                .store(u64::from(found), Ordering::Relaxed);
            let count = Counters::bump(&counters.fingerprint_mismatches);
            if worth_logging(count) {
                warn!(
                    expected = format_args!("{expected:#010x}"),
                    found = format_args!("{found:#010x}"),
                    count,
                    "telemetry from firmware built from another schema: flash the CCM from this commit"
                );
            }
        }
        Err(error) => {
            let count = Counters::bump(&counters.packet_errors);
            if worth_logging(count) {
                warn!(%error, count, "telemetry packet rejected");
            }
        }
    }
}

/// A candump log decoded as the service decodes it, without outputs.
#[derive(Debug)]
pub struct DecodedLog {
    /// Every telemetry packet: receive time (us since the epoch), header and values.
    pub packets: Vec<(u64, TelemetryHeader, Telemetry)>,
    /// What decoding counted (frames, errors, the firmware fingerprint seen, ...).
    pub counters: Arc<Counters>,
}

/// Decodes a whole log in memory with its recorded timestamps (tests, benchmarks, the
/// dashboard's screenshots). Broken lines are counted in `bad_lines`, as in a replay.
pub fn decode_log(log: &str) -> DecodedLog {
    let counters = Arc::new(Counters::default());
    let mut ingest = Ingest::new(counters.clone());
    let mut buses: HashMap<String, u8> = HashMap::new();
    let mut packets = Vec::new();
    for line in log.lines().filter(|line| !line.trim().is_empty()) {
        let known = buses.len();
        let parsed = parse_line(line, |name| {
            let next = u8::try_from(buses.len()).unwrap_or(u8::MAX);
            *buses.entry(name.to_owned()).or_insert(next)
        });
        if buses.len() > known {
            for (name, index) in &buses {
                ingest.name_bus(*index, name);
            }
        }
        let Ok(frame) = parsed else {
            Counters::bump(&counters.bad_lines);
            continue;
        };
        ingest.on_frame(
            &frame,
            |record| {
                if let Record::Telemetry {
                    ts_us,
                    header,
                    telemetry,
                    ..
                } = record
                {
                    packets.push((ts_us, header, *telemetry));
                }
            },
            |_, _| {},
        );
    }
    DecodedLog { packets, counters }
}
