//! candump log lines (`candump -l` / `-L`): `(1700000000.010123) can0 666#1042...`.
//!
//! Every malformed line is a typed error with its reason; the reader counts it and goes on.

use embedded_can::{ExtendedId, Id, StandardId};
use thiserror::Error;

/// One classic CAN frame as logged or received.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LoggedFrame {
    /// Receive time, microseconds since the Unix epoch.
    pub ts_us: u64,
    /// Index of the bus in the configured list (0 = first interface seen).
    pub bus: u8,
    /// Identifier.
    pub id: Id,
    /// Payload length (0..=8).
    pub len: u8,
    /// Payload, zero-padded.
    pub data: [u8; 8],
}

impl LoggedFrame {
    /// The payload bytes.
    pub fn payload(&self) -> &[u8] {
        self.data.get(..usize::from(self.len)).unwrap_or(&self.data)
    }

    /// A frame from its parts; `None` for payloads over 8 bytes.
    pub fn new(ts_us: u64, bus: u8, id: Id, payload: &[u8]) -> Option<Self> {
        let mut data = [0u8; 8];
        data.get_mut(..payload.len())?.copy_from_slice(payload);
        Some(Self {
            ts_us,
            bus,
            id,
            len: u8::try_from(payload.len()).ok()?,
            data,
        })
    }

    /// The line `candump -l` would write, with `interface` as the interface name.
    pub fn to_line(&self, interface: &str) -> String {
        let id = match self.id {
            Id::Standard(id) => format!("{:03X}", id.as_raw()),
            Id::Extended(id) => format!("{:08X}", id.as_raw()),
        };
        let data: String = self.payload().iter().map(|b| format!("{b:02X}")).collect();
        format!(
            "({}.{:06}) {interface} {id}#{data}",
            self.ts_us / 1_000_000,
            self.ts_us % 1_000_000
        )
    }
}

/// Why a log line was not a frame.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum LineError {
    /// Not `(seconds.micros) interface id#data`.
    #[error("not a candump -l line (expected `(sec.usec) iface id#data`)")]
    Shape,
    /// The timestamp is not `seconds.microseconds`.
    #[error("bad timestamp `{0}`")]
    Timestamp(String),
    /// The identifier is not 3 (standard) or 8 (extended) hex digits, or out of range.
    #[error("bad identifier `{0}`")]
    Identifier(String),
    /// The data is not an even number of hex digits, or longer than 8 bytes.
    #[error("bad data `{0}`")]
    Data(String),
    /// Remote frames carry no payload for us.
    #[error("remote frame")]
    Remote,
    /// CAN FD frames (`##`) are not on the car's buses.
    #[error("CAN FD frame")]
    Fd,
}

/// Parses one line; `interface_index` maps the interface name to a bus number.
pub fn parse_line(
    line: &str,
    interface_index: impl FnOnce(&str) -> u8,
) -> Result<LoggedFrame, LineError> {
    let mut parts = line.split_whitespace();
    let (Some(stamp), Some(interface), Some(frame)) = (parts.next(), parts.next(), parts.next())
    else {
        return Err(LineError::Shape);
    };
    let stamp = stamp
        .strip_prefix('(')
        .and_then(|s| s.strip_suffix(')'))
        .ok_or(LineError::Shape)?;
    let ts_us = parse_timestamp(stamp).ok_or_else(|| LineError::Timestamp(stamp.to_owned()))?;
    if frame.contains("##") {
        return Err(LineError::Fd);
    }
    let (id_text, data_text) = frame.split_once('#').ok_or(LineError::Shape)?;
    let id = parse_id(id_text).ok_or_else(|| LineError::Identifier(id_text.to_owned()))?;
    if data_text.starts_with('R') {
        return Err(LineError::Remote);
    }
    let bad_data = || LineError::Data(data_text.to_owned());
    if data_text.len() % 2 != 0 || data_text.len() > 16 {
        return Err(bad_data());
    }
    let mut data = [0u8; 8];
    for (slot, pair) in data.iter_mut().zip(data_text.as_bytes().chunks(2)) {
        let text = std::str::from_utf8(pair).map_err(|_| bad_data())?;
        *slot = u8::from_str_radix(text, 16).map_err(|_| bad_data())?;
    }
    Ok(LoggedFrame {
        ts_us,
        bus: interface_index(interface),
        id,
        len: u8::try_from(data_text.len() / 2).map_err(|_| bad_data())?,
        data,
    })
}

