//! A classic CAN frame and its message-buffer encoding.
//!
//! A FlexCAN message buffer is four 32-bit words: control/status (code, IDE, RTR, DLC,
//! time stamp), identifier, and the payload as two big-endian words (byte 0 in bits 31-24).

use embedded_can::{ExtendedId, Id, StandardId};

/// A classic CAN frame (up to 8 bytes), as the driver sends and receives it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CanFrame {
    id: Id,
    remote: bool,
    dlc: u8,
    data: [u8; 8],
}

impl CanFrame {
    /// The payload bytes (empty for a remote frame).
    pub fn payload(&self) -> &[u8] {
        if self.remote {
            return &[];
        }
        self.data.get(..usize::from(self.dlc.min(8))).unwrap_or(&[])
    }
}

impl embedded_can::Frame for CanFrame {
    fn new(id: impl Into<Id>, data: &[u8]) -> Option<Self> {
        let mut buffer = [0; 8];
        buffer.get_mut(..data.len())?.copy_from_slice(data);
        Some(Self {
            id: id.into(),
            remote: false,
            dlc: u8::try_from(data.len()).ok()?,
            data: buffer,
        })
    }

    fn new_remote(id: impl Into<Id>, dlc: usize) -> Option<Self> {
        Some(Self {
            id: id.into(),
            remote: true,
            dlc: u8::try_from(dlc).ok().filter(|dlc| *dlc <= 8)?,
            data: [0; 8],
        })
    }

    fn is_extended(&self) -> bool {
        matches!(self.id, Id::Extended(_))
    }

    fn is_remote_frame(&self) -> bool {
        self.remote
    }

    fn id(&self) -> Id {
        self.id
    }

    fn dlc(&self) -> usize {
        usize::from(self.dlc)
    }

    fn data(&self) -> &[u8] {
        self.payload()
    }
}

/// Message-buffer codes (RM 44.6.2.1: "CODE" field of the C/S word).
pub(crate) mod code {
    /// Transmit buffer, not active (also the state after a completed transmission).
    pub const TX_INACTIVE: u32 = 0b1000;
    /// Transmit buffer holding a frame to send.
    pub const TX_DATA: u32 = 0b1100;
    /// Written: abort the pending frame (MCR.AEN set). Read back after the buffer's flag
    /// rose: the frame was aborted (a transmitted one reads `TX_INACTIVE`).
    pub const TX_ABORT: u32 = 0b1001;
}

const CODE_SHIFT: u32 = 24;
/// The CODE field of a C/S word.
pub(crate) const CODE_MASK: u32 = 0xF << CODE_SHIFT;
const SRR: u32 = 1 << 22;
const IDE: u32 = 1 << 21;
const RTR: u32 = 1 << 20;
const DLC_SHIFT: u32 = 16;
const STD_ID_SHIFT: u32 = 18;
const EXT_ID_MASK: u32 = 0x1FFF_FFFF;

/// The code held in a C/S word.
pub(crate) fn code_of(cs: u32) -> u32 {
    (cs >> CODE_SHIFT) & 0xF
}

/// A C/S word with only a code (used to park and arm buffers).
pub(crate) fn cs_with_code(code: u32) -> u32 {
    code << CODE_SHIFT
}

/// The four words that queue `frame` for transmission: [C/S, ID, data 0-3, data 4-7].
pub(crate) fn tx_words(frame: &CanFrame) -> [u32; 4] {
    let mut cs = cs_with_code(code::TX_DATA) | (u32::from(frame.dlc) << DLC_SHIFT);
    let id = match frame.id {
        Id::Standard(id) => u32::from(id.as_raw()) << STD_ID_SHIFT,
        Id::Extended(id) => {
            // Extended frames carry SRR recessive (RM: must be 1 for transmission).
            cs |= IDE | SRR;
            id.as_raw()
        }
    };
    if frame.remote {
        cs |= RTR;
    }
    let [d0, d1, d2, d3, d4, d5, d6, d7] = frame.data;
    [
        cs,
        id,
        u32::from_be_bytes([d0, d1, d2, d3]),
        u32::from_be_bytes([d4, d5, d6, d7]),
    ]
}

