//! A small FlexCAN driver for the i.MX RT1062 (Teensy 4.0 and 4.1), shared by the CCM and PCC
//! firmware. imxrt-hal 0.6 has none.
//!
//! What it does: classic CAN (no CAN FD) on CAN1, CAN2 or CAN3 from the 24 MHz oscillator, exact
//! bit timing ([`timing`]), reception through the 6-deep hardware RX FIFO (ordered, with a
//! hardware overflow flag that is counted), transmission from 7 mailboxes. Frames with the same
//! identifier leave in the order they were queued: a frame is refused with
//! [`TxError::Busy`] while an earlier one with its identifier is still pending, because the
//! controller arbitrates pending mailboxes by identifier and mailbox number, not by age.
//! A command that must never go out stale uses [`Flexcan::transmit_latest`] instead: it
//! aborts the pending frame with the same identifier and queues the new one.
//!
//! Errors: [`Flexcan::check_errors`] reports the fault confinement state (error-active,
//! error-passive, bus-off), counts every entry into bus-off and then aborts every pending
//! frame, so nothing queued before the bus went away is sent late once it recovers. Recovery
//! itself is the controller's automatic one (CTRL1.BOFFREC clear): after 128 occurrences of
//! 11 recessive bits it is error-active again.
//!
//! CAN3 is the CAN FD-capable instance with a register block of its own; with MCR.FDEN clear it
//! is a classic controller whose registers this driver uses sit at the same offsets as on
//! CAN1/CAN2 (checked at compile time against imxrt-ral's two register blocks, [`can3`]).
//!
//! Register facts are from the i.MX RT1060 reference manual, chapter "FlexCAN"; the errata
//! workarounds are ERR005829 (a mailbox armed during arbitration can be skipped unless the first
//! free mailbox is written inactive twice afterwards) and ERR006032 (a pending mailbox is never
//! aborted while the bus is idle: [`Flexcan::transmit_latest`], [`Flexcan::check_errors`]).
#![cfg_attr(not(test), no_std)]

pub mod can3;
pub mod emergency;
mod frame;
mod report;
pub mod timing;

pub use frame::CanFrame;
use frame::code;
use imxrt_iomuxc::{
    consts::Const,
    flexcan::{Pin, Rx, Tx},
};
use imxrt_ral as ral;
use timing::{BitTiming, UnreachableBitrate};

/// CAN clock root: the 24 MHz oscillator, undivided.
pub const CAN_CLOCK_HZ: u32 = 24_000_000;

// MCR bits.
const MCR_MDIS: u32 = 1 << 31;
const MCR_FRZ: u32 = 1 << 30;
const MCR_RFEN: u32 = 1 << 29;
const MCR_HALT: u32 = 1 << 28;
const MCR_NOTRDY: u32 = 1 << 27;
const MCR_SOFTRST: u32 = 1 << 25;
const MCR_FRZACK: u32 = 1 << 24;
const MCR_SUPV: u32 = 1 << 23;
const MCR_WRNEN: u32 = 1 << 21;
const MCR_LPMACK: u32 = 1 << 20;
const MCR_SRXDIS: u32 = 1 << 17;
const MCR_IRMQ: u32 = 1 << 16;
const MCR_AEN: u32 = 1 << 12;
// ESR1: entered bus-off (write 1 to clear), and the fault confinement field.
const ESR1_BOFFINT: u32 = 1 << 2;
const ESR1_FLTCONF_SHIFT: u32 = 4;
// DBG1: the protocol state machine (CFSM) and the bit in the current field (CBN), for
// ERR006032. States: intermission after a received or a sent frame, bus idle.
const DBG1_CFSM_MASK: u32 = 0x3F;
const DBG1_CBN_SHIFT: u32 = 24;
const DBG1_CBN_MASK: u32 = 0x1F;
const CFSM_RX_INTERMISSION: u32 = 0x2F;
const CFSM_TX_INTERMISSION: u32 = 0x14;
const CFSM_BUS_IDLE: u32 = 0x02;
/// Spin iterations after bus idle is seen before the buffer is deactivated (NXP's SDK: 200).
const ERR006032_IDLE_DELAY: u32 = 200;
// CTRL1: internal loopback.
const CTRL1_LPB: u32 = 1 << 12;
// CTRL2: store received remote frames instead of answering them automatically.
const CTRL2_RRS: u32 = 1 << 17;
// IFLAG1 bits while the RX FIFO is on: frame available, almost full, overflow.
const IFLAG_FIFO_AVAILABLE: u32 = 1 << 5;
const IFLAG_FIFO_WARNING: u32 = 1 << 6;
const IFLAG_FIFO_OVERFLOW: u32 = 1 << 7;

