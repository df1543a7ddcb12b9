//! The ingest service's own topics: its status (retained: which schema it decodes, which the
//! firmware sends, when data last came) and its counters every second.

use crate::clock::{now_us, seconds};
use crate::reports::counters::{Counters, ServiceCounters};
use aer::mqtt::Topic;
use serde::{Deserialize, Serialize};
use std::sync::atomic::Ordering;

/// The ingest service's state, retained, so a subscriber learns it on subscribing.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Status {
    /// The publishing service (`aer-raspi`).
    pub service: String,
    pub car_id: String,
    /// The DBC schema fingerprint the service was built from (`0x` and eight hex digits).
    pub schema_fingerprint: String,
    /// The telemetry fingerprint the service decodes.
    pub telemetry_fingerprint: String,
    /// The telemetry fingerprint the firmware last sent (`null` before the first packet).
    pub firmware_fingerprint_seen: Option<String>,
    /// Whether the firmware and the service were built from the same schema.
    pub fingerprint_match: Option<bool>,
    /// Receive time of the last telemetry packet (s since the epoch).
    pub last_packet_ts: Option<f64>,
    /// Telemetry packets this service could not decode because another schema built them;
    /// they stay in the raw log (docs/pi-service.md says how to decode them).
    #[serde(default)]
    pub undecodable_packets: u64,
    /// The fingerprint those packets carry (the last one seen).
    #[serde(default)]
    pub undecodable_fingerprint: Option<String>,
    /// What is failing now, part by part.
    #[serde(default)]
    pub problems: Problems,
    /// Per message, the frames that came with a wrong checksum, a repeated or skipped
    /// counter, or later than the message's freshness limit (only messages with any).
    #[serde(default)]
    pub message_health: std::collections::BTreeMap<String, crate::reports::counters::MessageHealth>,
    /// Each bus's measured traffic since the previous status (about a second), by interface:
    /// frames, bits and load at worst-case stuffing, as the build-time figure in
    /// `generated/docs/can.md` counts them.
    #[serde(default)]
    pub bus_traffic: std::collections::BTreeMap<String, crate::reports::traffic::BusTraffic>,
    /// Each message's measured rate over the same window beside its declared cycle time, by
    /// interface and message.
    #[serde(default)]
    pub message_rates: std::collections::BTreeMap<
        String,
        std::collections::BTreeMap<String, crate::reports::traffic::MessageRate>,
    >,
    /// The clients connected through the gate (embedded broker only), each with how far
    /// behind it is.
    #[serde(default)]
    pub mqtt_clients: Vec<MqttClient>,
    /// The pit's XCP gateway to the CCM's calibration slave, when the service runs one.
    #[serde(default)]
    pub xcp_gateway: Option<XcpGateway>,
}

/// The XCP gateway as the status reports it.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct XcpGateway {
    /// Where pit masters connect (XCP on TCP).
    pub listen: String,
    /// The CAN interface the CCM's slave is on.
    pub interface: String,
    /// The master connected now (its address), if any: one at a time.
    pub master: Option<String>,
    /// When it connected (us since the epoch).
    pub master_since_us: Option<u64>,
    /// The master holds an XCP session with the CCM (its CONNECT was answered).
    pub session: bool,
    /// The last refusal, with the address and why.
    pub last_refusal: Option<String>,
    /// The last calibration change (or refused change) a master made, as one line.
    #[serde(default)]
    pub last_change: Option<String>,
    /// CRC-32 of the calibration the CCM runs on, as the gateway last knew it (hex, the value
    /// `CCM_CalChecksum` carries).
    #[serde(default)]
    pub checksum: Option<String>,
}

/// One MQTT client as the gate serves it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MqttClient {
    /// The client id it connected with.
    pub client_id: String,
    /// The listener it came through (`pit`, `local`, ...).
    pub listener: String,
    /// `3.1.1` or `5`.
    pub protocol: String,
    /// How long the oldest message the gate holds for it has waited (0: it is keeping up).
    /// The gate drops live messages older than its bound, so this stays about that bound
    /// for a client that cannot keep up.
    pub lag_ms: u64,
    /// What the gate holds for it now (bytes).
    pub queued_bytes: u64,
    /// Live messages dropped for it since it connected (newest data first: a pit fetches
    /// them from the Pi's history).
    pub dropped: u64,
}

