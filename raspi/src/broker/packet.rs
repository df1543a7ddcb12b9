//! Just enough MQTT for the gate: split a byte stream into packets, read a CONNECT of MQTT
//! 3.1.1 or 5 (client id, will, credentials, keep-alive) and write it as 3.1.1 for the broker,
//! read a PUBLISH's topic, and answer a client in its own version. Every length is checked
//! against the bytes present; bad input is a typed error.

use thiserror::Error;

/// The largest packet the gate passes (the broker's own limit is lower).
pub(crate) const MAX_PACKET: usize = 1 << 20;

pub(crate) const CONNECT: u8 = 1;
pub(crate) const CONNACK: u8 = 2;
pub(crate) const PUBLISH: u8 = 3;
pub(crate) const PUBACK: u8 = 4;
pub(crate) const PUBREC: u8 = 5;
pub(crate) const PUBREL: u8 = 6;
pub(crate) const PUBCOMP: u8 = 7;
pub(crate) const SUBSCRIBE: u8 = 8;
pub(crate) const SUBACK: u8 = 9;
pub(crate) const UNSUBSCRIBE: u8 = 10;
pub(crate) const UNSUBACK: u8 = 11;
pub(crate) const PINGREQ: u8 = 12;
pub(crate) const DISCONNECT: u8 = 14;
pub(crate) const AUTH: u8 = 15;

/// The MQTT versions the gate serves (the broker behind it speaks 3.1.1 only).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Version {
    V311,
    V5,
}

impl Version {
    /// As the status names it.
    pub fn name(self) -> &'static str {
        match self {
            Self::V311 => "3.1.1",
            Self::V5 => "5",
        }
    }
}

/// Why the gate refuses a connection, answered in the client's version.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refusal {
    /// A client id the service keeps for itself.
    IdRejected,
    BadCredentials,
    /// No TLS on a TLS listener, or a will under the service's topics.
    NotAuthorised,
    /// At the connection limit with no stalled client to make room.
    Busy,
    /// The broker did not answer.
    Unavailable,
}

/// Why bytes are not the MQTT the gate accepts.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum PacketError {
    #[error("remaining length longer than 4 bytes")]
    Length,
    #[error("packet of {0} bytes is over the limit")]
    TooLarge(usize),
    #[error("packet cut short")]
    Short,
    #[error("not MQTT 3.1.1 or 5 (protocol {name:?} level {level})")]
    Protocol { name: String, level: u8 },
    #[error("variable byte integer longer than 4 bytes")]
    VarInt,
    #[error("unknown MQTT 5 property {0:#04x}")]
    Property(u8),
    #[error("a topic alias (the gate offers none: Topic Alias Maximum 0)")]
    TopicAlias,
    #[error("enhanced authentication (AUTH) is not served; use username and password")]
    EnhancedAuth,
    #[error("packet type {0} not expected from a client")]
    Unexpected(u8),
    #[error("string not UTF-8")]
    Utf8,
    #[error("reserved flag set")]
    Reserved,
}

/// The packet at the start of `buf`: its type and whole length, once all of it has arrived
/// (`Ok(None)` until then).
pub fn frame(buf: &[u8]) -> Result<Option<(u8, usize)>, PacketError> {
    let Some(&first) = buf.first() else {
        return Ok(None);
    };
    let mut remaining = 0usize;
    for i in 0..4 {
        let Some(&byte) = buf.get(1 + i) else {
            return Ok(None);
        };
        remaining |= usize::from(byte & 0x7F) << (7 * i);
        if byte & 0x80 == 0 {
            let total = 2 + i + remaining;
            if total > MAX_PACKET {
                return Err(PacketError::TooLarge(total));
            }
            return Ok((buf.len() >= total).then_some((first >> 4, total)));
        }
    }
    Err(PacketError::Length)
}

/// The bytes after the fixed header of a whole packet.
fn body(packet: &[u8]) -> Result<&[u8], PacketError> {
    let header = 1
        + packet
            .iter()
            .skip(1)
            .take(4)
            .position(|b| b & 0x80 == 0)
            .ok_or(PacketError::Length)?
        + 1;
    packet.get(header..).ok_or(PacketError::Short)
}

/// Reads a packet's fields in order; every read is checked against the bytes present.
pub(crate) struct Reader<'a> {
    bytes: &'a [u8],
    pos: usize,
}

