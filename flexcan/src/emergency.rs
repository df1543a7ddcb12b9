//! Sending a few frames when nothing else can be trusted: the CCM's panic handler stops the
//! inverter through this before it resets, whatever state the driver (and its lock) was left
//! in. It touches only the transmit mailboxes, IFLAG1 and DBG1, by address: no
//! [`Flexcan`](crate::Flexcan) instance, no allocation, no waiting beyond bounded polls.
//!
//! Every frame still pending is taken off the bus first (aborted, or deactivated while the
//! bus is idle, as ERR006032 requires), so no stale command can leave after the stop frames:
//! they are always the last word. They then take the transmit mailboxes lowest first, which
//! with equal identifiers is also the order they leave in; frames of different identifiers
//! leave lowest identifier first. After they are armed the spare mailbox is written inactive
//! twice (ERR005829, as the driver's `transmit` does), so none is skipped in arbitration.

use crate::frame::{self, code};
use crate::{CanFrame, ERRATA_MB, FIRST_TX_MB, LAST_MB, MB_RAM_WORD_OFFSET};

/// IFLAG1's word in the register block (offset 0x30).
const IFLAG1_WORD: usize = 0x30 / 4;
/// DBG1's word in the register block (offset 0x58): the protocol state, for ERR006032.
const DBG1_WORD: usize = 0x58 / 4;
const DBG1_CFSM_MASK: u32 = 0x3F;
const DBG1_CBN_SHIFT: u32 = 24;
const DBG1_CBN_MASK: u32 = 0x1F;
const CFSM_RX_INTERMISSION: u32 = 0x2F;
const CFSM_TX_INTERMISSION: u32 = 0x14;
const CFSM_BUS_IDLE: u32 = 0x02;
/// Spins after bus idle is seen before a buffer is deactivated (NXP's SDK: 200).
const IDLE_DELAY: u32 = 200;

/// The register block's words, as the emergency path reads and writes them.
pub trait BlockWords {
    /// The word at `index` (32-bit words from the block's start).
    fn read(&self, index: usize) -> u32;
    /// Writes `value` to the word at `index`.
    fn write(&mut self, index: usize, value: u32);
}

/// A register block at a fixed address.
pub struct RawBlock {
    base: *mut u32,
}

impl BlockWords for RawBlock {
    fn read(&self, index: usize) -> u32 {
        // SAFETY: callers pass IFLAG1, DBG1 or a message buffer's word (below LAST_MB), inside
        // the block `EmergencyTx::new`'s contract guarantees.
        unsafe { self.base.wrapping_add(index).read_volatile() }
    }

    fn write(&mut self, index: usize, value: u32) {
        // SAFETY: as in `read`; no one else writes the block (`EmergencyTx::new`'s contract).
        unsafe { self.base.wrapping_add(index).write_volatile(value) }
    }
}

/// What [`EmergencyTx::queue`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Queued {
    /// The flags of the mailboxes the frames took, for [`EmergencyTx::wait_sent`].
    pub mask: u32,
    /// Pending frames taken off the bus before the stop frames were queued.
    pub withdrawn: u8,
}

/// A FlexCAN instance's transmit mailboxes.
pub struct EmergencyTx<B: BlockWords> {
    block: B,
}

impl EmergencyTx<RawBlock> {
    /// The controller whose register block starts at `base`.
    ///
    /// # Safety
    ///
    /// `base` must point at a FlexCAN register block that is clocked and configured (or at RAM
    /// laid out as one, for a test), with its 16 message buffers and DBG1 at 0x58, and nothing
    /// else may write it while this value is used (the panic handler: nothing else runs).
    pub const unsafe fn new(base: *mut u32) -> Self {
        Self {
            block: RawBlock { base },
        }
    }
}

impl<B: BlockWords> EmergencyTx<B> {
    /// Over any register block (a model of one, in tests).
    pub const fn over(block: B) -> Self {
        Self { block }
    }

    /// The register block, back.
    pub fn into_block(self) -> B {
        self.block
    }

    fn mb(mb: usize, word: usize) -> usize {
        MB_RAM_WORD_OFFSET + mb * 4 + word
    }

