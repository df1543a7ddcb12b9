//! What the schema declares and never arrived since the service started: a periodic message
//! no node sends (a message added to the DBC whose sender was never taught to send it, a
//! device configured without it), and the telemetry fields that mirror it. A field nothing
//! fills would otherwise read as a plausible 0 in every packet.
//!
//! A message counts as missing only on a bus this car has (one a message sent on that bus
//! alone arrived on: the comp car has no IFL100 bus, the bench car no DTI) and only once that
//! bus has been heard for longer than the message's freshness limit. Times are the frames' own
//! receive times, so a replay judges the recorded session, not the wall clock.

use aer::runtime::MessageMeta;
use aer::telemetry::Telemetry;
use std::collections::HashMap;

/// The first receive time of every message and of the telemetry packet.
#[derive(Debug, Default)]
pub struct Arrivals {
    /// By message name: the message and when its first frame came (us).
    first_us: HashMap<&'static str, (&'static MessageMeta, u64)>,
    /// When the first telemetry packet came.
    first_packet_us: Option<u64>,
    /// The newest receive time of anything.
    latest_us: u64,
}

impl Arrivals {
    /// A frame of `meta` received at `ts_us`.
    pub fn message(&mut self, meta: &'static MessageMeta, ts_us: u64) {
        self.first_us.entry(meta.name).or_insert((meta, ts_us));
        self.latest_us = self.latest_us.max(ts_us);
    }

    /// A telemetry packet received at `ts_us`.
    pub fn packet(&mut self, ts_us: u64) {
        self.first_packet_us.get_or_insert(ts_us);
        self.latest_us = self.latest_us.max(ts_us);
    }

    /// When the first message came.
    fn first(&self) -> Option<u64> {
        self.first_us.values().map(|(_, first)| *first).min()
    }