/// The identifier word of a buffer as an `Id`, given whether its C/S word says extended.
pub(crate) fn id_of(cs: u32, id_word: u32) -> Id {
    if cs & IDE != 0 {
        // Masked to 29 bits, so `new` cannot fail; the fallback keeps this panic-free.
        ExtendedId::new(id_word & EXT_ID_MASK).map_or(Id::Extended(ExtendedId::ZERO), Id::Extended)
    } else {
        let raw = u16::try_from((id_word >> STD_ID_SHIFT) & 0x7FF).unwrap_or(0);
        StandardId::new(raw).map_or(Id::Standard(StandardId::ZERO), Id::Standard)
    }
}

/// The frame held in a received buffer's words. A DLC above 8 (legal on the wire for classic
/// CAN) still means 8 data bytes; the DLC is kept as received.
pub(crate) fn rx_frame(words: [u32; 4]) -> CanFrame {
    let [cs, id_word, low, high] = words;
    let [d0, d1, d2, d3] = low.to_be_bytes();
    let [d4, d5, d6, d7] = high.to_be_bytes();
    let remote = cs & RTR != 0;
    CanFrame {
        id: id_of(cs, id_word),
        remote,
        dlc: u8::try_from((cs >> DLC_SHIFT) & 0xF).unwrap_or(8),
        data: if remote {
            [0; 8]
        } else {
            [d0, d1, d2, d3, d4, d5, d6, d7]
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use embedded_can::Frame;

    fn std_frame(id: u16, data: &[u8]) -> CanFrame {
        CanFrame::new(StandardId::new(id).unwrap(), data).unwrap()
    }

    #[test]
    fn a_standard_frame_survives_the_mailbox_words() {
        let frame = std_frame(0x222, &[1, 2, 3, 4, 5, 6, 7, 8]);
        let words = tx_words(&frame);
        assert_eq!(code_of(words[0]), code::TX_DATA);
        assert_eq!(words[1], 0x222 << 18);
        assert_eq!(words[2], 0x0102_0304);
        assert_eq!(words[3], 0x0506_0708);
        assert_eq!(rx_frame(words), frame);
    }

    #[test]
    fn an_extended_frame_sets_ide_and_srr() {
        let frame = CanFrame::new(ExtendedId::new(0x18FF_01F4).unwrap(), &[0xAA]).unwrap();
        let words = tx_words(&frame);
        assert_eq!(words[0] & (IDE | SRR), IDE | SRR);
        assert_eq!(words[1], 0x18FF_01F4);
        let back = rx_frame(words);
        assert_eq!(back, frame);
        assert_eq!(back.data(), &[0xAA]);
    }

    #[test]
    fn remote_frames_carry_a_dlc_but_no_data() {
        let frame = CanFrame::new_remote(StandardId::new(0x123).unwrap(), 4).unwrap();
        let back = rx_frame(tx_words(&frame));
        assert!(back.is_remote_frame());
        assert_eq!(back.dlc(), 4);
        assert!(back.data().is_empty());
    }

    #[test]
    fn oversized_payloads_and_dlcs_are_refused_or_capped() {
        assert!(CanFrame::new(StandardId::ZERO, &[0; 9]).is_none());
        assert!(CanFrame::new_remote(StandardId::ZERO, 9).is_none());
        // A received DLC of 15 means 8 bytes on classic CAN.
        let words = [
            cs_with_code(0b0010) | (15 << DLC_SHIFT),
            0,
            u32::MAX,
            u32::MAX,
        ];
        let frame = rx_frame(words);
        assert_eq!(frame.dlc(), 15);
        assert_eq!(frame.data(), &[0xFF; 8]);
    }
}
