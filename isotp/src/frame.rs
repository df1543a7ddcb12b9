//! Protocol control information (the first one or two bytes of every ISO-TP frame).

/// A frame's payload as it goes on the bus: up to 8 bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Frame {
    bytes: [u8; 8],
    len: u8,
}

impl Frame {
    /// Builds a frame from `head` (PCI bytes) and `data`, padded to 8 bytes if asked.
    pub(crate) fn build(head: &[u8], data: &[u8], padding: Option<u8>) -> Self {
        let mut bytes = [padding.unwrap_or(0); 8];
        let mut len = 0usize;
        for (slot, byte) in bytes.iter_mut().zip(head.iter().chain(data)) {
            *slot = *byte;
            len += 1;
        }
        if padding.is_some() {
            len = 8;
        }
        Self {
            bytes,
            len: u8::try_from(len).unwrap_or(8),
        }
    }

    /// The bytes to put in the CAN frame.
    pub fn as_slice(&self) -> &[u8] {
        self.bytes
            .get(..usize::from(self.len))
            .unwrap_or(&self.bytes)
    }
}

/// Minimum separation time between consecutive frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StMin(u8);

impl StMin {
    /// No gap.
    pub const ZERO: Self = Self(0);

    /// The raw byte as sent in flow control.
    pub const fn raw(self) -> u8 {
        self.0
    }

    /// From the raw byte; reserved values mean the longest gap, 127 ms (ISO 15765-2).
    pub const fn from_raw(raw: u8) -> Self {
        Self(raw)
    }

    /// A gap of `ms` milliseconds (0..=127).
    pub const fn from_millis(ms: u8) -> Self {
        Self(if ms > 0x7F { 0x7F } else { ms })
    }

    /// The gap in microseconds.
    pub const fn micros(self) -> u32 {
        match self.0 {
            0x00..=0x7F => self.0 as u32 * 1_000,
            0xF1..=0xF9 => (self.0 - 0xF0) as u32 * 100,
            _ => 127_000,
        }
    }
}

/// Flow status of a flow-control frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FlowStatus {
    /// Continue to send.
    ContinueToSend,
    /// Wait for the next flow control.
    Wait,
    /// The receiver cannot take a message this long.
    Overflow,
}

/// What a frame's PCI says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pci<'a> {
    /// A whole message in one frame.
    Single(&'a [u8]),
    /// The start of a segmented message of `length` bytes.
    First {
        /// Announced total length.
        length: u16,
        /// The first 6 payload bytes.
        data: &'a [u8],
    },
    /// A continuation with its 4-bit sequence number.
    Consecutive {
        /// Sequence number (1, 2, ... 15, 0, 1, ...).
        sequence: u8,
        /// Up to 7 payload bytes (the last frame's padding included).
        data: &'a [u8],
    },
    /// Flow control from the receiver.
    FlowControl {
        /// Continue, wait or overflow.
        status: FlowStatus,
        /// Consecutive frames before the next flow control (0 = no limit).
        block_size: u8,
        /// Gap between consecutive frames.
        st_min: StMin,
    },
}

/// Why a frame is not valid ISO-TP.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameError {
    /// No bytes at all.
    Empty,
    /// PCI type 4..=15 is not defined for classic CAN.
    UnknownType(u8),
    /// A single frame announcing 0 or more than 7 bytes, or more than the frame holds.
    BadSingleLength(u8),
    /// A first frame announcing fewer than 8 bytes (those fit a single frame), or too short.
    BadFirstFrame(u16),
    /// A flow control with an undefined flow status, or too short.
    BadFlowControl(u8),
}