    /// Takes every pending frame off the bus (each abort waits at most `polls` reads), then
    /// queues `frames` (at most the seven transmit mailboxes' worth, in order) lowest mailbox
    /// first.
    pub fn queue(&mut self, frames: impl IntoIterator<Item = CanFrame>, polls: u32) -> Queued {
        let mut withdrawn = 0u8;
        for mb in FIRST_TX_MB..=LAST_MB {
            match frame::code_of(self.block.read(Self::mb(mb, 0))) {
                code::TX_DATA => {
                    self.withdraw(mb, polls);
                    withdrawn = withdrawn.saturating_add(1);
                }
                // An abort the driver had asked for and the panic interrupted: let it finish
                // (the flag rises, aborted or sent), then park the buffer.
                code::TX_ABORT => {
                    let bit = 1u32 << mb;
                    let _ = (0..polls).any(|_| self.block.read(IFLAG1_WORD) & bit != 0);
                    self.block.write(IFLAG1_WORD, bit);
                    self.block
                        .write(Self::mb(mb, 0), frame::cs_with_code(code::TX_INACTIVE));
                    withdrawn = withdrawn.saturating_add(1);
                }
                _ => {}
            }
        }
        let mut mask = 0u32;
        for (mb, frame) in (FIRST_TX_MB..=LAST_MB).zip(frames) {
            let words = frame::tx_words(&frame);
            let bit = 1u32 << mb;
            self.block.write(IFLAG1_WORD, bit);
            self.block
                .write(Self::mb(mb, 0), frame::cs_with_code(code::TX_INACTIVE));
            self.block.write(Self::mb(mb, 1), words[1]);
            self.block.write(Self::mb(mb, 2), words[2]);
            self.block.write(Self::mb(mb, 3), words[3]);
            self.block.write(Self::mb(mb, 0), words[0]);
            mask |= bit;
        }
        for _ in 0..2 {
            self.block.write(
                Self::mb(ERRATA_MB, 0),
                frame::cs_with_code(code::TX_INACTIVE),
            );
        }
        Queued { mask, withdrawn }
    }

    /// Takes `mb`'s pending frame off the bus: deactivated if the bus is idle (ERR006032:
    /// an abort then could send a corrupted frame), aborted otherwise (the flag rises once
    /// the controller let it go, or it finished sending). The buffer is left inactive either
    /// way; a frame that was already on the wire completes, before the stop frames.
    fn withdraw(&mut self, mb: usize, polls: u32) {
        let bit = 1u32 << mb;
        self.block.write(IFLAG1_WORD, bit);
        let dbg1 = self.block.read(DBG1_WORD);
        let state = dbg1 & DBG1_CFSM_MASK;
        if matches!(state, CFSM_RX_INTERMISSION | CFSM_TX_INTERMISSION)
            && (dbg1 >> DBG1_CBN_SHIFT) & DBG1_CBN_MASK == 3
        {
            let _ = (0..polls).any(|_| self.block.read(DBG1_WORD) & DBG1_CFSM_MASK != state);
        }
        if self.block.read(DBG1_WORD) & DBG1_CFSM_MASK == CFSM_BUS_IDLE {
            for _ in 0..IDLE_DELAY {
                core::hint::spin_loop();
            }
            let cs = self.block.read(Self::mb(mb, 0));
            self.block.write(Self::mb(mb, 0), cs & !frame::CODE_MASK);
        } else {
            self.block
                .write(Self::mb(mb, 0), frame::cs_with_code(code::TX_ABORT));
            let _ = (0..polls).any(|_| self.block.read(IFLAG1_WORD) & bit != 0);
        }
        self.block.write(IFLAG1_WORD, bit);
        self.block
            .write(Self::mb(mb, 0), frame::cs_with_code(code::TX_INACTIVE));
    }