/// A whole packet's first byte, and a reader over what follows the fixed header.
pub(crate) fn open(packet: &[u8]) -> Result<(u8, Reader<'_>), PacketError> {
    let first = *packet.first().ok_or(PacketError::Short)?;
    Ok((
        first,
        Reader {
            bytes: body(packet)?,
            pos: 0,
        },
    ))
}

impl<'a> Reader<'a> {
    pub(crate) fn u8(&mut self) -> Result<u8, PacketError> {
        let byte = *self.bytes.get(self.pos).ok_or(PacketError::Short)?;
        self.pos += 1;
        Ok(byte)
    }

    pub(crate) fn u16(&mut self) -> Result<u16, PacketError> {
        Ok(u16::from_be_bytes([self.u8()?, self.u8()?]))
    }

    pub(crate) fn binary(&mut self) -> Result<&'a [u8], PacketError> {
        let len = usize::from(self.u16()?);
        let bytes = self
            .bytes
            .get(self.pos..self.pos + len)
            .ok_or(PacketError::Short)?;
        self.pos += len;
        Ok(bytes)
    }

    pub(crate) fn string(&mut self) -> Result<String, PacketError> {
        String::from_utf8(self.binary()?.to_vec()).map_err(|_| PacketError::Utf8)
    }

    pub(crate) fn take(&mut self, len: usize) -> Result<&'a [u8], PacketError> {
        let bytes = self
            .bytes
            .get(self.pos..self.pos.saturating_add(len))
            .ok_or(PacketError::Short)?;
        self.pos += len;
        Ok(bytes)
    }

    pub(crate) fn rest(&self) -> &'a [u8] {
        self.bytes.get(self.pos..).unwrap_or_default()
    }

    pub(crate) fn at_end(&self) -> bool {
        self.pos >= self.bytes.len()
    }

    pub(crate) fn varint(&mut self) -> Result<usize, PacketError> {
        let mut value = 0usize;
        for i in 0..4 {
            let byte = self.u8()?;
            value |= usize::from(byte & 0x7F) << (7 * i);
            if byte & 0x80 == 0 {
                return Ok(value);
            }
        }
        Err(PacketError::VarInt)
    }

    /// An MQTT 5 property list: the few properties the gate acts on; every other one is
    /// checked for its length and skipped.
    pub(crate) fn properties(&mut self) -> Result<Properties, PacketError> {
        let len = self.varint()?;
        let mut list = Reader {
            bytes: self.take(len)?,
            pos: 0,
        };
        let mut found = Properties::default();
        while !list.at_end() {
            let id = list.u8()?;
            match id {
                // Byte properties.
                0x01 | 0x17 | 0x19 | 0x24 | 0x25 | 0x28 | 0x29 | 0x2A => {
                    list.u8()?;
                }
                0x11 => found.session_expiry_s = Some(u32::from_be_bytes(array(list.take(4)?)?)),
                // Four-byte integers.
                0x02 | 0x18 | 0x27 => {
                    list.take(4)?;
                }
                0x0B => {
                    list.varint()?;
                }
                0x23 => found.topic_alias = Some(list.u16()?),
                // Two-byte integers.
                0x13 | 0x21 | 0x22 => {
                    list.u16()?;
                }
                0x15 => {
                    list.binary()?;
                    found.authentication = true;
                }
                // Strings and binary data.
                0x03 | 0x08 | 0x09 | 0x12 | 0x16 | 0x1A | 0x1C | 0x1F => {
                    list.binary()?;
                }
                // A user property: a string pair.
                0x26 => {
                    list.binary()?;
                    list.binary()?;
                }
                other => return Err(PacketError::Property(other)),
            }
        }
        Ok(found)
    }
}

fn array<const N: usize>(bytes: &[u8]) -> Result<[u8; N], PacketError> {
    bytes.try_into().map_err(|_| PacketError::Short)
}

/// The MQTT 5 properties the gate acts on.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Properties {
    pub session_expiry_s: Option<u32>,
    pub topic_alias: Option<u16>,
    /// An Authentication Method: enhanced authentication, which the gate does not serve.
    pub authentication: bool,
}