/// Message-buffer layout with the RX FIFO on and RFFN = 0: the FIFO occupies buffers 0-5,
/// its 8-entry filter table buffers 6-7, so buffer 8 is the first free one.
const FIFO_FILTERS: usize = 8;
/// Buffer 8 stays inactive for the ERR005829 workaround.
pub(crate) const ERRATA_MB: usize = 8;
pub(crate) const FIRST_TX_MB: usize = 9;
pub(crate) const LAST_MB: usize = 15;
/// Message-buffer RAM starts 0x80 bytes into the register block; each buffer is 4 words.
pub(crate) const MB_RAM_WORD_OFFSET: usize = 0x80 / 4;

/// Register polling limit during set-up (each poll is one bus read, a few ns).
const POLL_LIMIT: u32 = 1_000_000;

/// Why the controller could not be started.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InitError {
    /// The bit rate cannot be made exactly from the CAN clock.
    Bitrate(UnreachableBitrate),
    /// The TX and RX pins belong to another FlexCAN instance than the registers.
    WrongPins,
    /// The controller did not acknowledge a mode change (clock not running?).
    Timeout(&'static str),
}

/// Why a frame was not queued.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TxError {
    /// Every mailbox is busy, or a frame with this identifier is still pending; retry later.
    Busy,
}

/// Why a controller's self-test failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SelfTestError {
    /// Entering or leaving loopback mode timed out.
    Init(InitError),
    /// Every mailbox was busy.
    TxBusy,
    /// The frame never came back.
    NothingReceived,
    /// Another frame came back.
    Mismatch(CanFrame),
}

/// Fault confinement state of the controller (ESR1.FLTCONF).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FaultState {
    /// Normal operation.
    ErrorActive,
    /// An error counter passed 127: the node still talks, with passive error flags.
    ErrorPassive,
    /// The transmit error counter passed 255; the controller recovers by itself after
    /// 128 x 11 recessive bits.
    BusOff,
}

impl FaultState {
    /// The state an ESR1 value reports.
    pub const fn from_esr1(esr1: u32) -> Self {
        match (esr1 >> ESR1_FLTCONF_SHIFT) & 0b11 {
            0b00 => Self::ErrorActive,
            0b01 => Self::ErrorPassive,
            _ => Self::BusOff,
        }
    }
}

/// Error counters and state, for the status and telemetry frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BusStatus {
    /// Fault confinement state.
    pub state: FaultState,
    /// Transmit error counter.
    pub tx_errors: u8,
    /// Receive error counter.
    pub rx_errors: u8,
    /// Frames lost because the hardware RX FIFO was full (since start-up).
    pub rx_fifo_overflows: u32,
    /// Times the controller entered bus-off (counted by [`Flexcan::check_errors`]).
    pub bus_off_events: u32,
    /// Queued frames that never went out: replaced by a newer one with the same identifier,
    /// or aborted when the controller went bus-off.
    pub tx_dropped: u32,
}

