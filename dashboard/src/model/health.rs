//! Link health: the broker connection, the packet rate, packets lost on the way (gaps in the
//! CCM's sequence numbers), payloads this dashboard could not read, and what the Pi reports
//! (its counters and whether the firmware's schema matches).

use aer_host::reports::status::{Metrics, MqttClient, Status};
use std::collections::VecDeque;
use std::time::{Duration, Instant};

/// A sequence jump larger than this is a restart of the CCM (or a replay), not a loss.
const MAX_GAP: u16 = 1_000;
/// The window the packet rate is counted over.
const RATE_WINDOW: Duration = Duration::from_secs(1);

/// The broker connection as the dashboard sees it.
#[derive(Debug, Clone, PartialEq)]
pub enum Connection {
    /// Not connected yet.
    Connecting,
    Connected,
    /// Lost (or never made); the reason, and since when.
    Lost {
        since: Instant,
        reason: String,
    },
}

/// Everything the pit view's link panel shows.
#[derive(Debug, Clone)]
pub struct Health {
    pub connection: Connection,
    /// Telemetry packets received.
    pub packets: u64,
    /// Packets missing between received ones (sequence gaps).
    pub lost: u64,
    /// Payloads that did not decode as their topic's type (another schema, or corrupted).
    pub undecodable: u64,
    /// Batches of the compact stream that never arrived (numbering gaps).
    pub stream_gaps: u64,
    /// Telemetry packets merged from the Pi's history (what the gaps missed).
    pub backfilled: u64,
    /// How far the history has caught up (with the compact stream, once the link reports).
    pub backfill: Option<super::BackfillProgress>,
    /// The last decode error, for the link panel.
    pub last_error: Option<String>,
    /// The Pi's retained status.
    pub status: Option<Status>,
    /// The client id this dashboard connects with.
    pub client_id: Option<String>,
    /// The Pi's latest counters.
    pub metrics: Option<Metrics>,
    /// Every CAN message the Pi's status has reported frames of, on any bus.
    heard: std::collections::BTreeSet<String>,
    last_sequence: Option<u16>,
    arrivals: VecDeque<Instant>,
}

impl Default for Health {
    fn default() -> Self {
        Self {
            connection: Connection::Connecting,
            packets: 0,
            lost: 0,
            undecodable: 0,
            stream_gaps: 0,
            backfilled: 0,
            backfill: None,
            last_error: None,
            status: None,
            client_id: None,
            metrics: None,
            heard: std::collections::BTreeSet::new(),
            last_sequence: None,
            arrivals: VecDeque::new(),
        }
    }
}

/// Whether the car's buses carry a message, as the Pi's status has shown them so far.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Carried {
    /// No status with traffic yet: nothing to tell.
    Unknown,
    /// The Pi has reported frames of it.
    Yes,
    /// The Pi reports traffic, never of this message: it is not on this car (the other
    /// inverter's, say).
    No,
}

/// Whether the pieces of the chain were built from the same schema.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SchemaMatch {
    /// Not known yet (no status from the Pi).
    Unknown,
    /// Firmware, Pi and dashboard agree.
    Match,
    /// The firmware sends another layout than the Pi decodes (the Pi rejects its packets).
    FirmwareDiffers,
    /// The Pi was built from another schema than this dashboard.
    PiDiffers,
}

impl Health {
    /// Takes the Pi's status: the latest, and every message it has reported frames of.
    pub fn status(&mut self, status: Status) {
        for rates in status.message_rates.values() {
            for (message, rate) in rates {
                if rate.frames > 0 && !self.heard.contains(message) {
                    self.heard.insert(message.clone());
                }
            }
        }
        self.status = Some(status);
    }

    /// This dashboard as the Pi's gate serves it (how far behind, what it dropped), once the
    /// status lists it.
    pub fn served(&self) -> Option<&MqttClient> {
        let ours = self.client_id.as_deref()?;
        self.status
            .as_ref()?
            .mqtt_clients
            .iter()
            .find(|client| client.client_id == ours)
    }

    /// Whether the car's buses carry `message` (a DBC message name).
    pub fn carries(&self, message: &str) -> Carried {
        if self.heard.is_empty() {
            Carried::Unknown
        } else if self.heard.contains(message) {
            Carried::Yes
        } else {
            Carried::No
        }
    }