/// A CONNECT's fields.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Connect {
    /// The client's version; [`Connect::encode`] always writes 3.1.1, for the broker.
    pub version: Version,
    pub client_id: String,
    /// MQTT 3.1.1's clean session. An MQTT 5 client's is its clean start, or a session that
    /// ends with the connection (no Session Expiry Interval): both start afresh.
    pub clean_session: bool,
    pub keep_alive_s: u16,
    /// Topic, message, QoS, retain.
    pub will: Option<(String, Vec<u8>, u8, bool)>,
    pub username: Option<String>,
    pub password: Option<Vec<u8>>,
}

impl Connect {
    /// Reads a whole CONNECT packet.
    pub fn parse(packet: &[u8]) -> Result<Self, PacketError> {
        let mut r = Reader {
            bytes: body(packet)?,
            pos: 0,
        };
        let name = r.string()?;
        let level = r.u8()?;
        let version = match (name.as_str(), level) {
            ("MQTT", 4) => Version::V311,
            ("MQTT", 5) => Version::V5,
            _ => return Err(PacketError::Protocol { name, level }),
        };
        let flags = r.u8()?;
        if flags & 0x01 != 0 {
            return Err(PacketError::Reserved);
        }
        let keep_alive_s = r.u16()?;
        let mut clean_session = flags & 0x02 != 0;
        if version == Version::V5 {
            let properties = r.properties()?;
            if properties.authentication {
                return Err(PacketError::EnhancedAuth);
            }
            clean_session |= properties.session_expiry_s.unwrap_or(0) == 0;
        }
        let client_id = r.string()?;
        let will = if flags & 0x04 != 0 {
            if version == Version::V5 {
                // The will's own properties (delay, expiry, content type): not kept.
                r.properties()?;
            }
            let topic = r.string()?;
            let message = r.binary()?.to_vec();
            Some((topic, message, (flags >> 3) & 0x03, flags & 0x20 != 0))
        } else {
            None
        };
        let username = (flags & 0x80 != 0).then(|| r.string()).transpose()?;
        let password = (flags & 0x40 != 0)
            .then(|| r.binary().map(<[u8]>::to_vec))
            .transpose()?;
        Ok(Self {
            version,
            client_id,
            clean_session,
            keep_alive_s,
            will,
            username,
            password,
        })
    }

    /// The packet for these fields.
    pub fn encode(&self) -> Vec<u8> {
        let mut body = Vec::new();
        put_binary(&mut body, b"MQTT");
        body.push(4);
        let mut flags = 0u8;
        if self.clean_session {
            flags |= 0x02;
        }
        if let Some((_, _, qos, retain)) = &self.will {
            flags |= 0x04 | ((qos & 0x03) << 3);
            if *retain {
                flags |= 0x20;
            }
        }
        if self.password.is_some() {
            flags |= 0x40;
        }
        if self.username.is_some() {
            flags |= 0x80;
        }
        body.push(flags);
        body.extend_from_slice(&self.keep_alive_s.to_be_bytes());
        put_binary(&mut body, self.client_id.as_bytes());
        if let Some((topic, message, _, _)) = &self.will {
            put_binary(&mut body, topic.as_bytes());
            put_binary(&mut body, message);
        }
        if let Some(username) = &self.username {
            put_binary(&mut body, username.as_bytes());
        }
        if let Some(password) = &self.password {
            put_binary(&mut body, password);
        }
        with_header(CONNECT << 4, &body)
    }
}

/// A PUBLISH packet's topic.
pub(crate) fn publish_topic(packet: &[u8]) -> Result<String, PacketError> {
    Reader {
        bytes: body(packet)?,
        pos: 0,
    }
    .string()
}

/// CONNACK with `code` (0 accepted, 4 bad credentials, 5 not authorised).
pub fn connack(code: u8) -> [u8; 4] {
    [0x20, 2, 0, code]
}

/// The CONNACK refusing a client of `version` for `why`, with the code its version defines.
pub fn refusal(version: Version, why: Refusal) -> Vec<u8> {
    match version {
        Version::V311 => connack(match why {
            Refusal::IdRejected => 2,
            Refusal::Busy | Refusal::Unavailable => 3,
            Refusal::BadCredentials => 4,
            Refusal::NotAuthorised => 5,
        })
        .to_vec(),
        Version::V5 => {
            let reason = match why {
                Refusal::IdRejected => 0x85,
                Refusal::BadCredentials => 0x86,
                Refusal::NotAuthorised => 0x87,
                Refusal::Unavailable => 0x88,
                Refusal::Busy => 0x89,
            };
            vec![0x20, 3, 0, reason, 0]
        }
    }
}