    /// The periodic messages of `declared` that never arrived on a bus this car has, though
    /// that bus has been heard for longer than their freshness limit. XCP responses are left
    /// out: the slave sends them only while a master talks to it.
    pub fn missing(&self, declared: &[&'static MessageMeta]) -> Vec<&'static MessageMeta> {
        // Each bus this car has, with when it was first heard.
        let mut heard: HashMap<&str, u64> = HashMap::new();
        for (meta, first) in self.first_us.values() {
            if let [bus] = meta.buses {
                let since = heard.entry(bus).or_insert(*first);
                *since = (*since).min(*first);
            }
        }
        let anything = self.first();
        declared
            .iter()
            .copied()
            .filter(|meta| {
                let Some(limit_ms) = meta.timeout_ms else {
                    return false;
                };
                if is_xcp_response(meta) || self.first_us.contains_key(meta.name) {
                    return false;
                }
                let since = if meta.buses.is_empty() {
                    anything
                } else {
                    meta.buses
                        .iter()
                        .filter_map(|bus| heard.get(bus))
                        .min()
                        .copied()
                };
                since.is_some_and(|since| {
                    self.latest_us.saturating_sub(since) > u64::from(limit_ms) * 1_000
                })
            })
            .collect()
    }

    /// The status's problem line: every declared message and telemetry field that never
    /// arrived, `None` while everything the car declares has come.
    pub fn problem(&self, declared: &[&'static MessageMeta]) -> Option<String> {
        let missing = self.missing(declared);
        let packet_missing = self.first_packet_us.is_none()
            && self.first().is_some_and(|first| {
                self.latest_us.saturating_sub(first) > u64::from(Telemetry::TIMEOUT_MS) * 1_000
            });
        if missing.is_empty() && !packet_missing {
            return None;
        }
        let mut parts = Vec::new();
        if packet_missing {
            parts.push(format!(
                "the telemetry packet (ISO-TP 0x{:03X}): every telemetry field",
                Telemetry::TX_ID
            ));
        }
        if !missing.is_empty() {
            let messages: Vec<String> = missing
                .iter()
                .map(|meta| {
                    let from = meta.sender.unwrap_or("its sender");
                    let every = meta
                        .cycle_time_ms
                        .map_or_else(String::new, |ms| format!(", every {ms} ms"));
                    format!("{} (from {from}{every})", meta.name)
                })
                .collect();
            parts.push(messages.join(", "));
            let fields = mirroring(&missing);
            if !fields.is_empty() {
                parts.push(format!(
                    "telemetry fields mirroring them: {}",
                    fields.join(", ")
                ));
            }
        }
        Some(format!(
            "declared in the schema, never received since the service started: {}",
            parts.join("; ")
        ))
    }
}

/// The telemetry fields that mirror a signal of one of `messages`.
fn mirroring(messages: &[&MessageMeta]) -> Vec<&'static str> {
    Telemetry::FIELDS
        .iter()
        .zip(Telemetry::DISPLAY)
        .filter(|(_, display)| {
            display
                .mirrors
                .is_some_and(|name| messages.iter().any(|meta| meta.name == name))
        })
        .map(|(field, _)| field.name)
        .collect()
}

/// The XCP slave's responses (`XCP_Res`): sent only while a master is connected.
fn is_xcp_response(meta: &MessageMeta) -> bool {
    !meta.extended && meta.id == aer::calibration::xcp::CAN_ID_SLAVE
}

#[cfg(test)]
mod tests {
    use super::*;
    use aer::can::{
        CcmStatus, DtiFlags, DtiTemperatures, ImdInfoGeneral, MESSAGES, Mcu1, OrionPackStatus,
    };

    #[test]
    fn a_declared_message_that_never_comes_is_named_with_the_fields_it_fills() {
        let mut arrivals = Arrivals::default();
        // The comp car: the vehicle and DTI buses, every message but DTI_Flags, for 2 s.
        for meta in MESSAGES.iter().copied() {
            let on_this_car = meta.buses.iter().any(|b| *b != "bench-inverter");
            if on_this_car && meta.name != DtiFlags::META.name && meta.timeout_ms.is_some() {
                arrivals.message(meta, 1_000_000);
                arrivals.message(meta, 3_000_000);
            }
        }
        arrivals.packet(1_000_000);
        let missing: Vec<&str> = arrivals.missing(&MESSAGES).iter().map(|m| m.name).collect();
        assert_eq!(missing, [DtiFlags::META.name], "only DTI_Flags is missing");
        let problem = arrivals.problem(&MESSAGES).expect("a problem");
        assert!(problem.contains("DTI_Flags (from DTI, every "), "{problem}");
        let flags: Vec<&str> = mirroring(&[DtiFlags::META]);
        assert!(!flags.is_empty(), "telemetry mirrors DTI_Flags");
        for field in flags {
            assert!(problem.contains(field), "{field} named in {problem}");
        }
        assert!(
            !problem.contains("MCU1"),
            "the IFL100's bus is not on this car: {problem}"
        );
    }

    #[test]
    fn nothing_is_missing_before_its_freshness_limit_has_passed() {
        let mut arrivals = Arrivals::default();
        arrivals.message(OrionPackStatus::META, 1_000_000);
        arrivals.packet(1_000_000);
        let limit_us = u64::from(DtiFlags::META.timeout_ms.unwrap_or(0)) * 1_000;
        arrivals.message(DtiTemperatures::META, 1_000_000);
        arrivals.message(CcmStatus::META, 1_000_000 + limit_us);
        // DTI_Flags shares the DTI bus: not yet overdue at exactly its limit.
        let overdue: Vec<&str> = arrivals
            .missing(&[DtiFlags::META])
            .iter()
            .map(|m| m.name)
            .collect();
        assert!(overdue.is_empty(), "{overdue:?}");
        arrivals.message(CcmStatus::META, 1_000_001 + limit_us);
        assert_eq!(arrivals.missing(&[DtiFlags::META]).len(), 1);
        // A bus this car does not have: never missing.
        assert!(arrivals.missing(&[Mcu1::META]).is_empty());
    }

    #[test]
    fn no_telemetry_at_all_is_named() {
        let mut arrivals = Arrivals::default();
        arrivals.message(ImdInfoGeneral::META, 0);
        assert_eq!(arrivals.problem(&[ImdInfoGeneral::META]), None);
        arrivals.message(
            ImdInfoGeneral::META,
            u64::from(Telemetry::TIMEOUT_MS) * 1_000 + 1,
        );
        let problem = arrivals
            .problem(&[ImdInfoGeneral::META])
            .expect("a problem");
        assert!(problem.contains("the telemetry packet"), "{problem}");
    }
}
