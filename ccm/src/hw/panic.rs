//! The CCM's panic handler, both images': the inverter's stop frames on CAN2 first, then a
//! reset at once, so torque stops within a frame time whatever the inverter's own command
//! timeout is set to (a DTI whose CAN timeout was left disabled holds its last current for
//! ever).
//!
//! It runs with whatever state the program had when it panicked, so it builds nothing and
//! takes no lock: the frames are the copy the control task last published
//! ([`crate::stop::STOP`]), written into CAN2's transmit mailboxes by address
//! ([`EmergencyTx`]), and only once CAN2 has started ([`inverter_bus_started`]). It waits a
//! bounded time for them to leave, then resets through WDOG1's software reset (start-up then
//! reads `watchdog`), with a system reset request behind it should that not take.

use crate::stop::STOP;
use aer_flexcan::emergency::EmergencyTx;
use core::panic::PanicInfo;
use core::sync::atomic::{AtomicBool, Ordering};
use teensy4_bsp::ral;

/// IFLAG1 polls while the stop frames leave: about 3 ms at 600 MHz, time for four frames
/// behind a busy bus's higher-priority traffic at 500 kbit/s. A bus that takes nothing (bus-off, unplugged)
/// costs this much before the reset.
const SEND_POLLS: u32 = 300_000;

/// IFLAG1 polls while one pending frame is aborted: the rest of a frame already on the wire
/// (about 270 us at 500 kbit/s) with margin. Seven pending frames at most.
const ABORT_POLLS: u32 = 30_000;

/// CAN2 is clocked and configured: the mailboxes may be written.
static INVERTER_BUS: AtomicBool = AtomicBool::new(false);

/// Called once CAN2 has started: from then on a panic sends the stop frames.
pub fn inverter_bus_started() {
    INVERTER_BUS.store(true, Ordering::Release);
}

#[panic_handler]
fn panic(_: &PanicInfo<'_>) -> ! {
    stop_and_reset()
}

/// A fault no Rust panic reports (a bus fault, a stack overflow, an undefined instruction)
/// escalates here: the inverter is stopped the same way.
#[teensy4_bsp::rt::exception]
unsafe fn HardFault(_frame: &teensy4_bsp::rt::ExceptionFrame) -> ! {
    stop_and_reset()
}

/// An interrupt or exception nothing handles: a defect, treated as a panic.
#[teensy4_bsp::rt::exception]
unsafe fn DefaultHandler(_irqn: i16) {
    stop_and_reset()
}

fn stop_and_reset() -> ! {
    cortex_m::interrupt::disable();
    if INVERTER_BUS.load(Ordering::Acquire) {
        // SAFETY: CAN2's register block (imxrt-ral's address); it started (`INVERTER_BUS`),
        // and with interrupts off nothing else runs to write it after a panic.
        let mut tx = unsafe { EmergencyTx::new(ral::can::CAN2 as *mut u32) };
        let queued = tx.queue(STOP.latest_frames(), ABORT_POLLS);
        let _sent = tx.wait_sent(queued.mask, SEND_POLLS);
    }
    // SAFETY: WDOG1 is the watchdog both images start; clearing WCR.SRS asserts its software
    // reset (i.MX RT1060 RM, WDOG chapter). Nothing else runs.
    unsafe {
        let wdog = ral::wdog::WDOG1::instance();
        ral::modify_reg!(ral::wdog, wdog, WCR, SRS: 0);
    }
    cortex_m::asm::delay(60_000);
    aer_console::usb::restart()
}