impl Flexcan<3> {
    /// Clocks, resets and starts FlexCAN3 in classic CAN mode at `bitrate` on the Teensy 4.1's
    /// pins 31 (TX) and 30 (RX), receiving every frame, as [`Flexcan::new`] does for CAN1/CAN2.
    pub fn new_can3(
        regs: ral::can3::CAN3,
        mut tx: can3::TxPad,
        mut rx: can3::RxPad,
        ccm: &ral::ccm::CCM,
        bitrate: u32,
    ) -> Result<Self, InitError> {
        enable_clock::<3>(ccm)?;
        can3::mux_pins(&mut tx, &mut rx);
        Self::start(can3::classic_view(regs), bitrate)
    }
}

/// A started FlexCAN controller. `N` is the instance number (1, 2 or 3).
pub struct Flexcan<const N: u8> {
    regs: ral::can::Instance<N>,
    rx_fifo_overflows: u32,
    bus_off_events: u32,
    tx_dropped: u32,
}

impl<const N: u8> Flexcan<N> {
    /// Clocks, resets and starts controller `N` at `bitrate`, receiving every frame (no
    /// filters: the decoders decide what they care about), muxing `tx` and `rx` to it.
    ///
    /// Sets the shared CAN clock root to the 24 MHz oscillator, so every FlexCAN instance runs
    /// from the same clock.
    pub fn new<TX, RX>(
        regs: ral::can::Instance<N>,
        mut tx: TX,
        mut rx: RX,
        ccm: &ral::ccm::CCM,
        bitrate: u32,
    ) -> Result<Self, InitError>
    where
        TX: Pin<Signal = Tx, Module = Const<N>>,
        RX: Pin<Signal = Rx, Module = Const<N>>,
    {
        enable_clock::<N>(ccm)?;
        imxrt_iomuxc::flexcan::prepare(&mut tx);
        imxrt_iomuxc::flexcan::prepare(&mut rx);
        Self::start(regs, bitrate)
    }

    fn start(regs: ral::can::Instance<N>, bitrate: u32) -> Result<Self, InitError> {
        let timing = BitTiming::for_bitrate(CAN_CLOCK_HZ, bitrate).map_err(InitError::Bitrate)?;
        let mut can = Self {
            regs,
            rx_fifo_overflows: 0,
            bus_off_events: 0,
            tx_dropped: 0,
        };
        can.configure(timing)?;
        Ok(can)
    }

    /// Switches the controller's internal loopback on or off (CTRL1.LPB, with self-reception
    /// while it is on): frames sent are received by this controller and nothing reaches the
    /// bus. The bring-up images use it to test a controller without a second node.
    pub fn set_loopback(&mut self, on: bool) -> Result<(), InitError> {
        ral::modify_reg!(ral::can, self.regs, MCR, |mcr| mcr | MCR_FRZ | MCR_HALT);
        self.wait_mcr(MCR_FRZACK, true, "enter freeze mode")?;
        ral::modify_reg!(ral::can, self.regs, CTRL1, |ctrl1| if on {
            ctrl1 | CTRL1_LPB
        } else {
            ctrl1 & !CTRL1_LPB
        });
        ral::modify_reg!(ral::can, self.regs, MCR, |mcr| if on {
            mcr & !MCR_SRXDIS
        } else {
            mcr | MCR_SRXDIS
        });
        ral::modify_reg!(ral::can, self.regs, MCR, |mcr| mcr & !(MCR_FRZ | MCR_HALT));
        self.wait_mcr(MCR_FRZACK, false, "leave freeze mode")?;
        self.wait_mcr(MCR_NOTRDY, false, "synchronise to the bus")
    }

    /// The controller's self-test: internal loopback on, `frame` sent, and the same frame
    /// received back within the polling limit; loopback off again either way. Frames already
    /// waiting in the receive FIFO are drained first (and lost to the caller: run it on the
    /// bench, not while driving).
    pub fn self_test(&mut self, frame: &CanFrame) -> Result<(), SelfTestError> {
        self.set_loopback(true).map_err(SelfTestError::Init)?;
        while self.receive().is_some() {}
        let result = match self.transmit(frame) {
            Err(TxError::Busy) => Err(SelfTestError::TxBusy),
            Ok(()) => (0..POLL_LIMIT).find_map(|_| self.receive()).map_or(
                Err(SelfTestError::NothingReceived),
                |received| {
                    if received == *frame {
                        Ok(())
                    } else {
                        Err(SelfTestError::Mismatch(received))
                    }
                },
            ),
        };
        self.set_loopback(false).map_err(SelfTestError::Init)?;
        result
    }

