//! The memory transfer's state between commands: the MTA (an address, or a position in one of
//! the slave's texts) and a master-block-mode download being collected. The commands that move
//! it are in `memory`.

use crate::config::{BLOCK_MAX, DOWNLOAD_CHUNK};

/// A text the slave serves through UPLOAD after GET_ID or GET_DAQ_EVENT_INFO set the MTA to it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Text {
    /// GET_ID type 0.
    Ascii,
    /// GET_ID type 1.
    A2lName,
    /// GET_ID type 5, from the target.
    Epk,
    /// An event channel's name.
    EventName(u16),
    /// An identification type the slave does not have (length 0).
    Empty,
}

/// The memory transfer address: an XCP address, or a position in one of the slave's texts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Mta {
    /// An address in the target's map.
    Memory { ext: u8, address: u32 },
    /// An offset into a text.
    Text { text: Text, offset: u32 },
}

impl Mta {
    /// The MTA of a new session.
    pub(crate) const START: Self = Mta::Memory { ext: 0, address: 0 };

    /// The MTA `count` bytes further on, or `None` past the end of the address space.
    pub(crate) fn advanced(self, count: usize) -> Option<Self> {
        let count = u32::try_from(count).ok()?;
        Some(match self {
            Mta::Memory { ext, address } => Mta::Memory {
                ext,
                address: address.checked_add(count)?,
            },
            Mta::Text { text, offset } => Mta::Text {
                text,
                offset: offset.checked_add(count)?,
            },
        })
    }
}

/// A master-block-mode download being collected: written to the target in one call when its
/// last byte has arrived. A block that failed (its error already answered) is still followed
/// to its end so its remaining packets can be dropped without answers: every block gets
/// exactly one answer, and a master that streams the packets (pyxcp reads no answers mid-block
/// and never drains stale ones) is not left with extra errors for its next commands.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Block {
    data: [u8; BLOCK_MAX],
    /// Bytes announced (0: no block open).
    total: usize,
    /// Bytes received.
    got: usize,
    /// The block's error was answered; its remaining packets are dropped.
    pub(crate) failed: bool,
    /// Where the block goes.
    pub(crate) ext: u8,
    pub(crate) address: u32,
}

impl Block {
    /// No block open.
    pub(crate) const IDLE: Self = Block {
        data: [0; BLOCK_MAX],
        total: 0,
        got: 0,
        failed: false,
        ext: 0,
        address: 0,
    };

    /// A block of `total` bytes for `address` (extension `ext`), nothing received yet.
    pub(crate) fn open(total: usize, ext: u8, address: u32) -> Self {
        Block {
            total,
            ext,
            address,
            ..Self::IDLE
        }
    }

    /// The rest of a failed block: `remaining` more bytes to drop (none: no block open).
    pub(crate) fn failed(remaining: usize) -> Self {
        Block {
            total: remaining,
            failed: true,
            ..Self::IDLE
        }
    }

    pub(crate) fn is_open(&self) -> bool {
        self.total != 0
    }

    /// Bytes still to come.
    pub(crate) fn remaining(&self) -> usize {
        self.total.saturating_sub(self.got)
    }

    /// Appends received bytes (never past the announced total).
    pub(crate) fn append(&mut self, bytes: &[u8]) {
        let end = self.got.saturating_add(bytes.len()).min(self.total);
        if let Some(slots) = self.data.get_mut(self.got..end) {
            for (slot, byte) in slots.iter_mut().zip(bytes) {
                *slot = *byte;
            }
        }
        self.got = end;
    }

    pub(crate) fn bytes(&self) -> &[u8] {
        self.data.get(..self.got).unwrap_or(&[])
    }
}

/// The remaining-elements byte of DOWNLOAD_NEXT's ERR_SEQUENCE (at most 255 by construction).
pub(crate) fn expected(block: &Block) -> u8 {
    u8::try_from(block.remaining()).unwrap_or(u8::MAX)
}

/// What is left of a block whose packet announced `count` remaining bytes, after that packet.
pub(crate) fn after_packet(count: usize) -> Block {
    Block::failed(count.saturating_sub(DOWNLOAD_CHUNK))
}