    /// Counts a telemetry packet with CCM sequence number `sequence`, received at `now`.
    pub fn packet(&mut self, sequence: u16, now: Instant) {
        self.packets += 1;
        if let Some(last) = self.last_sequence {
            let gap = sequence.wrapping_sub(last).wrapping_sub(1);
            if gap != 0 && gap < MAX_GAP {
                self.lost += u64::from(gap);
            }
        }
        self.last_sequence = Some(sequence);
        self.arrivals.push_back(now);
        self.forget_before(now);
    }

    /// Counts a payload that failed to decode.
    pub fn undecodable(&mut self, topic: &str, error: &str) {
        self.undecodable += 1;
        self.last_error = Some(format!("{topic}: {error}"));
    }

    /// Packets per second over the last second, as of `now`.
    pub fn rate(&self, now: Instant) -> usize {
        self.arrivals
            .iter()
            .rev()
            .take_while(|&&t| now.saturating_duration_since(t) <= RATE_WINDOW)
            .count()
    }

    fn forget_before(&mut self, now: Instant) {
        while self
            .arrivals
            .front()
            .is_some_and(|&t| now.saturating_duration_since(t) > RATE_WINDOW)
        {
            self.arrivals.pop_front();
        }
    }

    /// Whether firmware, Pi and this dashboard share one schema.
    pub fn schema_match(&self) -> SchemaMatch {
        let Some(status) = &self.status else {
            return SchemaMatch::Unknown;
        };
        if status.telemetry_fingerprint != fingerprint(aer::telemetry::TELEMETRY_FINGERPRINT) {
            return SchemaMatch::PiDiffers;
        }
        match status.fingerprint_match {
            Some(false) => SchemaMatch::FirmwareDiffers,
            Some(true) => SchemaMatch::Match,
            None => SchemaMatch::Unknown,
        }
    }
}

/// A fingerprint as the status topic writes it.
pub fn fingerprint(value: u32) -> String {
    format!("{value:#010x}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sequence_gaps_count_lost_packets_across_the_wrap() {
        let mut health = Health::default();
        let t = Instant::now();
        for sequence in [65_534, 65_535, 2, 3, 3] {
            health.packet(sequence, t);
        }
        // 0 and 1 are missing; the repeated 3 is no loss.
        assert_eq!(health.lost, 2);
        assert_eq!(health.packets, 5);
        // A CCM restart (sequence back to 0 from 40,000) is not 25,535 lost packets.
        health.packet(40_000, t);
        health.packet(0, t);
        assert_eq!(health.lost, 2);
    }

    #[test]
    fn the_rate_counts_the_last_second() {
        let mut health = Health::default();
        let start = Instant::now();
        for i in 0..300 {
            health.packet(i, start + Duration::from_millis(u64::from(i) * 10));
        }
        // Packets at 1.99 s back to 0.99 s: 101 of them (both ends included).
        assert_eq!(health.rate(start + Duration::from_millis(1_990)), 101);
        assert_eq!(health.rate(start + Duration::from_secs(10)), 0);
    }

    #[test]
    fn schema_agreement_comes_from_the_status_topic() {
        let mut health = Health::default();
        assert_eq!(health.schema_match(), SchemaMatch::Unknown);
        let ours = fingerprint(aer::telemetry::TELEMETRY_FINGERPRINT);
        let status = |telemetry: &str, firmware_ok: Option<bool>| Status {
            service: "aer-raspi".into(),
            car_id: "car1".into(),
            schema_fingerprint: "0x00000000".into(),
            telemetry_fingerprint: telemetry.into(),
            firmware_fingerprint_seen: None,
            fingerprint_match: firmware_ok,
            last_packet_ts: None,
            undecodable_packets: 0,
            undecodable_fingerprint: None,
            problems: Default::default(),
            message_health: Default::default(),
            bus_traffic: Default::default(),
            message_rates: Default::default(),
            mqtt_clients: Default::default(),
            xcp_gateway: None,
        };
        health.status = Some(status(&ours, Some(true)));
        assert_eq!(health.schema_match(), SchemaMatch::Match);
        health.status = Some(status(&ours, Some(false)));
        assert_eq!(health.schema_match(), SchemaMatch::FirmwareDiffers);
        health.status = Some(status("0x12345678", Some(true)));
        assert_eq!(health.schema_match(), SchemaMatch::PiDiffers);
    }
}