    fn configure(&mut self, timing: BitTiming) -> Result<(), InitError> {
        // CAN3 only: classic CAN (FDEN is reserved and zero on CAN1/CAN2). Writable only while
        // the module is disabled, and left at its reset value by every later MCR write.
        ral::modify_reg!(ral::can, self.regs, MCR, |mcr| mcr & !can3::MCR_FDEN);
        ral::modify_reg!(ral::can, self.regs, MCR, |mcr| mcr & !MCR_MDIS);
        self.wait_mcr(MCR_LPMACK, false, "leave low-power mode")?;
        ral::modify_reg!(ral::can, self.regs, MCR, |mcr| mcr | MCR_SOFTRST);
        self.wait_mcr(MCR_SOFTRST, false, "soft reset")?;
        ral::modify_reg!(ral::can, self.regs, MCR, |mcr| mcr | MCR_FRZ | MCR_HALT);
        self.wait_mcr(MCR_FRZACK, true, "enter freeze mode")?;

        // Oscillator clock (CLKSRC = 0), automatic bus-off recovery, lowest ID sent first.
        let ctrl1 = (u32::from(timing.presdiv) << 24)
            | (u32::from(timing.rjw) << 22)
            | (u32::from(timing.pseg1) << 19)
            | (u32::from(timing.pseg2) << 16)
            | u32::from(timing.propseg);
        ral::write_reg!(ral::can, self.regs, CTRL1, ctrl1);
        // RFFN = 0 (8 filters), remote frames stored rather than answered.
        ral::write_reg!(ral::can, self.regs, CTRL2, CTRL2_RRS);
        // RX FIFO, individual masks, no self-reception, user mode, warnings, transmit abort,
        // buffers 0..=15.
        let maxmb = u32::try_from(LAST_MB).unwrap_or(15);
        let mcr = ral::read_reg!(ral::can, self.regs, MCR)
            & !(MCR_SUPV | 0x7F | (0b11 << 8) | can3::MCR_FDEN);
        ral::write_reg!(
            ral::can,
            self.regs,
            MCR,
            mcr | MCR_RFEN | MCR_IRMQ | MCR_SRXDIS | MCR_WRNEN | MCR_AEN | maxmb
        );

        // Accept everything: filter entries 0 with all-zero ("don't care") masks.
        for index in 0..FIFO_FILTERS {
            if let Some(mask) = self.regs.RXIMR.get(index) {
                mask.write(0);
            }
        }
        ral::write_reg!(ral::can, self.regs, RXFGMASK, 0);
        for word in 0..FIFO_FILTERS {
            self.write_mb_word(6 + word / 4, word % 4, 0);
        }
        for mb in ERRATA_MB..=LAST_MB {
            self.write_mb_word(mb, 0, frame::cs_with_code(code::TX_INACTIVE));
        }
        ral::write_reg!(ral::can, self.regs, IFLAG1, u32::MAX);
        ral::write_reg!(ral::can, self.regs, IMASK1, 0);

        ral::modify_reg!(ral::can, self.regs, MCR, |mcr| mcr & !(MCR_FRZ | MCR_HALT));
        self.wait_mcr(MCR_FRZACK, false, "leave freeze mode")?;
        self.wait_mcr(MCR_NOTRDY, false, "synchronise to the bus")
    }

    fn wait_mcr(&self, bit: u32, set: bool, what: &'static str) -> Result<(), InitError> {
        for _ in 0..POLL_LIMIT {
            let mcr = ral::read_reg!(ral::can, self.regs, MCR);
            if (mcr & bit != 0) == set {
                return Ok(());
            }
        }
        Err(InitError::Timeout(what))
    }

