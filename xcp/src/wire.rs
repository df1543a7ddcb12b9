//! Bounds-checked reading of command packets and building of answers. Every field access on
//! wire bytes goes through here, so a short packet becomes ERR_CMD_SYNTAX instead of a panic.

use crate::protocol::{MAX_CTO, err, pid};
use crate::refusal::Detail;
use crate::target::{Refusal, Target};

/// What a command handler answers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Answer {
    /// A positive response packet.
    Reply(Packet),
    /// No packet (the middle of a master-block-mode download).
    Silent,
}

/// An error packet to send: the code and the bytes that follow it, and why (the detail the
/// slave keeps as the last refusal; it is not on the wire).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Fail {
    pub(crate) packet: Packet,
    pub(crate) detail: Detail,
}

impl Fail {
    /// An error packet with just the code.
    pub(crate) fn new(code: u8) -> Self {
        let mut packet = Packet::empty();
        packet.push(pid::ERR);
        packet.push(code);
        Fail {
            packet,
            detail: Detail::default(),
        }
    }

    /// An error packet with just the code, and why.
    pub(crate) fn because(code: u8, detail: Detail) -> Self {
        Fail {
            detail,
            ..Self::new(code)
        }
    }

    /// The target refused: its code, and its own explanation.
    pub(crate) fn refused(refusal: Refusal, target: &impl Target) -> Self {
        Self::because(refusal.code(), target.explain())
    }

    /// The XCP error code.
    pub(crate) fn code(&self) -> u8 {
        self.packet.bytes().get(1).copied().unwrap_or(0)
    }

    /// An error packet with one more byte (DOWNLOAD_NEXT's expected element count).
    pub(crate) fn with_byte(code: u8, byte: u8) -> Self {
        let mut fail = Self::new(code);
        fail.packet.push(byte);
        fail
    }

    /// An error packet with two reserved bytes and a u32 (BUILD_CHECKSUM's largest block).
    pub(crate) fn with_u32(code: u8, value: u32) -> Self {
        let mut fail = Self::new(code);
        fail.packet.push(0);
        fail.packet.push(0);
        fail.packet.push_u32(value);
        fail
    }
}

/// Result of one command handler.
pub(crate) type Outcome = Result<Answer, Fail>;

/// A packet of at most MAX_CTO bytes, built by appending; bytes past the end are dropped (never
/// happens for the fixed layouts built here, and never panics).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Packet {
    bytes: [u8; MAX_CTO],
    len: usize,
}

impl Packet {
    /// No bytes yet.
    pub(crate) const fn empty() -> Self {
        Packet {
            bytes: [0; MAX_CTO],
            len: 0,
        }
    }

    /// A positive response: PID 0xFF followed by `fields`.
    pub(crate) fn ok(fields: &[u8]) -> Self {
        let mut packet = Self::empty();
        packet.push(pid::RES);
        packet.extend(fields);
        packet
    }

    /// Appends one byte.
    pub(crate) fn push(&mut self, byte: u8) {
        if let Some(slot) = self.bytes.get_mut(self.len) {
            *slot = byte;
            self.len = self.len.saturating_add(1);
        }
    }

    /// Appends bytes.
    pub(crate) fn extend(&mut self, bytes: &[u8]) {
        for &byte in bytes {
            self.push(byte);
        }
    }

    /// Appends a u16, Intel byte order.
    pub(crate) fn push_u16(&mut self, value: u16) {
        self.extend(&value.to_le_bytes());
    }

    /// Appends a u32, Intel byte order.
    pub(crate) fn push_u32(&mut self, value: u32) {
        self.extend(&value.to_le_bytes());
    }

    /// The bytes written so far.
    pub(crate) fn bytes(&self) -> &[u8] {
        self.bytes.get(..self.len).unwrap_or(&[])
    }

    /// Room left for data, in bytes.
    pub(crate) fn room(&self) -> usize {
        MAX_CTO.saturating_sub(self.len)
    }

    /// The unused tail, for reading data straight into the packet.
    pub(crate) fn tail_mut(&mut self, len: usize) -> Option<&mut [u8]> {
        let end = self.len.checked_add(len)?;
        self.bytes.get_mut(self.len..end)
    }

    /// Marks `len` more bytes (filled through [`Packet::tail_mut`]) as used.
    pub(crate) fn commit(&mut self, len: usize) {
        self.len = self.len.saturating_add(len).min(MAX_CTO);
    }
}

/// A command packet's parameter bytes, read by position (position 0 is the command code).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Args<'a> {
    bytes: &'a [u8],
}

impl<'a> Args<'a> {
    /// Wraps a whole command packet.
    pub(crate) fn new(bytes: &'a [u8]) -> Self {
        Args { bytes }
    }

    /// The byte at `at`, or ERR_CMD_SYNTAX if the packet is shorter.
    pub(crate) fn u8(&self, at: usize) -> Result<u8, Fail> {
        self.bytes
            .get(at)
            .copied()
            .ok_or(Fail::new(err::CMD_SYNTAX))
    }

    /// The Intel-order u16 at `at`.
    pub(crate) fn u16(&self, at: usize) -> Result<u16, Fail> {
        let raw = self.slice(at, 2)?;
        let two = <[u8; 2]>::try_from(raw).map_err(|_| Fail::new(err::CMD_SYNTAX))?;
        Ok(u16::from_le_bytes(two))
    }

    /// The Intel-order u32 at `at`.
    pub(crate) fn u32(&self, at: usize) -> Result<u32, Fail> {
        let raw = self.slice(at, 4)?;
        let four = <[u8; 4]>::try_from(raw).map_err(|_| Fail::new(err::CMD_SYNTAX))?;
        Ok(u32::from_le_bytes(four))
    }

    /// `len` bytes from `at`, or ERR_CMD_SYNTAX if the packet is shorter.
    pub(crate) fn slice(&self, at: usize, len: usize) -> Result<&'a [u8], Fail> {
        let end = at.checked_add(len).ok_or(Fail::new(err::CMD_SYNTAX))?;
        self.bytes.get(at..end).ok_or(Fail::new(err::CMD_SYNTAX))
    }
}
