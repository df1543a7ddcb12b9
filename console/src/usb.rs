//! The Teensy's USB CDC serial device: the console's log out, typed bytes in.
//!
//! It enumerates as PJRC's Teensy USB serial (16C0:0483), with the image's own product string
//! and the chip's unique id as its serial number, so two boards on one host get two
//! `/dev/serial/by-id` names. A host that sets the line rate to 134 baud (what
//! `teensy_loader_cli -s` does) asks for the bootloader: the console reports the request
//! ([`UsbConsole::serve`]'s result) and the image decides whether it is safe to obey. Poll it
//! from the USB_OTG1 interrupt at the lowest priority: it only copies bytes between the host
//! and the console's buffers, and never waits.

pub use teensy4_bsp::usbd::EndpointState;

use crate::bench::{After, BenchBoard, BenchLoop, Line};
use crate::log::{LineReader, LogBuffer};
use crate::{Command, REBOOT_BAUD, Reboot, RebootRequest, StatusRequest};
use core::sync::atomic::{AtomicU32, Ordering};
use rtic_core::Mutex;
use teensy4_bsp::hal::gpio::Input;
use teensy4_bsp::usbd::{
    BusAdapter, EndpointMemory, Speed,
    gpt::{Instance::Gpt0, Mode},
};
use usb_device::{
    LangID,
    bus::UsbBusAllocator,
    device::{StringDescriptors, UsbDevice, UsbDeviceBuilder, UsbDeviceState, UsbVidPid},
};
use usbd_serial::SerialPort;

/// PJRC's USB serial identity, which `teensy_loader_cli -s` looks for.
pub const VID_PID: UsbVidPid = UsbVidPid(0x16C0, 0x0483);

/// Endpoint memory for the device (static: the USB controller reads it by DMA).
pub type Memory = EndpointMemory<1024>;
/// The device's bus, kept in a static slot.
pub type Bus = UsbBusAllocator<BusAdapter>;

/// The console's USB device.
pub struct UsbConsole {
    device: UsbDevice<'static, BusAdapter>,
    serial: SerialPort<'static, BusAdapter>,
    configured: bool,
    /// The host's line rate was 134 baud at the last poll (a request is its rising edge).
    reboot_rate: bool,
}

/// Why the device could not be built.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UsbError;

/// The static memory the USB device keeps (the image's `#[init(local = [..])]`): endpoint
/// memory and state (read by the controller's DMA), the bus, the serial number's text.
pub struct UsbMemory {
    pub memory: &'static mut Memory,
    pub state: &'static mut EndpointState,
    pub bus: &'static mut Option<Bus>,
    pub serial: &'static mut [u8; 16],
}

impl UsbConsole {
    /// Builds the device on USB1, naming itself `product` with the chip's unique id as its
    /// serial number ([`chip_serial`]). The GPT0 timer of the USB block interrupts every
    /// 10 ms, so the log drains while the host is idle too.
    pub fn new(
        usb: teensy4_bsp::usbd::Instances<1>,
        kept: UsbMemory,
        product: &'static str,
    ) -> Result<Self, UsbError> {
        let serial_number = chip_serial(kept.serial);
        let slot = kept.bus;
        let adapter = BusAdapter::with_speed(usb, kept.memory, kept.state, Speed::LowFull);
        adapter.set_interrupts(true);
        adapter.gpt_mut(Gpt0, |gpt| {
            gpt.stop();
            gpt.clear_elapsed();
            gpt.set_interrupt_enabled(true);
            gpt.set_mode(Mode::Repeat);
            gpt.set_load(10_000);
            gpt.reset();
            gpt.run();
        });
        let bus: &'static Bus = slot.insert(UsbBusAllocator::new(adapter));
        let serial = SerialPort::new(bus);
        let device = UsbDeviceBuilder::new(bus, VID_PID)
            .strings(&[StringDescriptors::new(LangID::EN_US)
                .manufacturer("AER")
                .product(product)
                .serial_number(serial_number)])
            .map_err(|_| UsbError)?
            .device_class(usbd_serial::USB_CLASS_CDC)
            .build();
        Ok(Self {
            device,
            serial,
            configured: false,
            reboot_rate: false,
        })
    }

    /// Services the device: offers `outgoing` to the host and returns how many of its bytes
    /// were taken, hands every received byte to `typed`, and says whether the host just asked
    /// for the bootloader (set 134 baud).
    pub fn poll(&mut self, outgoing: &[u8], mut typed: impl FnMut(u8)) -> Polled {
        self.device.bus().gpt_mut(Gpt0, |gpt| {
            while gpt.is_elapsed() {
                gpt.clear_elapsed();
            }
        });
        if self.device.poll(&mut [&mut self.serial]) {
            if self.device.state() == UsbDeviceState::Configured {
                if !self.configured {
                    self.device.bus().configure();
                }
                self.configured = true;
            } else {
                self.configured = false;
            }
            let mut input = [0u8; 64];
            if let Ok(count) = self.serial.read(&mut input) {
                input.iter().take(count).for_each(|&byte| typed(byte));
            }
        }
        let reboot_rate = self.serial.line_coding().data_rate() == REBOOT_BAUD;
        let reboot_requested = reboot_rate && !self.reboot_rate;
        self.reboot_rate = reboot_rate;
        let mut sent = 0;
        while self.configured && sent < outgoing.len() {
            match self.serial.write(outgoing.get(sent..).unwrap_or(&[])) {
                Ok(written) if written > 0 => sent += written,
                _ => break,
            }
        }
        Polled {
            sent,
            reboot_requested,
        }
    }