    /// Enables the "frame received" interrupt (and the FIFO overflow one, so a lost frame is
    /// counted as soon as it happens). Unmask the CAN1/CAN2 vector in the NVIC as well.
    pub fn enable_rx_interrupt(&mut self) {
        ral::modify_reg!(ral::can, self.regs, IMASK1, |mask| {
            mask | IFLAG_FIFO_AVAILABLE | IFLAG_FIFO_OVERFLOW
        });
    }

    /// The next received frame, oldest first, or `None` when the FIFO is empty. Also counts
    /// and clears a FIFO overflow.
    pub fn receive(&mut self) -> Option<CanFrame> {
        let flags = ral::read_reg!(ral::can, self.regs, IFLAG1);
        if flags & IFLAG_FIFO_OVERFLOW != 0 {
            self.rx_fifo_overflows = self.rx_fifo_overflows.wrapping_add(1);
            ral::write_reg!(
                ral::can,
                self.regs,
                IFLAG1,
                IFLAG_FIFO_OVERFLOW | IFLAG_FIFO_WARNING
            );
        }
        if flags & IFLAG_FIFO_AVAILABLE == 0 {
            return None;
        }
        let words = [0, 1, 2, 3].map(|word| self.read_mb_word(0, word));
        // Clearing the flag pops the FIFO (and reading TIMER releases the buffer lock).
        ral::write_reg!(ral::can, self.regs, IFLAG1, IFLAG_FIFO_AVAILABLE);
        let _ = ral::read_reg!(ral::can, self.regs, TIMER);
        Some(frame::rx_frame(words))
    }

    /// Queues `frame` for transmission in a free mailbox.
    pub fn transmit(&mut self, frame: &CanFrame) -> Result<(), TxError> {
        let words = frame::tx_words(frame);
        let mut free = None;
        for mb in FIRST_TX_MB..=LAST_MB {
            let cs = self.read_mb_word(mb, 0);
            if frame::code_of(cs) == code::TX_DATA {
                if frame::id_of(cs, self.read_mb_word(mb, 1)) == embedded_can::Frame::id(frame) {
                    return Err(TxError::Busy);
                }
            } else if free.is_none() {
                free = Some(mb);
            }
        }
        let mb = free.ok_or(TxError::Busy)?;
        if let Some(bit) = 1u32.checked_shl(u32::try_from(mb).unwrap_or(u32::MAX)) {
            ral::write_reg!(ral::can, self.regs, IFLAG1, bit);
        }
        self.write_mb_word(mb, 0, frame::cs_with_code(code::TX_INACTIVE));
        self.write_mb_word(mb, 1, words[1]);
        self.write_mb_word(mb, 2, words[2]);
        self.write_mb_word(mb, 3, words[3]);
        self.write_mb_word(mb, 0, words[0]);
        // ERR005829: write the reserved first buffer inactive twice after arming one.
        self.write_mb_word(ERRATA_MB, 0, frame::cs_with_code(code::TX_INACTIVE));
        self.write_mb_word(ERRATA_MB, 0, frame::cs_with_code(code::TX_INACTIVE));
        Ok(())
    }

    /// Queues `frame`, first aborting a pending frame with the same identifier (counted in
    /// [`BusStatus::tx_dropped`] unless it went out while the abort was requested): the
    /// newest command replaces a stale one instead of queueing behind it.
    pub fn transmit_latest(&mut self, frame: &CanFrame) -> Result<(), TxError> {
        let id = embedded_can::Frame::id(frame);
        for mb in FIRST_TX_MB..=LAST_MB {
            let cs = self.read_mb_word(mb, 0);
            if frame::code_of(cs) == code::TX_DATA
                && frame::id_of(cs, self.read_mb_word(mb, 1)) == id
            {
                self.abort(mb);
            }
        }
        self.transmit(frame)
    }