impl Problems {
    /// Each problem there is, with the part's name.
    pub fn named(&self) -> Vec<(&'static str, &str)> {
        [
            ("store", &self.store),
            ("store recovered", &self.store_recovered),
            ("raw log", &self.raw_log),
            ("disk", &self.disk),
            ("TDengine", &self.forward),
            ("TDengine refused", &self.forward_refused),
            ("MQTT", &self.mqtt),
            ("CAN", &self.can),
            ("firmware", &self.firmware),
            ("MQTT clients", &self.mqtt_clients),
            ("XCP gateway", &self.xcp_gateway),
            ("never arrived", &self.never_arrived),
        ]
        .into_iter()
        .filter_map(|(part, problem)| problem.as_deref().map(|p| (part, p)))
        .collect()
    }
}

/// A client this far behind (or losing messages) is a problem the status names.
pub const CLIENT_BEHIND_MS: u64 = 1_000;

/// The problem line for clients behind, `None` while every client keeps up. Each client comes
/// with the messages dropped for it since the last status.
pub fn clients_behind(clients: &[(MqttClient, u64)]) -> Option<String> {
    let behind: Vec<String> = clients
        .iter()
        .filter(|(client, dropped)| client.lag_ms >= CLIENT_BEHIND_MS || *dropped > 0)
        .map(|(client, dropped)| {
            format!(
                "`{}` ({}) {:.1} s behind, {dropped} messages dropped in the last second",
                client.client_id,
                client.listener,
                client.lag_ms as f64 / 1000.0
            )
        })
        .collect();
    (!behind.is_empty()).then(|| {
        format!(
            "MQTT clients not keeping up (served the newest data; a pit fetches the rest from \
             history): {}",
            behind.join("; ")
        )
    })
}

/// What is failing in the service, part by part (`None`: working).
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Problems {
    /// The local store's last write error, while writes fail (rows are dropped and counted).
    pub store: Option<String>,
    /// A damaged store found at start-up, and where it was moved.
    pub store_recovered: Option<String>,
    /// The raw log's last write error, while writes fail.
    pub raw_log: Option<String>,
    /// The disk is under the free-space floor and pruning cannot lift it: the session being
    /// recorded is kept, a full disk drops rows (counted) until space is made.
    #[serde(default)]
    pub disk: Option<String>,
    /// Forwarding to TDengine is failing (an outage).
    pub forward: Option<String>,
    /// Rows TDengine refused, set aside in the store (`forward_set_aside`) with the reason.
    pub forward_refused: Option<String>,
    /// The service's own link to the broker.
    pub mqtt: Option<String>,
    /// CAN interfaces that cannot be opened or read, each with its error
    /// (`can0: No such device (os error 19)`).
    pub can: Option<String>,
    /// The firmware sends telemetry of another schema (both fingerprints), while its latest
    /// packets are of another schema.
    #[serde(default)]
    pub firmware: Option<String>,
    /// MQTT clients behind by a second or more, or losing live messages (their link is
    /// slower than what they subscribed to).
    #[serde(default)]
    pub mqtt_clients: Option<String>,
    /// The XCP gateway could not start (its address taken, its CAN interface missing).
    #[serde(default)]
    pub xcp_gateway: Option<String>,
    /// Periodic messages the schema declares on a bus this car has that never arrived since
    /// the service started, and the telemetry fields mirroring them (or the telemetry packet
    /// itself): what nothing sends reads 0, not missing, in the data.
    #[serde(default)]
    pub never_arrived: Option<String>,
}

/// The ingest service's counters, published every second.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Metrics {
    /// When they were read (s since the epoch).
    pub ts: f64,
    /// Telemetry packets decoded in the last second.
    pub packets_per_s: f64,
    /// Rows decoded but not yet committed to (or dropped by) the local store.
    pub store_lag: u64,
    #[serde(flatten)]
    pub counters: ServiceCounters,
}

/// The ingest service's status (retained).
pub const STATUS: Topic<Status> = Topic::new("status");

