//! Sending a few frames when nothing else can be trusted: the CCM's panic handler stops the
//! inverter through this before it resets, whatever state the driver (and its lock) was left
//! in. It touches only the transmit mailboxes and the interrupt flags, by address: no
//! [`Flexcan`](crate::Flexcan) instance, no allocation, no waiting beyond a bounded poll.
//!
//! A free transmit mailbox is taken for each frame; if every one is busy (a flooded bus, or
//! bus-off) the highest ones are reclaimed, written inactive first. Frames with equal
//! identifiers leave lowest mailbox first, so a stale command still pending goes out before
//! the stop frame that follows it: the stop frame is always the last word.

use crate::frame::{self, code};
use crate::{CanFrame, FIRST_TX_MB, LAST_MB, MB_RAM_WORD_OFFSET};

/// IFLAG1's word in the register block (offset 0x30).
const IFLAG1_WORD: usize = 0x30 / 4;

/// A FlexCAN instance's transmit mailboxes, by address.
pub struct EmergencyTx {
    base: *mut u32,
}

impl EmergencyTx {
    /// The controller whose register block starts at `base`.
    ///
    /// # Safety
    ///
    /// `base` must point at a FlexCAN register block that is clocked and configured (or at RAM
    /// laid out as one, for a test), with its 16 message buffers, and nothing else may write it
    /// while this value is used (the panic handler: nothing else runs).
    pub const unsafe fn new(base: *mut u32) -> Self {
        Self { base }
    }

    fn word(&self, index: usize) -> *mut u32 {
        self.base.wrapping_add(index)
    }

    fn read(&self, index: usize) -> u32 {
        // SAFETY: `index` is one of the register block's words (IFLAG1 or a message buffer's,
        // below LAST_MB), inside the block `new`'s contract guarantees.
        unsafe { self.word(index).read_volatile() }
    }

    fn write(&mut self, index: usize, value: u32) {
        // SAFETY: as in `read`; no one else writes the block (`new`'s contract).
        unsafe { self.word(index).write_volatile(value) }
    }

    fn mb(mb: usize, word: usize) -> usize {
        MB_RAM_WORD_OFFSET + mb * 4 + word
    }

    /// Queues `frames` (at most the seven transmit mailboxes' worth, in order); returns the
    /// mask of the mailboxes' flags, for [`Self::wait_sent`].
    pub fn queue(&mut self, frames: impl IntoIterator<Item = CanFrame>) -> u32 {
        let mut mask = 0u32;
        let mut reclaim = LAST_MB;
        for frame in frames.into_iter().take(LAST_MB - FIRST_TX_MB + 1) {
            let free = (FIRST_TX_MB..=LAST_MB).find(|&mb| {
                mask & (1 << mb) == 0 && frame::code_of(self.read(Self::mb(mb, 0))) != code::TX_DATA
            });
            let mb = match free {
                Some(mb) => mb,
                None => {
                    // Every mailbox busy: take the highest not yet ours.
                    let mb = reclaim;
                    reclaim = reclaim.saturating_sub(1).max(FIRST_TX_MB);
                    mb
                }
            };
            let words = frame::tx_words(&frame);
            let bit = 1u32 << mb;
            self.write(IFLAG1_WORD, bit);
            self.write(Self::mb(mb, 0), frame::cs_with_code(code::TX_INACTIVE));
            self.write(Self::mb(mb, 1), words[1]);
            self.write(Self::mb(mb, 2), words[2]);
            self.write(Self::mb(mb, 3), words[3]);
            self.write(Self::mb(mb, 0), words[0]);
            mask |= bit;
        }
        mask
    }

    /// Polls IFLAG1 until every buffer in `mask` has sent (at most `polls` reads); true if all
    /// did.
    pub fn wait_sent(&self, mask: u32, polls: u32) -> bool {
        (0..polls).any(|_| self.read(IFLAG1_WORD) & mask == mask)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use embedded_can::{ExtendedId, Frame};

    /// RAM laid out as a register block with its 16 message buffers.
    fn block() -> [u32; MB_RAM_WORD_OFFSET + 16 * 4] {
        let mut block = [0u32; MB_RAM_WORD_OFFSET + 16 * 4];
        for mb in FIRST_TX_MB..=LAST_MB {
            block[EmergencyTx::mb(mb, 0)] = frame::cs_with_code(code::TX_INACTIVE);
        }
        block
    }

    fn disable() -> CanFrame {
        let id = ExtendedId::new(0x0C41).expect("29 bits");
        CanFrame::new(id, &[0]).expect("one byte")
    }

    #[test]
    fn stop_frames_take_free_mailboxes_in_order() {
        let mut ram = block();
        let busy = FIRST_TX_MB;
        ram[EmergencyTx::mb(busy, 0)] = frame::cs_with_code(code::TX_DATA);
        // SAFETY: `ram` is laid out as the block and only this test touches it.
        let mut tx = unsafe { EmergencyTx::new(ram.as_mut_ptr()) };
        let mask = tx.queue([disable(), disable()]);
        assert_eq!(mask, 1 << (busy + 1) | 1 << (busy + 2));
        let words = frame::tx_words(&disable());
        for mb in [busy + 1, busy + 2] {
            assert_eq!(&ram[EmergencyTx::mb(mb, 0)..EmergencyTx::mb(mb, 4)], &words);
        }
        assert!(!tx_after(&mut ram).wait_sent(mask, 10), "not sent yet");
        ram[IFLAG1_WORD] = mask;
        assert!(tx_after(&mut ram).wait_sent(mask, 1));
    }

    fn tx_after(ram: &mut [u32]) -> EmergencyTx {
        // SAFETY: as above.
        unsafe { EmergencyTx::new(ram.as_mut_ptr()) }
    }

    #[test]
    fn with_every_mailbox_busy_the_highest_are_reclaimed() {
        let mut ram = block();
        for mb in FIRST_TX_MB..=LAST_MB {
            ram[EmergencyTx::mb(mb, 0)] = frame::cs_with_code(code::TX_DATA);
        }
        // SAFETY: as above.
        let mut tx = unsafe { EmergencyTx::new(ram.as_mut_ptr()) };
        let mask = tx.queue([disable(), disable()]);
        assert_eq!(mask, 1 << LAST_MB | 1 << (LAST_MB - 1));
    }
}
