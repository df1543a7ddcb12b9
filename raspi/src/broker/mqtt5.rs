//! MQTT 5 clients through a 3.1.1 broker: the gate rewrites each packet between the two, so
//! the broker, the access rules and the per-client queue see 3.1.1 only.
//!
//! What an MQTT 5 client gives up: properties are dropped on the way in (user properties,
//! message expiry, subscription identifiers) and none are sent out; the gate offers no topic
//! aliases (CONNACK's Topic Alias Maximum is absent, so 0), and a client that uses one anyway
//! is disconnected; subscription options beyond the QoS (no local, retain handling) are not
//! passed on; enhanced authentication (AUTH) is refused. Reason codes the broker cannot give
//! are success: the broker's 3.1.1 acknowledgements carry none.

use super::packet::{
    self, AUTH, CONNACK, CONNECT, DISCONNECT, PINGREQ, PUBACK, PUBCOMP, PUBLISH, PUBREC, PUBREL,
    PacketError, SUBACK, SUBSCRIBE, UNSUBACK, UNSUBSCRIBE,
};
use std::collections::HashMap;
use std::sync::Mutex;

/// UNSUBSCRIBEs on their way to the broker: how many filters each named, for its UNSUBACK
/// (MQTT 5 answers each filter with a reason code; 3.1.1 with none).
#[derive(Debug, Default)]
pub(crate) struct Unsubscribes {
    filters: Mutex<HashMap<u16, usize>>,
}

/// A client's MQTT 5 packet as MQTT 3.1.1 for the broker.
pub(crate) fn to_broker(packet: &[u8], pending: &Unsubscribes) -> Result<Vec<u8>, PacketError> {
    let (first, mut r) = packet::open(packet)?;
    let kind = first >> 4;
    match kind {
        PUBLISH => {
            let qos = (first >> 1) & 0x03;
            let topic = r.binary()?;
            let id = if qos > 0 { Some(r.take(2)?) } else { None };
            if r.properties()?.topic_alias.is_some() || topic.is_empty() {
                return Err(PacketError::TopicAlias);
            }
            let mut body = Vec::with_capacity(packet.len());
            packet::put_binary(&mut body, topic);
            body.extend_from_slice(id.unwrap_or_default());
            body.extend_from_slice(r.rest());
            Ok(packet::with_header(first, &body))
        }
        // The packet id is what 3.1.1 keeps; a reason code and properties may follow.
        PUBACK | PUBREC | PUBREL | PUBCOMP => Ok(packet::with_header(first, r.take(2)?)),
        SUBSCRIBE => {
            let mut body = r.take(2)?.to_vec();
            r.properties()?;
            while !r.at_end() {
                packet::put_binary(&mut body, r.binary()?);
                body.push(r.u8()? & 0x03);
            }
            Ok(packet::with_header(first, &body))
        }
        UNSUBSCRIBE => {
            let id = r.u16()?;
            let mut body = id.to_be_bytes().to_vec();
            r.properties()?;
            let mut filters = 0;
            while !r.at_end() {
                packet::put_binary(&mut body, r.binary()?);
                filters += 1;
            }
            if let Ok(mut pending) = pending.filters.lock() {
                pending.insert(id, filters);
            }
            Ok(packet::with_header(first, &body))
        }
        PINGREQ => Ok(packet.to_vec()),
        // Whatever its reason code: a will is never sent by the broker anyway once asked by
        // a 3.1.1 DISCONNECT, which is the safe reading of "disconnect with will".
        DISCONNECT => Ok(vec![DISCONNECT << 4, 0]),
        AUTH => Err(PacketError::EnhancedAuth),
        other => Err(PacketError::Unexpected(other)),
    }
}

