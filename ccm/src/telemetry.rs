//! Sends the telemetry packet every 10 ms over ISO-TP (0x666 out, the Pi's flow control on
//! 0x777 in), with the same `aer-isotp` code the Pi receives with.

use aer::telemetry::{Telemetry, TelemetryHeader};
use aer_isotp::{Config, Frame, SendError, Sender};

/// Buffer for one packet (the packet is `Telemetry::LEN` bytes; room to grow).
const BUFFER: usize = 128;
const _: () = assert!(
    Telemetry::LEN <= BUFFER,
    "raise BUFFER: the telemetry packet grew"
);

/// Counters the CCM reports about its telemetry link.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LinkCounters {
    /// Packets started.
    pub sent: u32,
    /// Packets abandoned because the next snapshot was due before they finished (no or slow
    /// flow control from the Pi).
    pub superseded: u32,
    /// Packets that ended in an ISO-TP error (timeout, overflow, too many waits).
    pub failed: u32,
    /// Fields saturated while packing (a value outside its wire range).
    pub saturated_fields: u32,
}

/// The CCM end of the telemetry link.
#[derive(Debug, Clone)]
pub struct TelemetryLink {
    sender: Sender<BUFFER>,
    sequence: u16,
    counters: LinkCounters,
    last_error: Option<SendError>,
    last_packet: [u8; Telemetry::LEN],
}

impl Default for TelemetryLink {
    fn default() -> Self {
        Self::new()
    }
}

impl TelemetryLink {
    /// An idle link with the car's ISO-TP settings.
    pub const fn new() -> Self {
        Self {
            sender: Sender::new(Config::CAR),
            sequence: 0,
            counters: LinkCounters {
                sent: 0,
                superseded: 0,
                failed: 0,
                saturated_fields: 0,
            },
            last_error: None,
            last_packet: [0; Telemetry::LEN],
        }
    }

    /// Counters so far.
    pub fn counters(&self) -> LinkCounters {
        self.counters
    }

    /// The packet last packed, exactly as sent (what XCP reads at the telemetry address).
    pub fn last_packet(&self) -> &[u8; Telemetry::LEN] {
        &self.last_packet
    }

    /// The last ISO-TP error, for diagnostics.
    pub fn last_error(&self) -> Option<SendError> {
        self.last_error
    }

    /// Packs `snapshot` and starts sending it; a packet still in flight is abandoned
    /// (fresh data beats stale data) and counted.
    pub fn send(&mut self, snapshot: &Telemetry, now_us: u32) {
        let mut packet = [0u8; Telemetry::LEN];
        let header = TelemetryHeader {
            sequence: self.sequence,
            timestamp_us: now_us,
        };
        self.counters.saturated_fields = self
            .counters
            .saturated_fields
            .wrapping_add(u32::from(snapshot.pack(header, &mut packet)));
        self.last_packet = packet;
        if !self.sender.is_idle() {
            self.sender.abort();
            self.counters.superseded = self.counters.superseded.wrapping_add(1);
        }
        // The packet is never empty and fits the buffer (checked at compile time above).
        if self.sender.start(&packet).is_ok() {
            self.sequence = self.sequence.wrapping_add(1);
            self.counters.sent = self.counters.sent.wrapping_add(1);
        }
    }

    /// The next frame to put on the bus, if one is due; call [`sent`](Self::sent) once it is
    /// queued, or call again later if the controller was busy.
    pub fn poll(&mut self, now_us: u32) -> Option<Frame> {
        match self.sender.poll(now_us) {
            Ok(frame) => frame,
            Err(error) => {
                self.fail(error);
                None
            }
        }
    }

    /// Records that the frame from [`poll`](Self::poll) was queued.
    pub fn sent(&mut self, now_us: u32) {
        self.sender.sent(now_us);
    }

    /// Feeds a frame received on the flow-control id (0x777).
    pub fn on_flow_control(&mut self, data: &[u8], now_us: u32) {
        if let Err(error) = self.sender.on_flow_control(data, now_us) {
            self.fail(error);
        }
    }

    fn fail(&mut self, error: SendError) {
        self.counters.failed = self.counters.failed.wrapping_add(1);
        self.last_error = Some(error);
    }
}