fn parse_timestamp(stamp: &str) -> Option<u64> {
    let (seconds, micros) = stamp.split_once('.')?;
    if micros.len() != 6 {
        return None;
    }
    let seconds: u64 = seconds.parse().ok()?;
    let micros: u64 = micros.parse().ok()?;
    seconds.checked_mul(1_000_000)?.checked_add(micros)
}

fn parse_id(text: &str) -> Option<Id> {
    let raw = u32::from_str_radix(text, 16).ok()?;
    match text.len() {
        3 => StandardId::new(u16::try_from(raw).ok()?).map(Id::Standard),
        8 => ExtendedId::new(raw).map(Id::Extended),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(line: &str) -> Result<LoggedFrame, LineError> {
        parse_line(line, |name| u8::from(name == "can1"))
    }

    #[test]
    fn standard_and_extended_frames_parse() {
        let frame = parse("(1700000000.010123) can0 666#1042AABB").unwrap();
        assert_eq!(frame.ts_us, 1_700_000_000_010_123);
        assert_eq!(frame.bus, 0);
        assert_eq!(frame.id, Id::Standard(StandardId::new(0x666).unwrap()));
        assert_eq!(frame.payload(), &[0x10, 0x42, 0xAA, 0xBB]);
        let frame = parse("(1700000000.000001) can1 18FF01F4#0102030405060708").unwrap();
        assert_eq!(frame.bus, 1);
        assert_eq!(
            frame.id,
            Id::Extended(ExtendedId::new(0x18FF_01F4).unwrap())
        );
        assert_eq!(
            frame.to_line("can1"),
            "(1700000000.000001) can1 18FF01F4#0102030405060708"
        );
        assert_eq!(
            parse("(1.000000) can0 123#").unwrap().payload(),
            &[] as &[u8]
        );
    }

    #[test]
    fn every_malformed_line_has_a_reason() {
        assert_eq!(parse(""), Err(LineError::Shape));
        assert_eq!(parse("(1700000000.010123) can0"), Err(LineError::Shape));
        assert_eq!(
            parse("1700000000.010123 can0 123#00"),
            Err(LineError::Shape)
        );
        assert!(matches!(
            parse("(17x.000000) can0 123#00"),
            Err(LineError::Timestamp(_))
        ));
        assert!(matches!(
            parse("(17.00) can0 123#00"),
            Err(LineError::Timestamp(_))
        ));
        assert!(matches!(
            parse("(1.000000) can0 12#00"),
            Err(LineError::Identifier(_))
        ));
        assert!(parse("(1.000000) can0 7FF#00").is_ok());
        assert!(matches!(
            parse("(1.000000) can0 FFF#00"),
            Err(LineError::Identifier(_))
        ));
        assert!(matches!(
            parse("(1.000000) can0 2FFFFFFF#00"),
            Err(LineError::Identifier(_))
        ));
        assert!(matches!(
            parse("(1.000000) can0 123#0"),
            Err(LineError::Data(_))
        ));
        assert!(matches!(
            parse("(1.000000) can0 123#GG"),
            Err(LineError::Data(_))
        ));
        assert!(matches!(
            parse("(1.000000) can0 123#000102030405060708"),
            Err(LineError::Data(_))
        ));
        assert_eq!(parse("(1.000000) can0 123#R"), Err(LineError::Remote));
        assert_eq!(parse("(1.000000) can0 123##1AA"), Err(LineError::Fd));
    }
}
