//! The PCC's hardware, set up one way for both images (race and bring-up): the Teensy 4.0's
//! pins as the board wires them ([`board`]), pin 11 (AIR+) driven low before anything else,
//! the watchdog, the panic handler that opens AIR+, and [`start`], which brings up everything
//! the images share.
//!
//! Firmware only (feature `firmware`, thumbv7em): the logic stays in the portable modules;
//! this is the thin layer at the edge that touches registers.

pub mod board;

use aer_console::board_check::{BoardCheck, Teensy};
use aer_console::bringup::ResetCause;
use aer_console::usb::{UsbConsole, UsbMemory};
use aer_flexcan::{Flexcan, InitError};
use core::panic::PanicInfo;
use teensy4_bsp::{
    board as bsp,
    hal::{
        self, adc, gpio,
        iomuxc::{self, Config, PullKeeper},
    },
    ral,
};

/// Everything both images drive and read, set up.
pub struct Pcc {
    /// Pin 11, close AIR+ (high = closed): the board's only relay output, low from here on.
    pub air_plus: gpio::Output,
    /// The on-board LED.
    pub led: gpio::Output,
    /// The accumulator's and the tractive system's V/F converter outputs (pulled down: an
    /// unplugged converter reads low), interrupting on rising edges (GPIO1_COMBINED_16_31).
    pub vf: [gpio::Input; 2],
    /// The on-chip ADC, 12 bits.
    pub adc: adc::Adc,
    /// The precharge-resistor thermistors' pads (A7, A8), left as they are: only the
    /// bring-up image reads them.
    pub thermistors: board::ThermistorPins,
    /// CAN2, the vehicle bus (its start can fail: the race image halts, bring-up reports).
    pub can: Result<Flexcan<{ board::CAN_INSTANCE }>, InitError>,
    /// WDOG1, not started: each image starts it with its own timeout.
    pub wdog: ral::wdog::WDOG1,
    /// Why the chip started (SRC_SRSR, cleared for the next start).
    pub reset_cause: ResetCause,
    /// The board check: the board this image was built for, found (or the image would have
    /// stopped in `wrong_board`).
    pub board: BoardCheck,
    /// The USB serial console, if the device started (the images run without it).
    pub console: Option<UsbConsole>,
}

/// Start-up failed (a pin on the wrong port): the image halts with pin 11 low.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SetupFailed;

/// Brings the board up: the board check first (on a Teensy 4.1, or one the check cannot
/// identify, the image stops here in `wrong_board`, every pin as reset left it), then AIR+,
/// driven low (its pad pulled down before it becomes an output), the LED, the V/F inputs, the ADC, GPT1 on the 1 MHz peripheral clock (the image
/// starts its monotonic on it next), CAN2, the reset cause and the USB console named
/// `product`. The watchdog is the image's to start.
pub fn start(
    device: teensy4_bsp::Peripherals,
    usb_memory: UsbMemory,
    product: &'static str,
) -> Result<Pcc, SetupFailed> {
    let bsp::Resources {
        pins,
        mut gpio1,
        mut gpio2,
        mut gpt1,
        ccm,
        adc1,
        usb,
        ..
    } = bsp::t40(device);
    let mut pins = pins;
    board::park_air_plus(&mut pins);
    // Which board this is, before any pin is driven: on another one, nothing is.
    let check = BoardCheck {
        image: product,
        built_for: Teensy::T40,
        found: aer_console::chip::identify(),
    };
    if !check.right() {
        aer_console::usb::wrong_board(usb, usb_memory, check);
    }
    let mut pins = board::pins(pins);

    // AIR+ first, driven low, before anything else can run. A pin on the wrong port is a
    // build-time mistake in board.rs: the output then stays unconfigured (low through the
    // pull-down) and the image halts.
    let pull_down = Config::modify().set_pull_keeper(Some(PullKeeper::Pulldown100k));
    iomuxc::configure(&mut pins.air_plus, pull_down);
    let air_plus = gpio2.output(pins.air_plus).map_err(|_| SetupFailed)?;
    air_plus.clear();
    let led = gpio2.output(pins.led).map_err(|_| SetupFailed)?;
    iomuxc::configure(&mut pins.accumulator_freq, pull_down);
    iomuxc::configure(&mut pins.tractive_freq, pull_down);
    let vf = [
        gpio1
            .input(pins.accumulator_freq)
            .map_err(|_| SetupFailed)?,
        gpio1.input(pins.tractive_freq).map_err(|_| SetupFailed)?,
    ];
    for input in &vf {
        gpio1
            .set_interrupt(input, Some(gpio::Trigger::RisingEdge))
            .map_err(|_| SetupFailed)?;
    }
    let mut adc = adc1;
    adc.set_resolution(adc::ResolutionBits::Res12);

    // 1 MHz: microsecond edge stamps and the 10 ms schedule.
    gpt1.set_clock_source(hal::gpt::ClockSource::PeripheralClock);
    gpt1.set_divider(bsp::PERCLK_FREQUENCY / 1_000_000);

    // SAFETY: the BSP does not hand out the FlexCAN instances, SRC or WDOG1; nothing else uses
    // CAN2, the reset status or the watchdog.
    let (can_regs, src, wdog) = unsafe {
        (
            ral::can::CAN2::instance(),
            ral::src::SRC::instance(),
            ral::wdog::WDOG1::instance(),
        )
    };
    // Why this start (sticky flags, cleared so the next start is judged on its own).
    let srsr = ral::read_reg!(ral::src, src, SRSR);
    ral::write_reg!(ral::src, src, SRSR, srsr);
    let can = Flexcan::new(can_regs, pins.can_tx, pins.can_rx, &ccm, board::CAN_BITRATE);

    let console = UsbConsole::new(usb, usb_memory, product).ok();
    Ok(Pcc {
        air_plus,
        led,
        vf,
        adc,
        thermistors: pins.thermistors,
        can,
        wdog,
        reset_cause: ResetCause(srsr),
        board: check,
        console,
    })
}