    /// Polls IFLAG1 until every buffer in `mask` has sent (at most `polls` reads); true if all
    /// did.
    pub fn wait_sent(&self, mask: u32, polls: u32) -> bool {
        (0..polls).any(|_| self.block.read(IFLAG1_WORD) & mask == mask)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use embedded_can::{ExtendedId, Frame};

    const WORDS: usize = MB_RAM_WORD_OFFSET + 16 * 4;

    /// A FlexCAN's transmit side as far as this path sees it: IFLAG1 is write-one-to-clear;
    /// an ABORT written to a pending buffer lets it go at once (flag up, code reads ABORT);
    /// every code written to a buffer is recorded, in order.
    struct Model {
        words: [u32; WORDS],
        dbg1: u32,
        codes: Vec<(usize, u32)>,
        /// Buffers the controller sends as soon as they are written TX_DATA (a bus taking
        /// frames), instead of leaving them pending.
        sending: bool,
        sent: Vec<(usize, [u32; 4])>,
    }

    impl Model {
        fn new(dbg1: u32) -> Self {
            let mut words = [0u32; WORDS];
            for mb in FIRST_TX_MB..=LAST_MB {
                words[EmergencyTx::<Self>::mb(mb, 0)] = frame::cs_with_code(code::TX_INACTIVE);
            }
            Self {
                words,
                dbg1,
                codes: Vec::new(),
                sending: false,
                sent: Vec::new(),
            }
        }

        fn pending(&mut self, mb: usize, frame: &CanFrame) {
            let words = frame::tx_words(frame);
            let at = EmergencyTx::<Self>::mb(mb, 0);
            self.words[at..at + 4].copy_from_slice(&words);
        }
    }

    impl BlockWords for Model {
        fn read(&self, index: usize) -> u32 {
            if index == DBG1_WORD {
                return self.dbg1;
            }
            self.words[index]
        }

        fn write(&mut self, index: usize, value: u32) {
            if index == IFLAG1_WORD {
                self.words[index] &= !value;
                return;
            }
            let mb_word = index.checked_sub(MB_RAM_WORD_OFFSET).unwrap();
            let (mb, word) = (mb_word / 4, mb_word % 4);
            if word == 0 {
                let written = frame::code_of(value);
                self.codes.push((mb, written));
                let was = frame::code_of(self.words[index]);
                if written == code::TX_ABORT && was == code::TX_DATA {
                    self.words[IFLAG1_WORD] |= 1 << mb;
                } else if written == code::TX_DATA && self.sending {
                    let at = index;
                    let mut frame = [value, 0, 0, 0];
                    frame[1..].copy_from_slice(&self.words[at + 1..at + 4]);
                    self.sent.push((mb, frame));
                    self.words[IFLAG1_WORD] |= 1 << mb;
                    self.words[index] = frame::cs_with_code(code::TX_INACTIVE);
                    return;
                }
            }
            self.words[index] = value;
        }
    }

    fn command(byte: u8) -> CanFrame {
        let id = ExtendedId::new(0x0C41).expect("29 bits");
        CanFrame::new(id, &[byte]).expect("one byte")
    }

    const ENABLE: u8 = 1;
    const DISABLE: u8 = 0;

    #[test]
    fn a_stale_command_pending_is_aborted_before_the_stop_frames_are_queued() {
        let mut model = Model::new(0);
        // The control task's last enable, still waiting in a high mailbox on a busy bus.
        model.pending(LAST_MB, &command(ENABLE));
        let mut tx = EmergencyTx::over(model);
        let queued = tx.queue([command(DISABLE), command(DISABLE)], 100);
        let mut model = tx.into_block();
        assert_eq!(queued.withdrawn, 1);
        assert_eq!(queued.mask, 1 << FIRST_TX_MB | 1 << (FIRST_TX_MB + 1));
        let abort_at = model
            .codes
            .iter()
            .position(|&entry| entry == (LAST_MB, code::TX_ABORT))
            .expect("the stale enable was aborted");
        let first_queued = model
            .codes
            .iter()
            .position(|&(_, written)| written == code::TX_DATA)
            .expect("stop frames queued");
        assert!(abort_at < first_queued, "{:?}", model.codes);
        let code_now = frame::code_of(model.read(EmergencyTx::<Model>::mb(LAST_MB, 0)));
        assert_eq!(code_now, code::TX_INACTIVE);
        // The bus now takes frames: only the stop frames leave, in order.
        model.sending = true;
        for mb in FIRST_TX_MB..=LAST_MB {
            let at = EmergencyTx::<Model>::mb(mb, 0);
            let cs = model.words[at];
            if frame::code_of(cs) == code::TX_DATA {
                model.write(at, cs);
            }
        }
        let payloads: Vec<u32> = model.sent.iter().map(|(_, words)| words[2] >> 24).collect();
        assert_eq!(payloads, [u32::from(DISABLE), u32::from(DISABLE)]);
    }

    #[test]
    fn on_an_idle_bus_a_pending_frame_is_deactivated_never_aborted() {
        // ERR006032: an abort while the bus is idle can send a corrupted frame.
        let mut model = Model::new(CFSM_BUS_IDLE);
        model.pending(FIRST_TX_MB, &command(ENABLE));
        let mut tx = EmergencyTx::over(model);
        let queued = tx.queue([command(DISABLE)], 100);
        let model = tx.into_block();
        assert_eq!(queued.withdrawn, 1);
        assert!(
            !model
                .codes
                .iter()
                .any(|&(_, written)| written == code::TX_ABORT),
            "{:?}",
            model.codes
        );
        assert_eq!(model.codes.first(), Some(&(FIRST_TX_MB, 0)));
        assert_eq!(queued.mask, 1 << FIRST_TX_MB);
    }

    #[test]
    fn with_every_mailbox_pending_all_are_withdrawn_and_each_frame_has_its_own() {
        let mut model = Model::new(0);
        for mb in FIRST_TX_MB..=LAST_MB {
            model.pending(mb, &command(ENABLE));
        }
        let mut tx = EmergencyTx::over(model);
        let stops = [command(DISABLE); 9];
        let queued = tx.queue(stops, 100);
        let model = tx.into_block();
        assert_eq!(usize::from(queued.withdrawn), LAST_MB - FIRST_TX_MB + 1);
        // Seven frames, one per mailbox, none overwriting another.
        assert_eq!(queued.mask.count_ones() as usize, LAST_MB - FIRST_TX_MB + 1);
        let words = frame::tx_words(&command(DISABLE));
        for mb in FIRST_TX_MB..=LAST_MB {
            let at = EmergencyTx::<Model>::mb(mb, 0);
            assert_eq!(&model.words[at..at + 4], &words, "mailbox {mb}");
        }
    }

    #[test]
    fn an_abort_that_never_completes_costs_only_its_polls() {
        // Bus-off or a controller that never answers: the flag never rises.
        struct Deaf(Model);
        impl BlockWords for Deaf {
            fn read(&self, index: usize) -> u32 {
                if index == IFLAG1_WORD {
                    0
                } else {
                    self.0.read(index)
                }
            }
            fn write(&mut self, index: usize, value: u32) {
                self.0.write(index, value);
            }
        }
        let mut model = Model::new(0);
        model.pending(FIRST_TX_MB, &command(ENABLE));
        let mut tx = EmergencyTx::over(Deaf(model));
        let queued = tx.queue([command(DISABLE)], 10);
        assert_eq!(queued.mask, 1 << FIRST_TX_MB);
        assert!(!tx.wait_sent(queued.mask, 10));
    }

    #[test]
    fn the_spare_mailbox_is_written_inactive_twice_after_the_stop_frames_are_armed() {
        let mut tx = EmergencyTx::over(Model::new(0));
        tx.queue([command(DISABLE), command(DISABLE)], 100);
        let model = tx.into_block();
        let last_armed = model
            .codes
            .iter()
            .rposition(|&(_, written)| written == code::TX_DATA)
            .expect("armed");
        let spare = model.codes[last_armed..]
            .iter()
            .filter(|&&entry| entry == (ERRATA_MB, code::TX_INACTIVE))
            .count();
        assert_eq!(spare, 2, "{:?}", model.codes);
    }

    #[test]
    fn a_mailbox_caught_mid_abort_is_parked_before_it_is_reused() {
        let mut model = Model::new(0);
        model.pending(FIRST_TX_MB, &command(ENABLE));
        let at = EmergencyTx::<Model>::mb(FIRST_TX_MB, 0);
        model.words[at] =
            (model.words[at] & !frame::CODE_MASK) | frame::cs_with_code(code::TX_ABORT);
        let mut tx = EmergencyTx::over(model);
        let queued = tx.queue([command(DISABLE)], 100);
        let model = tx.into_block();
        assert_eq!(queued.withdrawn, 1);
        let parked = model
            .codes
            .iter()
            .position(|&entry| entry == (FIRST_TX_MB, code::TX_INACTIVE))
            .expect("parked");
        let armed = model
            .codes
            .iter()
            .position(|&(_, written)| written == code::TX_DATA)
            .expect("armed");
        assert!(parked < armed, "{:?}", model.codes);
    }

    #[test]
    fn sent_frames_are_seen_through_iflag1() {
        let mut tx = EmergencyTx::over(Model::new(0));
        let queued = tx.queue([command(DISABLE)], 10);
        assert!(!tx.wait_sent(queued.mask, 10), "not sent yet");
        let mut model = tx.into_block();
        model.words[IFLAG1_WORD] = queued.mask;
        assert!(EmergencyTx::over(model).wait_sent(queued.mask, 1));
    }
}