    /// [`poll`](Self::poll) for a log shared with the control tasks: the log's lock is held
    /// only to copy up to [`STAGED_BYTES`] out and, after the USB work, to drop what the host
    /// took, so a task that logs never waits for USB. Typed bytes are gathered into lines by
    /// `reader`; each complete line goes to `on_line`. Returns true when the host just asked
    /// for the bootloader by its line rate.
    pub fn serve<const N: usize, const L: usize>(
        &mut self,
        log: &mut impl Mutex<T = LogBuffer<N>>,
        reader: &mut LineReader<L>,
        mut on_line: impl FnMut(&str),
    ) -> bool {
        let mut staged = [0u8; STAGED_BYTES];
        let count = log.lock(|log| log.peek(&mut staged));
        let polled = self.poll(staged.get(..count).unwrap_or(&[]), |byte| {
            if let Some(line) = reader.push(byte) {
                on_line(line);
            }
        });
        if polled.sent > 0 {
            log.lock(|log| log.consume(polled.sent));
        }
        polled.reboot_requested
    }
}

/// The race images' console task: the log out, typed bytes in. Only `bootloader`, `restart`
/// and `status` are taken, as requests the control task grants, refuses or answers (the
/// host's 134 baud asks for the bootloader). An image without a console (`None`: the USB device did not
/// start) runs as before.
pub fn serve_race<const N: usize>(
    console: Option<&mut UsbConsole>,
    log: &mut impl Mutex<T = LogBuffer<N>>,
    typed: &mut LineReader<64>,
    reboot: &RebootRequest,
    status: &StatusRequest,
) {
    let Some(console) = console else {
        return;
    };
    let host_asks = console.serve(log, typed, |line| match Command::parse(line) {
        Ok(Command::Bootloader) => reboot.request(Reboot::Bootloader),
        Ok(Command::Restart) => reboot.request(Reboot::Restart),
        Ok(Command::Status) => status.request(),
        _ => {}
    });
    if host_asks {
        reboot.request(Reboot::Bootloader);
    }
}

/// The bring-up images' console task: every typed line goes to the bench loop
/// ([`crate::bench`]); typing faster than the loop takes lines drops them.
pub fn serve_bench<const N: usize>(
    console: Option<&mut UsbConsole>,
    log: &mut impl Mutex<T = LogBuffer<N>>,
    typed: &mut LineReader<64>,
    lines: &mut heapless::spsc::Producer<'static, Line>,
    reboot: &RebootRequest,
) {
    let Some(console) = console else {
        return;
    };
    let host_asks = console.serve(log, typed, |typed| {
        let mut line = Line::new();
        if line.push_str(typed).is_ok() {
            let _dropped = lines.enqueue(line);
        }
    });
    if host_asks {
        reboot.request(Reboot::Bootloader);
    }
}

/// One step of a bring-up image's bench loop as its task runs it: the lines typed since the
/// last step (from the USB interrupt) and the log under its lock. A reboot it returns
/// (every output already safe) goes to [`hand_over`] after the caller's 2 ms.
pub fn bench_step<B: BenchBoard, const N: usize>(
    bench: &mut BenchLoop,
    board: &mut B,
    now_ms: u32,
    lines: &mut heapless::spsc::Consumer<'static, Line>,
    shared: &B::Shared,
    log: &mut impl Mutex<T = LogBuffer<N>>,
    reboot: &RebootRequest,
) -> After {
    let typed = core::iter::from_fn(|| lines.dequeue());
    log.lock(|log| bench.step(board, now_ms, typed, reboot, shared, log))
}

/// What [`bench_step`] asked for, once the caller has let the safe commands leave the CAN
/// mailboxes (two frame times at 500 kbit/s: the caller waits 2 ms first): the bootloader, or a
/// restart; the panic `panic test` asked for. Nothing for [`After::Continue`].
pub fn hand_over(after: After) {
    match after {
        After::Continue => {}
        After::Bootloader => reboot_to_bootloader(),
        After::Restart => restart(),
        After::Panic => panic!("panic test"),
    }
}

/// What one poll did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Polled {
    /// Bytes of the log the host took.
    pub sent: usize,
    /// The host just set 134 baud: it asks for the bootloader.
    pub reboot_requested: bool,
}