/// Reads the PCI of a received frame's payload.
pub fn parse(data: &[u8]) -> Result<Pci<'_>, FrameError> {
    let (&head, rest) = data.split_first().ok_or(FrameError::Empty)?;
    let low = head & 0x0F;
    match head >> 4 {
        0 => {
            let len = usize::from(low);
            match rest.get(..len) {
                Some(payload) if len > 0 => Ok(Pci::Single(payload)),
                _ => Err(FrameError::BadSingleLength(low)),
            }
        }
        1 => {
            let (&second, data) = rest.split_first().ok_or(FrameError::BadFirstFrame(0))?;
            let length = u16::from(low) << 8 | u16::from(second);
            if length < 8 || data.is_empty() {
                return Err(FrameError::BadFirstFrame(length));
            }
            Ok(Pci::First { length, data })
        }
        2 => Ok(Pci::Consecutive {
            sequence: low,
            data: rest,
        }),
        3 => {
            let status = match low {
                0 => FlowStatus::ContinueToSend,
                1 => FlowStatus::Wait,
                2 => FlowStatus::Overflow,
                other => return Err(FrameError::BadFlowControl(other)),
            };
            let [block_size, st_min, ..] = *rest else {
                return Err(FrameError::BadFlowControl(low));
            };
            Ok(Pci::FlowControl {
                status,
                block_size,
                st_min: StMin::from_raw(st_min),
            })
        }
        other => Err(FrameError::UnknownType(other)),
    }
}

/// A flow-control frame.
pub(crate) fn flow_control(
    status: FlowStatus,
    block_size: u8,
    st_min: StMin,
    padding: Option<u8>,
) -> Frame {
    let code = match status {
        FlowStatus::ContinueToSend => 0x30,
        FlowStatus::Wait => 0x31,
        FlowStatus::Overflow => 0x32,
    };
    Frame::build(&[code, block_size, st_min.raw()], &[], padding)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn st_min_covers_milliseconds_microseconds_and_reserved_values() {
        assert_eq!(StMin::from_raw(0x00).micros(), 0);
        assert_eq!(StMin::from_raw(0x7F).micros(), 127_000);
        assert_eq!(StMin::from_raw(0xF1).micros(), 100);
        assert_eq!(StMin::from_raw(0xF9).micros(), 900);
        assert_eq!(StMin::from_raw(0x80).micros(), 127_000);
        assert_eq!(StMin::from_raw(0xFA).micros(), 127_000);
        assert_eq!(StMin::from_millis(200), StMin::from_raw(0x7F));
    }

    #[test]
    fn every_pci_type_parses() {
        assert_eq!(parse(&[0x03, 1, 2, 3, 0xCC]), Ok(Pci::Single(&[1, 2, 3])));
        assert_eq!(
            parse(&[0x10, 0x3E, 1, 2, 3, 4, 5, 6]),
            Ok(Pci::First {
                length: 62,
                data: &[1, 2, 3, 4, 5, 6]
            })
        );
        assert_eq!(
            parse(&[0x2F, 9]),
            Ok(Pci::Consecutive {
                sequence: 15,
                data: &[9]
            })
        );
        assert_eq!(
            parse(&[0x30, 4, 0xF5]),
            Ok(Pci::FlowControl {
                status: FlowStatus::ContinueToSend,
                block_size: 4,
                st_min: StMin::from_raw(0xF5)
            })
        );
    }

    #[test]
    fn malformed_frames_are_refused_with_a_reason() {
        assert_eq!(parse(&[]), Err(FrameError::Empty));
        assert_eq!(parse(&[0x00]), Err(FrameError::BadSingleLength(0)));
        assert_eq!(parse(&[0x05, 1, 2]), Err(FrameError::BadSingleLength(5)));
        assert_eq!(
            parse(&[0x10, 0x07, 1, 2, 3, 4, 5, 6]),
            Err(FrameError::BadFirstFrame(7))
        );
        assert_eq!(parse(&[0x10]), Err(FrameError::BadFirstFrame(0)));
        assert_eq!(parse(&[0x33, 0, 0]), Err(FrameError::BadFlowControl(3)));
        assert_eq!(parse(&[0x30, 0]), Err(FrameError::BadFlowControl(0)));
        assert_eq!(parse(&[0x40]), Err(FrameError::UnknownType(4)));
    }

    #[test]
    fn frames_are_padded_only_when_asked() {
        let padded = Frame::build(&[0x02], &[7, 8], Some(0xCC));
        assert_eq!(
            padded.as_slice(),
            &[0x02, 7, 8, 0xCC, 0xCC, 0xCC, 0xCC, 0xCC]
        );
        let bare = Frame::build(&[0x02], &[7, 8], None);
        assert_eq!(bare.as_slice(), &[0x02, 7, 8]);
    }
}
