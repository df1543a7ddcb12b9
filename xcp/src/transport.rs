//! The two transports the slave is served over: XCP on CAN (the car) and XCP on TCP (the host,
//! for pyxcp). Both carry the same packets of at most [`MAX_CTO`] bytes.
//!
//! - CAN: one packet per frame. Responses are padded to 8 bytes with [`CAN_PAD`] (the DBC
//!   declares XCP_Res with DLC 8, what pyxcp calls `max_dlc_required`); commands may arrive
//!   padded too, and the slave ignores bytes past each command's fields.
//! - TCP: each packet follows a 4-byte header, LEN (u16, Intel) and CTR (u16, Intel). The
//!   decoder takes bytes as they come off the socket; the encoder numbers the slave's packets
//!   (responses and DTOs alike) with its own counter.

use crate::protocol::{MAX_CTO, MAX_DTO};

/// Byte that pads a CAN response to 8 bytes (0x55: alternating bits, no stuff bits).
pub const CAN_PAD: u8 = 0x55;

/// Bytes of a classic CAN frame's payload.
pub const CAN_DLC: usize = 8;

/// A packet as one CAN frame payload padded with [`CAN_PAD`], or `None` if it is longer than a
/// frame.
pub fn can_frame(packet: &[u8]) -> Option<[u8; CAN_DLC]> {
    if packet.len() > CAN_DLC {
        return None;
    }
    let mut frame = [CAN_PAD; CAN_DLC];
    for (slot, byte) in frame.iter_mut().zip(packet) {
        *slot = *byte;
    }
    Some(frame)
}

/// Bytes of the XCP-on-TCP header.
pub const TCP_HEADER: usize = 4;

/// Largest encoded TCP packet: header plus the largest packet either direction carries.
pub const TCP_FRAME_MAX: usize = TCP_HEADER + if MAX_CTO > MAX_DTO { MAX_CTO } else { MAX_DTO };

/// Why a TCP stream cannot be decoded or a packet not encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TcpError {
    /// A header announced this length: 0, or more than MAX_CTO. The stream has lost its
    /// framing; close the connection (the decoder keeps answering this error until reset).
    BadLength(u16),
    /// A packet to encode is empty or longer than a frame may carry.
    PacketSize(usize),
}

/// One packet out of a TCP stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TcpPacket<'a> {
    /// The sender's counter from the header.
    pub ctr: u16,
    /// The packet.
    pub data: &'a [u8],
}

/// Streaming XCP-on-TCP decoder: hand it whatever the socket delivered, in any split.
#[derive(Debug, Clone)]
pub struct TcpDecoder {
    header: [u8; TCP_HEADER],
    body: [u8; MAX_CTO],
    /// Bytes of the current frame collected (header first, then body).
    have: usize,
    /// The stream announced a bad length.
    broken: Option<u16>,
}

impl Default for TcpDecoder {
    fn default() -> Self {
        Self::new()
    }
}

impl TcpDecoder {
    /// A decoder at the start of a stream.
    pub const fn new() -> Self {
        TcpDecoder {
            header: [0; TCP_HEADER],
            body: [0; MAX_CTO],
            have: 0,
            broken: None,
        }
    }

    /// Starts over (a new connection).
    pub fn reset(&mut self) {
        *self = Self::new();
    }

    fn announced(&self) -> u16 {
        let [l0, l1, _, _] = self.header;
        u16::from_le_bytes([l0, l1])
    }

    /// Consumes bytes of `input` until one packet is complete or `input` is used up. Returns
    /// how many bytes were consumed and the packet, if one completed (or the error, if the
    /// stream is broken). Call again with the rest of `input` after a packet.
    pub fn decode<'s>(
        &'s mut self,
        input: &[u8],
    ) -> (usize, Option<Result<TcpPacket<'s>, TcpError>>) {
        if let Some(length) = self.broken {
            return (0, Some(Err(TcpError::BadLength(length))));
        }
        let mut used = 0usize;
        let mut rest = input;
        while self.have < TCP_HEADER {
            let Some((&byte, tail)) = rest.split_first() else {
                return (used, None);
            };
            if let Some(slot) = self.header.get_mut(self.have) {
                *slot = byte;
            }
            self.have += 1;
            used += 1;
            rest = tail;
        }
        let length = self.announced();
        let len = usize::from(length);
        if len == 0 || len > MAX_CTO {
            self.broken = Some(length);
            return (used, Some(Err(TcpError::BadLength(length))));
        }
        let got = self.have.saturating_sub(TCP_HEADER);
        let take = len.saturating_sub(got).min(rest.len());
        if let (Some(slots), Some(bytes)) = (
            self.body.get_mut(got..got.saturating_add(take)),
            rest.get(..take),
        ) {
            for (slot, byte) in slots.iter_mut().zip(bytes) {
                *slot = *byte;
            }
        }
        self.have += take;
        used += take;
        if self.have < TCP_HEADER + len {
            return (used, None);
        }
        self.have = 0;
        let [_, _, c0, c1] = self.header;
        let data = self.body.get(..len).unwrap_or(&[]);
        (
            used,
            Some(Ok(TcpPacket {
                ctr: u16::from_le_bytes([c0, c1]),
                data,
            })),
        )
    }
}

/// XCP-on-TCP encoder: frames the slave's packets and numbers them 0, 1, 2, ... (wrapping).
#[derive(Debug, Clone, Default)]
pub struct TcpEncoder {
    ctr: u16,
}

impl TcpEncoder {
    /// An encoder whose first packet gets counter 0.
    pub const fn new() -> Self {
        TcpEncoder { ctr: 0 }
    }

    /// The counter the next packet gets.
    pub fn next_ctr(&self) -> u16 {
        self.ctr
    }

    /// Frames `packet` (1 to MAX_CTO/MAX_DTO bytes) into `out`; returns the frame's length.
    pub fn encode(
        &mut self,
        packet: &[u8],
        out: &mut [u8; TCP_FRAME_MAX],
    ) -> Result<usize, TcpError> {
        let len = packet.len();
        if len == 0 || len > TCP_FRAME_MAX - TCP_HEADER {
            return Err(TcpError::PacketSize(len));
        }
        let length = u16::try_from(len).map_err(|_| TcpError::PacketSize(len))?;
        let [l0, l1] = length.to_le_bytes();
        let [c0, c1] = self.ctr.to_le_bytes();
        let header = [l0, l1, c0, c1];
        for (slot, byte) in out.iter_mut().zip(header.iter().chain(packet)) {
            *slot = *byte;
        }
        self.ctr = self.ctr.wrapping_add(1);
        Ok(TCP_HEADER + len)
    }
}