/// The chip's 64-bit unique id (OCOTP CFG0 and CFG1, fused at manufacture).
pub fn chip_id() -> u64 {
    // SAFETY: the OCOTP shadow registers are read-only here and loaded by the boot ROM before
    // any code runs; nothing else in the images writes the OCOTP block.
    let ocotp = unsafe { teensy4_bsp::ral::ocotp::OCOTP::instance() };
    let high = teensy4_bsp::ral::read_reg!(teensy4_bsp::ral::ocotp, ocotp, CFG1);
    let low = teensy4_bsp::ral::read_reg!(teensy4_bsp::ral::ocotp, ocotp, CFG0);
    u64::from(high) << 32 | u64::from(low)
}

/// The chip's unique id ([`chip_id`]) as the USB serial number: 16 hex digits written into
/// `text`, which the device then keeps.
pub fn chip_serial(text: &'static mut [u8; 16]) -> &'static str {
    crate::serial_number(chip_id(), text)
}

/// Bytes of log copied out per USB poll.
pub const STAGED_BYTES: usize = 512;

/// Counts a rising edge on each of `inputs` whose interrupt flag is set (and clears it): the
/// body of a GPIO edge interrupt.
pub fn count_rising_edges(inputs: &[Input], counters: &[AtomicU32]) {
    for (input, edges) in inputs.iter().zip(counters) {
        if input.is_triggered() {
            input.clear_triggered();
            edges.fetch_add(1, Ordering::Relaxed);
        }
    }
}

/// What an image does on a board it was not built for (or cannot identify): nothing but the
/// console. Its USB device names the mistake in its product string; the check's line is
/// offered to the host every 5 s; `bootloader` (typed or 134 baud) and `restart` are obeyed at
/// once, as no output was ever driven. Called before any pin is configured, the watchdog not
/// started.
pub fn wrong_board(
    usb: teensy4_bsp::usbd::Instances<1>,
    kept: UsbMemory,
    check: crate::board_check::BoardCheck,
) -> ! {
    let Ok(mut console) = UsbConsole::new(usb, kept, check.wrong_board_product()) else {
        // No console to say it on: the image stays idle, every pin as reset left it.
        loop {
            cortex_m::asm::wfi();
        }
    };
    let mut log = LogBuffer::<1024>::new();
    let mut reader = LineReader::<64>::new();
    let mut tick: u32 = 0;
    loop {
        if tick % 5_000 == 0 && log.is_empty() {
            log.line(format_args!("{check}"));
        }
        tick = tick.wrapping_add(1);
        let mut staged = [0u8; STAGED_BYTES];
        let count = log.peek(&mut staged);
        let mut asked = None;
        let polled = console.poll(staged.get(..count).unwrap_or(&[]), |byte| {
            if let Some(line) = reader.push(byte) {
                match Command::parse(line) {
                    Ok(Command::Bootloader) => asked = Some(Reboot::Bootloader),
                    Ok(Command::Restart) => asked = Some(Reboot::Restart),
                    _ => {}
                }
            }
        });
        log.consume(polled.sent);
        if polled.reboot_requested {
            asked = Some(Reboot::Bootloader);
        }
        match asked {
            Some(Reboot::Bootloader) => reboot_to_bootloader(),
            Some(Reboot::Restart) => restart(),
            None => {}
        }
        cortex_m::asm::delay(600_000);
    }
}

/// Hands the chip to the Teensy's bootloader: a breakpoint with immediate 251, which PJRC's
/// own firmware executes for a soft reboot on a Teensy 4 that is not locked.
pub fn reboot_to_bootloader() -> ! {
    cortex_m_bkpt_251();
    loop {
        core::hint::spin_loop();
    }
}

/// Starts the image again from reset: a system reset request (AIRCR SYSRESETREQ), which
/// SRC_SRSR reports as a software reset, not a watchdog's, so the image starts as after a
/// power cycle. The caller has made every output safe.
pub fn restart() -> ! {
    const AIRCR: *mut u32 = 0xE000_ED0C as *mut u32;
    const VECTKEY_SYSRESETREQ: u32 = 0x05FA_0004;
    // SAFETY: AIRCR is the Cortex-M7's Application Interrupt and Reset Control Register
    // (ARMv7-M ARM B3.2.6); writing the key with SYSRESETREQ only requests a reset. Every
    // memory write before it is finished first (the barrier).
    unsafe {
        core::arch::asm!("dsb");
        core::ptr::write_volatile(AIRCR, VECTKEY_SYSRESETREQ);
        core::arch::asm!("dsb");
    }
    loop {
        core::hint::spin_loop();
    }
}

fn cortex_m_bkpt_251() {
    // SAFETY: a breakpoint instruction, nothing else. The Teensy's bootloader chip watches the
    // core's debug port and starts the bootloader on it (PJRC's own soft reboot). Should it
    // not, the breakpoint escalates to a HardFault and the watchdog restarts the chip.
    unsafe { core::arch::asm!("bkpt #251") };
}
