//! FlexCAN3 in classic CAN mode.
//!
//! FlexCAN3 is the i.MX RT1062's CAN FD-capable controller, with a register block of its own
//! (imxrt-ral's `can3`). With MCR.FDEN clear (its reset value, and cleared again at start-up)
//! it works as a classic controller: 16-byte message buffers at offset 0x80, the legacy RX FIFO,
//! CTRL1's bit timing (CBT.BTF clear). Every register this driver touches sits at the same offset
//! as in CAN1/CAN2's block; the assertions below check that against imxrt-ral for each of them,
//! so the driver can address CAN3 through the classic block's layout.
//!
//! imxrt-iomuxc 0.3 has no FlexCAN3 pads, so the Teensy 4.1's CAN3 pins (31 = GPIO_EMC_36 TX,
//! 30 = GPIO_EMC_37 RX) are muxed here: ALT 9 on both, and FlexCAN3's RX select-input register
//! pointed at GPIO_EMC_37.

use crate::ral;
use core::mem::offset_of;
use imxrt_iomuxc::imxrt1060::gpio_emc::{GPIO_EMC_36, GPIO_EMC_37};

/// Teensy 4.1 pin 31: FlexCAN3 TX.
pub type TxPad = GPIO_EMC_36;
/// Teensy 4.1 pin 30: FlexCAN3 RX.
pub type RxPad = GPIO_EMC_37;

/// Mux mode of GPIO_EMC_36/37 that connects them to FlexCAN3 (i.MX RT1060 RM, IOMUXC
/// "SW_MUX_CTL_PAD_GPIO_EMC_36/37": ALT9 = FLEXCAN3_TX / FLEXCAN3_RX).
const ALT_FLEXCAN3: u32 = 9;
/// IOMUXC_CANFD_IPP_IND_CANRX_SELECT_INPUT: which pad feeds FlexCAN3's RX.
const CANFD_RX_SELECT_INPUT: *mut u32 = 0x401F_8788 as *mut u32;
/// Its value for GPIO_EMC_37 (ALT9).
const CANFD_RX_FROM_GPIO_EMC_37: u32 = 1;

/// MCR.FDEN: CAN FD operation (CAN3 only; reserved and zero on CAN1/CAN2).
pub(crate) const MCR_FDEN: u32 = 1 << 11;

macro_rules! same_offset {
    ($($register:ident),* $(,)?) => {
        $(
            const _: () = assert!(
                offset_of!(ral::can::RegisterBlock, $register)
                    == offset_of!(ral::can3::RegisterBlock, $register),
                concat!("CAN3's ", stringify!($register), " is not where CAN1/CAN2 have it"),
            );
        )*
    };
}

same_offset!(
    MCR, CTRL1, TIMER, RXMGMASK, RX14MASK, RX15MASK, ECR, ESR1, IMASK2, IMASK1, IFLAG2, IFLAG1,
    CTRL2, ESR2, CRCR, RXFGMASK, RXFIR, RXIMR,
);
// Message buffer 0 starts at 0x80 in both blocks (the driver addresses buffers from there).
const _: () = assert!(offset_of!(ral::can3::RegisterBlock, CS0) == 0x80);
const _: () = assert!(offset_of!(ral::can::RegisterBlock, RXIMR) == 0x880);

/// CAN3's registers, addressed through the classic block's layout (every register the driver
/// uses is at the same offset, checked above).
pub(crate) fn classic_view(_regs: ral::can3::CAN3) -> ral::can::Instance<3> {
    // SAFETY: the pointer is CAN3's register block, which we own (the argument is consumed);
    // every field of `can::RegisterBlock` the driver accesses is at the same offset in it,
    // and the classic block is smaller than CAN3's, so no access leaves CAN3's block.
    unsafe { ral::can::Instance::new(ral::can3::CAN3.cast::<ral::can::RegisterBlock>()) }
}

const _: () = assert!(
    size_of::<ral::can::RegisterBlock>() <= size_of::<ral::can3::RegisterBlock>(),
    "the classic view must not reach past CAN3's block"
);

/// Connects pins 31 (TX) and 30 (RX) to FlexCAN3.
pub(crate) fn mux_pins(tx: &mut TxPad, rx: &mut RxPad) {
    imxrt_iomuxc::alternate(tx, ALT_FLEXCAN3);
    imxrt_iomuxc::alternate(rx, ALT_FLEXCAN3);
    imxrt_iomuxc::set_sion(rx);
    // SAFETY: a write-only select-input register that only FlexCAN3's RX reads; we own the
    // pads that it selects between.
    unsafe { CANFD_RX_SELECT_INPUT.write_volatile(CANFD_RX_FROM_GPIO_EMC_37) };
}