    /// Reads the error state; on an entry into bus-off (ESR1.BOFFINT), counts it, clears
    /// the flag and aborts every pending frame. Call it periodically (every control step).
    pub fn check_errors(&mut self) -> BusStatus {
        let esr1 = ral::read_reg!(ral::can, self.regs, ESR1);
        if esr1 & ESR1_BOFFINT != 0 {
            ral::write_reg!(ral::can, self.regs, ESR1, ESR1_BOFFINT);
            self.bus_off_events = self.bus_off_events.wrapping_add(1);
            for mb in FIRST_TX_MB..=LAST_MB {
                if frame::code_of(self.read_mb_word(mb, 0)) == code::TX_DATA {
                    self.abort(mb);
                }
            }
        }
        self.status_from(esr1)
    }

    /// Error counters, fault confinement state and the drop counts.
    pub fn status(&self) -> BusStatus {
        self.status_from(ral::read_reg!(ral::can, self.regs, ESR1))
    }

    fn status_from(&self, esr1: u32) -> BusStatus {
        let ecr = ral::read_reg!(ral::can, self.regs, ECR);
        let [tx_errors, rx_errors, _, _] = ecr.to_le_bytes();
        BusStatus {
            state: FaultState::from_esr1(esr1),
            tx_errors,
            rx_errors,
            rx_fifo_overflows: self.rx_fifo_overflows,
            bus_off_events: self.bus_off_events,
            tx_dropped: self.tx_dropped,
        }
    }

    /// Aborts the pending frame in `mb` (RM "Transmission abort mechanism"): clear the
    /// buffer's flag, write ABORT, wait for the flag (at most the rest of a frame on the
    /// wire), then read whether it was aborted or sent. Leaves the buffer free.
    ///
    /// ERR006032 first: aborting or deactivating a buffer while the bus is idle can send a
    /// frame with a wrong identifier or payload, so an abort never lands in that window (see
    /// [`Self::deactivate_if_bus_idle`]). Call it with this controller's interrupt masked (the
    /// firmware holds the controller's lock), as the workaround requires.
    fn abort(&mut self, mb: usize) {
        let Some(bit) = u32::try_from(mb).ok().and_then(|mb| 1u32.checked_shl(mb)) else {
            return;
        };
        ral::write_reg!(ral::can, self.regs, IFLAG1, bit);
        if self.deactivate_if_bus_idle(mb) {
            // Whether the frame still left cannot be known: count it as not sent.
            self.tx_dropped = self.tx_dropped.wrapping_add(1);
            ral::write_reg!(ral::can, self.regs, IFLAG1, bit);
            self.write_mb_word(mb, 0, frame::cs_with_code(code::TX_INACTIVE));
            return;
        }
        self.write_mb_word(mb, 0, frame::cs_with_code(code::TX_ABORT));
        let finished =
            (0..POLL_LIMIT).any(|_| ral::read_reg!(ral::can, self.regs, IFLAG1) & bit != 0);
        let aborted = frame::code_of(self.read_mb_word(mb, 0)) == code::TX_ABORT;
        if finished {
            ral::write_reg!(ral::can, self.regs, IFLAG1, bit);
        }
        if aborted || !finished {
            self.tx_dropped = self.tx_dropped.wrapping_add(1);
        }
        // Park the buffer whatever happened, so `transmit` can reuse it.
        self.write_mb_word(mb, 0, frame::cs_with_code(code::TX_INACTIVE));
    }