/// WDOG1's timeout.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WatchdogTimeout {
    /// The race image: a hung control loop restarts the PCC (WT = 0).
    HalfSecond,
    /// The bring-up image, fed by its bench loop (WT = 1).
    OneSecond,
}

/// Starts WDOG1 with `timeout`. The power-down counter is switched off so only a missed
/// service restarts the PCC.
pub fn start_watchdog(wdog: &ral::wdog::WDOG1, timeout: WatchdogTimeout) {
    ral::write_reg!(ral::wdog, wdog, WMCR, 0);
    match timeout {
        WatchdogTimeout::HalfSecond => ral::modify_reg!(ral::wdog, wdog, WCR, WT: 0, WDE: 1),
        WatchdogTimeout::OneSecond => ral::modify_reg!(ral::wdog, wdog, WCR, WT: 1, WDE: 1),
    }
}

/// Services WDOG1.
pub fn feed_watchdog(wdog: &ral::wdog::WDOG1) {
    ral::write_reg!(ral::wdog, wdog, WSR, 0x5555);
    ral::write_reg!(ral::wdog, wdog, WSR, 0xAAAA);
}

/// Parks the core with pin 11 low. Only reachable at start-up, before the watchdog runs.
pub fn halt_safe() -> ! {
    loop {
        cortex_m::asm::wfi();
    }
}

/// Opens AIR+, then waits for the watchdog. Runs with whatever state the code had when it
/// panicked, so it touches nothing but pin 11's write-only clear register. Both images'.
#[panic_handler]
fn panic(_: &PanicInfo<'_>) -> ! {
    open_air_plus_and_wait()
}

/// A fault no Rust panic reports (a bus fault, a stack overflow, an undefined instruction)
/// escalates here: the same as a panic.
#[teensy4_bsp::rt::exception]
unsafe fn HardFault(_frame: &teensy4_bsp::rt::ExceptionFrame) -> ! {
    open_air_plus_and_wait()
}

/// An interrupt or exception nothing handles: a defect, treated as a panic.
#[teensy4_bsp::rt::exception]
unsafe fn DefaultHandler(_irqn: i16) {
    open_air_plus_and_wait()
}

fn open_air_plus_and_wait() -> ! {
    cortex_m::interrupt::disable();
    // SAFETY: DR_CLEAR is write-only and only clears the given bits; the mask is pin 11
    // (board.rs), an output from start-up onwards, so this can only open AIR+. Nothing else
    // in the program runs after a panic or a fault.
    unsafe {
        let gpio2 = ral::gpio::GPIO2::instance();
        ral::write_reg!(ral::gpio, gpio2, DR_CLEAR, board::AIR_PLUS_GPIO2_MASK);
    }
    loop {
        cortex_m::asm::nop();
    }
}