/// The refusal a client of protocol `level` understands when the gate does not serve its
/// version: MQTT 5 defines a CONNACK with reason 0x84 (unsupported protocol version) and an
/// empty property list; 3.1 and 3.1.1 define return code 1 (unacceptable protocol version).
pub fn unsupported_version(level: u8) -> Vec<u8> {
    if level >= 5 {
        vec![0x20, 3, 0, 0x84, 0]
    } else {
        connack(1).to_vec()
    }
}

pub(crate) fn put_binary(out: &mut Vec<u8>, bytes: &[u8]) {
    let len = u16::try_from(bytes.len()).unwrap_or(u16::MAX);
    out.extend_from_slice(&len.to_be_bytes());
    out.extend_from_slice(bytes.get(..usize::from(len)).unwrap_or(bytes));
}

/// A packet: `first` byte, remaining length, `body`.
pub fn with_header(first: u8, body: &[u8]) -> Vec<u8> {
    let mut packet = vec![first];
    let mut len = body.len();
    loop {
        let mut byte = (len & 0x7F) as u8;
        len >>= 7;
        if len > 0 {
            byte |= 0x80;
        }
        packet.push(byte);
        if len == 0 {
            break;
        }
    }
    packet.extend_from_slice(body);
    packet
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Connect {
        Connect {
            version: Version::V311,
            client_id: "dash-1".into(),
            clean_session: true,
            keep_alive_s: 30,
            will: Some(("bye".into(), b"gone".to_vec(), 1, true)),
            username: Some("pit".into()),
            password: Some(b"Xq7-fast-laps".to_vec()),
        }
    }

    #[test]
    fn a_connect_reads_back_what_was_written() {
        let packet = sample().encode();
        assert_eq!(frame(&packet), Ok(Some((CONNECT, packet.len()))));
        assert_eq!(Connect::parse(&packet), Ok(sample()));
        let bare = Connect {
            will: None,
            username: None,
            password: None,
            ..sample()
        };
        assert_eq!(Connect::parse(&bare.encode()), Ok(bare));
    }

    #[test]
    fn packets_are_framed_only_once_whole() {
        let publish = with_header(PUBLISH << 4, &[0, 3, b'a', b'/', b'b', 1, 2, 3]);
        assert_eq!(frame(&publish[..4]), Ok(None));
        assert_eq!(frame(&publish), Ok(Some((PUBLISH, publish.len()))));
        assert_eq!(publish_topic(&publish).as_deref(), Ok("a/b"));
        let big = with_header(PUBLISH << 4, &vec![0; 300]);
        assert_eq!(big[1..3], [0xAC, 0x02], "two-byte remaining length");
        assert_eq!(frame(&big), Ok(Some((PUBLISH, big.len()))));
        assert_eq!(
            frame(&[0x30, 0xFF, 0xFF, 0xFF, 0xFF, 0x01]),
            Err(PacketError::Length)
        );
        assert!(matches!(
            frame(&[0x30, 0xFF, 0xFF, 0xFF, 0x7F]),
            Err(PacketError::TooLarge(_))
        ));
    }

    #[test]
    fn other_protocols_and_broken_packets_are_refused() {
        let mut v6 = sample().encode();
        v6[8] = 6;
        assert!(matches!(
            Connect::parse(&v6),
            Err(PacketError::Protocol { level: 6, .. })
        ));
        let mut v31 = sample().encode();
        v31[8] = 3;
        assert!(matches!(
            Connect::parse(&v31),
            Err(PacketError::Protocol { level: 3, .. })
        ));
        let packet = sample().encode();
        assert_eq!(
            Connect::parse(&packet[..packet.len() - 3]),
            Err(PacketError::Short)
        );
    }

    proptest::proptest! {
        /// Any bytes give a packet or a typed error, never a panic.
        #[test]
        fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..64)) {
            let _ = frame(&bytes);
            let _ = Connect::parse(&bytes);
            let _ = publish_topic(&bytes);
        }
    }
}