/// The ingest service's counters, every second.
pub const METRICS: Topic<Metrics> = Topic::new("metrics");

/// The status as of now, for `car_id`, from what `counters` saw and the `problems` reported.
pub fn status(car_id: &str, counters: &Counters, problems: Problems) -> Status {
    let seen = counters.firmware_fingerprint.load(Ordering::Relaxed);
    let mismatched = counters.mismatched_fingerprint.load(Ordering::Relaxed);
    let last = counters.last_packet_us.load(Ordering::Relaxed);
    let ours = aer::telemetry::TELEMETRY_FINGERPRINT;
    let mut problems = problems;
    problems.never_arrived = counters
        .arrivals
        .lock()
        .ok()
        .and_then(|arrivals| arrivals.problem(&aer::can::MESSAGES));
    if seen != 0 && seen != u64::from(ours) {
        problems.firmware = Some(format!(
            "telemetry of another schema: the firmware sends {seen:#010x}, this service \
             decodes {ours:#010x}; flash the CCM and install the service from the same commit \
             (the packets are kept in the raw log)"
        ));
    }
    let (bus_traffic, message_rates) = counters
        .traffic
        .lock()
        .map(|traffic| (traffic.buses(), traffic.messages()))
        .unwrap_or_default();
    Status {
        service: "aer-raspi".to_owned(),
        car_id: car_id.to_owned(),
        schema_fingerprint: format!("{:#010x}", aer::can::SCHEMA_FINGERPRINT),
        telemetry_fingerprint: format!("{ours:#010x}"),
        firmware_fingerprint_seen: (seen != 0).then(|| format!("{seen:#010x}")),
        fingerprint_match: (seen != 0).then_some(seen == u64::from(ours)),
        last_packet_ts: (last != 0).then(|| seconds(last)),
        undecodable_packets: counters.fingerprint_mismatches.load(Ordering::Relaxed),
        undecodable_fingerprint: (mismatched != 0).then(|| format!("{mismatched:#010x}")),
        problems,
        message_health: counters
            .message_health
            .lock()
            .map(|health| health.clone())
            .unwrap_or_default(),
        bus_traffic,
        message_rates,
        mqtt_clients: Vec::new(),
        xcp_gateway: None,
    }
}

/// The counters `now`, with the packet rate since `previous` (read one second earlier).
pub fn metrics(now: ServiceCounters, previous: ServiceCounters) -> Metrics {
    Metrics {
        ts: seconds(now_us()),
        packets_per_s: now.packets.saturating_sub(previous.packets) as f64,
        store_lag: (now.packets + now.messages).saturating_sub(now.stored + now.store_dropped),
        counters: now,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_status_says_whether_the_firmware_matches() {
        let counters = Counters::default();
        let before = status("car1", &counters, Problems::default());
        assert_eq!(
            (before.fingerprint_match, before.last_packet_ts),
            (None, None)
        );
        counters.firmware_fingerprint.store(
            u64::from(aer::telemetry::TELEMETRY_FINGERPRINT),
            Ordering::Relaxed,
        );
        counters.last_packet_us.store(2_500_000, Ordering::Relaxed);
        let after = status("car1", &counters, Problems::default());
        assert_eq!(after.fingerprint_match, Some(true));
        assert_eq!(after.last_packet_ts, Some(2.5));
        let round_trip = STATUS.decode(&STATUS.encode(&after).unwrap()).unwrap();
        assert_eq!(round_trip, after);
        assert_eq!(after.problems.firmware, None);
    }

    #[test]
    fn firmware_of_another_schema_is_a_problem_naming_both_fingerprints() {
        let counters = Counters::default();
        counters
            .firmware_fingerprint
            .store(0xDEAD_BEEF, Ordering::Relaxed);
        let status = status("car1", &counters, Problems::default());
        let problem = status.problems.firmware.expect("a problem");
        let ours = format!("{:#010x}", aer::telemetry::TELEMETRY_FINGERPRINT);
        assert!(
            problem.contains("0xdeadbeef") && problem.contains(&ours),
            "{problem}"
        );
        assert_eq!(status.fingerprint_match, Some(false));
    }
}