/// The broker's MQTT 3.1.1 packet as MQTT 5 for the client.
pub(crate) fn to_client(packet: &[u8], pending: &Unsubscribes) -> Result<Vec<u8>, PacketError> {
    let (first, mut r) = packet::open(packet)?;
    match first >> 4 {
        CONNACK => {
            // Session present, then the 3.1.1 return code as its MQTT 5 reason.
            let flags = r.u8()?;
            let reason = match r.u8()? {
                0 => 0,
                1 => 0x84,
                2 => 0x85,
                3 => 0x88,
                4 => 0x86,
                _ => 0x87,
            };
            Ok(vec![first, 3, flags, reason, 0])
        }
        PUBLISH => {
            let qos = (first >> 1) & 0x03;
            let topic = r.binary()?;
            let id = if qos > 0 { Some(r.take(2)?) } else { None };
            let mut body = Vec::with_capacity(packet.len() + 1);
            packet::put_binary(&mut body, topic);
            body.extend_from_slice(id.unwrap_or_default());
            body.push(0);
            body.extend_from_slice(r.rest());
            Ok(packet::with_header(first, &body))
        }
        SUBACK => {
            let mut body = r.take(2)?.to_vec();
            body.push(0);
            // 3.1.1's granted QoS 0-2 and failure 0x80 are MQTT 5 reason codes as they are.
            body.extend_from_slice(r.rest());
            Ok(packet::with_header(first, &body))
        }
        UNSUBACK => {
            let id = r.u16()?;
            let filters = pending
                .filters
                .lock()
                .ok()
                .and_then(|mut pending| pending.remove(&id))
                .unwrap_or(1);
            let mut body = id.to_be_bytes().to_vec();
            body.push(0);
            body.resize(3 + filters, 0);
            Ok(packet::with_header(first, &body))
        }
        CONNECT => Err(PacketError::Unexpected(CONNECT)),
        // PUBACK, PUBREC, PUBREL, PUBCOMP with only a packet id mean success in MQTT 5 too;
        // PINGRESP is the same packet.
        _ => Ok(packet.to_vec()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::broker::packet::{Connect, Version, publish_topic, with_header};

    fn string(out: &mut Vec<u8>, text: &str) {
        out.extend_from_slice(&(text.len() as u16).to_be_bytes());
        out.extend_from_slice(text.as_bytes());
    }

    /// An MQTT 5 CONNECT as a client writes it, with properties everywhere.
    fn connect_v5(clean_start: bool, session_expiry_s: u32) -> Vec<u8> {
        let mut body = Vec::new();
        string(&mut body, "MQTT");
        body.push(5);
        body.push(0x80 | 0x40 | 0x04 | if clean_start { 0x02 } else { 0 });
        body.extend_from_slice(&30u16.to_be_bytes());
        // Session Expiry Interval, Receive Maximum, a user property.
        let mut props = vec![0x11];
        props.extend_from_slice(&session_expiry_s.to_be_bytes());
        props.extend_from_slice(&[0x21, 0, 10, 0x26]);
        string(&mut props, "k");
        string(&mut props, "v");
        body.push(props.len() as u8);
        body.extend_from_slice(&props);
        string(&mut body, "pit-laptop");
        // Will properties (a delay), topic, payload.
        body.extend_from_slice(&[5, 0x18, 0, 0, 0, 9]);
        string(&mut body, "pit/gone");
        string(&mut body, "bye");
        string(&mut body, "pit");
        string(&mut body, "Xq7-fast-laps");
        with_header(CONNECT << 4, &body)
    }

    #[test]
    fn an_mqtt5_connect_becomes_the_same_connect_in_3_1_1() {
        let connect = Connect::parse(&connect_v5(false, 3600)).expect("v5 CONNECT");
        assert_eq!(connect.version, Version::V5);
        assert_eq!(connect.client_id, "pit-laptop");
        assert!(
            !connect.clean_session,
            "a session that outlives the connection"
        );
        assert_eq!(connect.keep_alive_s, 30);
        assert_eq!(connect.username.as_deref(), Some("pit"));
        assert_eq!(connect.password.as_deref(), Some(&b"Xq7-fast-laps"[..]));
        assert_eq!(
            connect
                .will
                .as_ref()
                .map(|(topic, message, ..)| (topic.as_str(), message.as_slice())),
            Some(("pit/gone", &b"bye"[..]))
        );
        let for_broker = Connect::parse(&connect.encode()).expect("3.1.1 CONNECT");
        assert_eq!(for_broker.version, Version::V311);
        assert_eq!(
            Connect {
                version: Version::V5,
                ..for_broker
            },
            connect
        );
        // No Session Expiry Interval: the session ends with the connection, as clean session.
        assert!(
            Connect::parse(&connect_v5(false, 0))
                .expect("v5")
                .clean_session
        );
    }

    #[test]
    fn enhanced_authentication_is_refused() {
        let mut body = Vec::new();
        string(&mut body, "MQTT");
        body.extend_from_slice(&[5, 0x02, 0, 30, 6, 0x15, 0, 3, b'S', b'C', b'R']);
        string(&mut body, "x");
        let packet = with_header(CONNECT << 4, &body);
        assert_eq!(Connect::parse(&packet), Err(PacketError::EnhancedAuth));
    }

    #[test]
    fn a_publish_loses_its_properties_on_the_way_in_and_gains_an_empty_list_on_the_way_out() {
        let pending = Unsubscribes::default();
        // QoS 1, topic, packet id 7, a content type property, payload.
        let mut body = Vec::new();
        string(&mut body, "pit/notes");
        body.extend_from_slice(&[0, 7, 5, 0x03, 0, 2, b'j', b's']);
        body.extend_from_slice(b"{\"lap\":3}");
        let v5 = with_header((PUBLISH << 4) | 0x02, &body);
        let v311 = to_broker(&v5, &pending).expect("publish");
        assert_eq!(publish_topic(&v311).as_deref(), Ok("pit/notes"));
        let mut expected = Vec::new();
        string(&mut expected, "pit/notes");
        expected.extend_from_slice(&[0, 7]);
        expected.extend_from_slice(b"{\"lap\":3}");
        assert_eq!(v311, with_header((PUBLISH << 4) | 0x02, &expected));
        // And back: the same publish with an empty property list.
        let back = to_client(&v311, &pending).expect("publish");
        let mut with_empty = Vec::new();
        string(&mut with_empty, "pit/notes");
        with_empty.extend_from_slice(&[0, 7, 0]);
        with_empty.extend_from_slice(b"{\"lap\":3}");
        assert_eq!(back, with_header((PUBLISH << 4) | 0x02, &with_empty));
    }

    #[test]
    fn a_topic_alias_cannot_hide_a_topic_from_the_access_rules() {
        let pending = Unsubscribes::default();
        let mut body = Vec::new();
        string(&mut body, "");
        body.extend_from_slice(&[3, 0x23, 0, 1]);
        body.extend_from_slice(b"x");
        let aliased = with_header(PUBLISH << 4, &body);
        assert_eq!(to_broker(&aliased, &pending), Err(PacketError::TopicAlias));
    }

    #[test]
    fn subscriptions_and_their_acknowledgements_translate_both_ways() {
        let pending = Unsubscribes::default();
        // SUBSCRIBE id 3, a subscription identifier, two filters with v5-only option bits.
        let mut body = vec![0, 3, 2, 0x0B, 4];
        string(&mut body, "aer/car1/#");
        body.push(0x2C | 1);
        string(&mut body, "aer-pit/car1/stream");
        body.push(0x04);
        let subscribe = to_broker(&with_header(0x82, &body), &pending).expect("subscribe");
        let mut expected = vec![0, 3];
        string(&mut expected, "aer/car1/#");
        expected.push(1);
        string(&mut expected, "aer-pit/car1/stream");
        expected.push(0);
        assert_eq!(subscribe, with_header(0x82, &expected));
        let suback = to_client(&with_header(SUBACK << 4, &[0, 3, 1, 0]), &pending);
        assert_eq!(suback, Ok(with_header(SUBACK << 4, &[0, 3, 0, 1, 0])));

        let mut body = vec![0, 4, 0];
        string(&mut body, "a");
        string(&mut body, "b");
        let unsubscribe = to_broker(&with_header(0xA2, &body), &pending).expect("unsubscribe");
        let mut expected = vec![0, 4];
        string(&mut expected, "a");
        string(&mut expected, "b");
        assert_eq!(unsubscribe, with_header(0xA2, &expected));
        let unsuback = to_client(&with_header(UNSUBACK << 4, &[0, 4]), &pending);
        assert_eq!(
            unsuback,
            Ok(with_header(UNSUBACK << 4, &[0, 4, 0, 0, 0])),
            "one reason code per filter"
        );
    }

    #[test]
    fn acknowledgements_disconnect_and_the_connack() {
        let pending = Unsubscribes::default();
        let puback = with_header(PUBACK << 4, &[0, 9, 0x10, 0]);
        assert_eq!(
            to_broker(&puback, &pending),
            Ok(with_header(PUBACK << 4, &[0, 9]))
        );
        assert_eq!(
            to_broker(&[DISCONNECT << 4, 2, 0x04, 0], &pending),
            Ok(vec![DISCONNECT << 4, 0])
        );
        assert_eq!(
            to_broker(&[AUTH << 4, 0], &pending),
            Err(PacketError::EnhancedAuth)
        );
        assert_eq!(
            to_client(&[CONNACK << 4, 2, 1, 0], &pending),
            Ok(vec![0x20, 3, 1, 0, 0])
        );
        assert_eq!(
            to_client(&[CONNACK << 4, 2, 0, 4], &pending),
            Ok(vec![0x20, 3, 0, 0x86, 0])
        );
    }

    proptest::proptest! {
        /// Any bytes give a packet or a typed error, never a panic.
        #[test]
        fn arbitrary_packets_never_panic(kind in 0u8..16, flags in 0u8..16, body in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..48)) {
            let packet = with_header((kind << 4) | flags, &body);
            let pending = Unsubscribes::default();
            let _ = to_broker(&packet, &pending);
            let _ = to_client(&packet, &pending);
            let _ = Connect::parse(&packet);
        }
    }
}