    /// ERR006032's workaround, as NXP's SDK applies it on every FlexCAN instance of the
    /// i.MX RT1060: read the protocol state (DBG1.CFSM). In the third bit of an intermission
    /// (DBG1.CBN = 3) after a received or sent frame, wait until it ends; if the bus is then
    /// idle, wait a little more and deactivate the buffer by writing code 0 rather than
    /// aborting it. Returns true when it deactivated the buffer (no abort must follow).
    ///
    /// DBG1 is at 0x58 on CAN1/CAN2 (imxrt-ral's block); imxrt-ral's CAN3 block leaves that
    /// offset out, while NXP's SDK reads it there on FlexCAN3 as well.
    fn deactivate_if_bus_idle(&mut self, mb: usize) -> bool {
        let dbg1 = ral::read_reg!(ral::can, self.regs, DBG1);
        let state = dbg1 & DBG1_CFSM_MASK;
        if matches!(state, CFSM_RX_INTERMISSION | CFSM_TX_INTERMISSION)
            && (dbg1 >> DBG1_CBN_SHIFT) & DBG1_CBN_MASK == 3
        {
            let _ = (0..POLL_LIMIT)
                .any(|_| ral::read_reg!(ral::can, self.regs, DBG1) & DBG1_CFSM_MASK != state);
        }
        if ral::read_reg!(ral::can, self.regs, DBG1) & DBG1_CFSM_MASK != CFSM_BUS_IDLE {
            return false;
        }
        for _ in 0..ERR006032_IDLE_DELAY {
            core::hint::spin_loop();
        }
        let cs = self.read_mb_word(mb, 0);
        self.write_mb_word(mb, 0, cs & !frame::CODE_MASK);
        true
    }

    fn mb_word_ptr(&self, mb: usize, word: usize) -> *mut u32 {
        let base = core::ptr::from_ref::<ral::can::RegisterBlock>(&self.regs).cast::<u32>();
        base.cast_mut()
            .wrapping_add(MB_RAM_WORD_OFFSET + mb * 4 + word)
    }

    fn read_mb_word(&self, mb: usize, word: usize) -> u32 {
        debug_assert!(mb <= LAST_MB && word < 4);
        // SAFETY: `mb` <= LAST_MB and `word` < 4 (all callers use constants in range), so the
        // address is inside this instance's message-buffer RAM, which is always mapped.
        unsafe { self.mb_word_ptr(mb, word).read_volatile() }
    }

    fn write_mb_word(&mut self, mb: usize, word: usize, value: u32) {
        debug_assert!(mb <= LAST_MB && word < 4);
        // SAFETY: as in `read_mb_word`; we own the instance, so nothing else writes it.
        unsafe { self.mb_word_ptr(mb, word).write_volatile(value) }
    }
}

/// Selects the 24 MHz oscillator for the CAN clock root (shared by all three instances) and
/// ungates instance `N`'s clocks: CCGR0 CG7/CG8 (CAN1), CG9/CG10 (CAN2), CCGR7 CG3/CG4 (CAN3).
fn enable_clock<const N: u8>(ccm: &ral::ccm::CCM) -> Result<(), InitError> {
    ral::modify_reg!(ral::ccm, ccm, CSCMR2, CAN_CLK_SEL: 1, CAN_CLK_PODF: 0);
    match N {
        1 => ral::modify_reg!(ral::ccm, ccm, CCGR0, CG7: 0b11, CG8: 0b11),
        2 => ral::modify_reg!(ral::ccm, ccm, CCGR0, CG9: 0b11, CG10: 0b11),
        3 => ral::modify_reg!(ral::ccm, ccm, CCGR7, CG3: 0b11, CG4: 0b11),
        _ => return Err(InitError::WrongPins),
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fault_confinement_reads_from_esr1_fltconf() {
        assert_eq!(FaultState::from_esr1(0), FaultState::ErrorActive);
        assert_eq!(FaultState::from_esr1(0b01 << 4), FaultState::ErrorPassive);
        assert_eq!(FaultState::from_esr1(0b10 << 4), FaultState::BusOff);
        assert_eq!(FaultState::from_esr1(0b11 << 4), FaultState::BusOff);
        // Other ESR1 bits (BOFFINT, error flags) do not change the state.
        assert_eq!(
            FaultState::from_esr1(ESR1_BOFFINT | 0xFC00),
            FaultState::ErrorActive
        );
    }
}
