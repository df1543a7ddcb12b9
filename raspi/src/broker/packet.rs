//! Just enough MQTT 3.1.1 for the gate: split a byte stream into packets, read a CONNECT
//! (client id, will, credentials, keep-alive) and write it back changed, and read a PUBLISH's
//! topic. Every length is checked against the bytes present; bad input is a typed error.

use thiserror::Error;

/// The largest packet the gate passes (the broker's own limit is lower).
pub(crate) const MAX_PACKET: usize = 1 << 20;

pub(crate) const CONNECT: u8 = 1;
pub(crate) const CONNACK: u8 = 2;
pub(crate) const PUBLISH: u8 = 3;

/// Why bytes are not the MQTT the gate accepts.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum PacketError {
    #[error("remaining length longer than 4 bytes")]
    Length,
    #[error("packet of {0} bytes is over the limit")]
    TooLarge(usize),
    #[error("packet cut short")]
    Short,
    #[error("not MQTT 3.1.1 (protocol {name:?} level {level})")]
    Protocol { name: String, level: u8 },
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

struct Reader<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    fn u8(&mut self) -> Result<u8, PacketError> {
        let byte = *self.bytes.get(self.pos).ok_or(PacketError::Short)?;
        self.pos += 1;
        Ok(byte)
    }

    fn u16(&mut self) -> Result<u16, PacketError> {
        Ok(u16::from_be_bytes([self.u8()?, self.u8()?]))
    }

    fn binary(&mut self) -> Result<&'a [u8], PacketError> {
        let len = usize::from(self.u16()?);
        let bytes = self
            .bytes
            .get(self.pos..self.pos + len)
            .ok_or(PacketError::Short)?;
        self.pos += len;
        Ok(bytes)
    }

    fn string(&mut self) -> Result<String, PacketError> {
        String::from_utf8(self.binary()?.to_vec()).map_err(|_| PacketError::Utf8)
    }
}

/// A CONNECT's fields.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Connect {
    pub client_id: String,
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
        if name != "MQTT" || level != 4 {
            return Err(PacketError::Protocol { name, level });
        }
        let flags = r.u8()?;
        if flags & 0x01 != 0 {
            return Err(PacketError::Reserved);
        }
        let keep_alive_s = r.u16()?;
        let client_id = r.string()?;
        let will = if flags & 0x04 != 0 {
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
            client_id,
            clean_session: flags & 0x02 != 0,
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

fn put_binary(out: &mut Vec<u8>, bytes: &[u8]) {
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
        let mut v5 = sample().encode();
        v5[8] = 5;
        assert!(matches!(
            Connect::parse(&v5),
            Err(PacketError::Protocol { level: 5, .. })
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
