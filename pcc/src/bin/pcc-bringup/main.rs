//! PCC bring-up image (Teensy 4.0): checks every pin of the board on the bench and reports
//! over USB serial (any terminal: `screen /dev/ttyACM0`, `picocom`, the Arduino monitor).
//!
//! At start: firmware, board revision, schema fingerprint, reset cause (a `watchdog test`
//! shows here after the reset), clocks. Every second: both V/F converters' levels, edge counts
//! and frequencies (with the voltage they mean), both thermistor inputs' counts and volts,
//! the CAN controller's state and what it heard. Pin 11 (AIR+) stays low unless typed:
//! `confirm hv-disconnected` (taken only while both converters are alive and read below
//! 60 V), then `out air-plus-close on` within 30 s; it drops again at the first 10 ms step
//! where the confirmation has expired or a converter reads 60 V or more or goes silent, on
//! `off`, on `bootloader`, on `restart` and on every reset. `help` lists
//! the commands.
//!
//! The gate reads both converters at every 10 ms step from the edge interrupt's time stamps:
//! a converter that gives no pulses is no reading (not 0 V), and no reading never arms pin 11.
//!
//! The hardware is set up by `aer_pcc::hw`, as in the race image (its panic handler opens
//! AIR+ here too); the loop and the commands every board answers alike are
//! `aer_console::bench`; this board's checks and answers are `aer_pcc::bench`, over the pins
//! in `bench.rs`. docs/bench-day.md quotes that library driven by a simulated board.
#![no_std]
#![no_main]

mod bench;

use aer_console::RebootRequest;
use core::sync::atomic::AtomicU32;
use rtic_monotonics::imxrt::prelude::*;

imxrt_gpt1_monotonic!(Mono, 1_000_000);

/// `bootloader` typed, or 134 baud from the host.
static REBOOT: RebootRequest = RebootRequest::new();
/// Rising edges of the accumulator and tractive-system V/F converters.
static EDGES: [AtomicU32; 2] = [AtomicU32::new(0), AtomicU32::new(0)];

#[rtic::app(device = teensy4_bsp, peripherals = true, dispatchers = [KPP])]
mod app {
    use crate::bench::TeensyPcc;
    use crate::{EDGES, Mono, REBOOT};
    use aer_console::bench::{After, BenchLoop, Line, QUEUED_LINES};
    use aer_console::bringup::Clocks;
    use aer_console::usb::{
        Bus, EndpointState, Memory, UsbConsole, UsbMemory, bench_step, hand_over, serve_bench,
    };
    use aer_console::{LineReader, LogBuffer};
    use aer_pcc::VfConfig;
    use aer_pcc::bench::{PccBench, VfInputs};
    use aer_pcc::console::BRINGUP_LOG_BYTES as LOG_BYTES;
    use aer_pcc::hw::{self, WatchdogTimeout, board, halt_safe};
    use aer_pcc::measurement::FrequencyMeter;
    use heapless::spsc::{Consumer, Producer, Queue};
    use rtic_monotonics::imxrt::prelude::*;
    use teensy4_bsp::{board as bsp, hal::gpio, ral};

    /// The clocks the start-up lines print are the BSP's.
    const _: () = assert!(
        bsp::ARM_FREQUENCY == Clocks::TEENSY4.core_hz
            && bsp::IPG_FREQUENCY == Clocks::TEENSY4.ipg_hz
            && bsp::PERCLK_FREQUENCY == Clocks::TEENSY4.perclk_hz
            && board::CAN_BITRATE == Clocks::TEENSY4.can_bitrate
    );

    #[shared]
    struct Shared {
        log: LogBuffer<LOG_BYTES>,
        /// The V/F converters' inputs: the edge interrupt counts, the report reads levels.
        vf: [gpio::Input; 2],
        /// Each converter's edges, time-stamped by the interrupt, read by every bench step.
        meters: [FrequencyMeter; 2],
    }

    #[local]
    struct Local {
        console: Option<UsbConsole>,
        typed: LineReader<64>,
        lines_in: Producer<'static, Line>,
        lines: Consumer<'static, Line>,
        bench: PccBench<TeensyPcc>,
    }

    #[init(local = [
        queue: Queue<Line, QUEUED_LINES> = Queue::new(),
        usb_memory: Memory = Memory::new(),
        usb_state: EndpointState = EndpointState::max_endpoints(),
        usb_bus: Option<Bus> = None,
        serial: [u8; 16] = [0; 16],
    ])]
    fn init(cx: init::Context) -> (Shared, Local) {
        let usb = UsbMemory {
            memory: cx.local.usb_memory,
            state: cx.local.usb_state,
            bus: cx.local.usb_bus,
            serial: cx.local.serial,
        };
        let Ok(board) = hw::start(cx.device, usb, "AER PCC bring-up") else {
            halt_safe()
        };
        // SAFETY: `hw::start` configured GPT1 and does not use it again; the monotonic owns it.
        Mono::start(
            unsafe { ral::gpt::GPT1::instance() },
            Priority::rtic_default(),
        );
        let mut log = LogBuffer::new();
        aer_pcc::console::bringup_startup(
            &mut log,
            &board::REVISION,
            board.reset_cause,
            board.board,
        );
        // WDOG1 at 1 s, fed by the bench loop (`watchdog test` stops feeding it).
        hw::start_watchdog(&board.wdog, WatchdogTimeout::OneSecond);
        // The V/F inputs are shared with their edge interrupt, the console with the USB's.
        let Ok((teensy, vf, console)) = TeensyPcc::new(board, &mut log) else {
            halt_safe()
        };
        let bench = PccBench::new(teensy, board::REVISION);
        let (lines_in, lines) = cx.local.queue.split();
        if bench::spawn().is_err() {
            halt_safe();
        }
        (
            Shared {
                log,
                vf,
                meters: [FrequencyMeter::default(); 2],
            },
            Local {
                console,
                typed: LineReader::new(),
                lines_in,
                lines,
                bench,
            },
        )
    }

    /// Counts and time-stamps each converter's rising edges.
    #[task(binds = GPIO1_COMBINED_16_31, priority = 2, shared = [vf, meters])]
    fn vf_edge(mut cx: vf_edge::Context) {
        let now_us = Mono::now().as_ticks() as u32;
        let meters = &mut cx.shared.meters;
        cx.shared.vf.lock(|vf| {
            meters.lock(|meters| {
                for ((input, edges), meter) in vf.iter().zip(&EDGES).zip(meters.iter_mut()) {
                    if input.is_triggered() {
                        input.clear_triggered();
                        edges.fetch_add(1, core::sync::atomic::Ordering::Relaxed);
                        meter.on_edge(now_us);
                    }
                }
            })
        });
    }

    #[task(binds = USB_OTG1, priority = 1, local = [console, typed, lines_in], shared = [log])]
    fn usb(mut cx: usb::Context) {
        serve_bench(
            cx.local.console.as_mut(),
            &mut cx.shared.log,
            cx.local.typed,
            cx.local.lines_in,
            &REBOOT,
        );
    }

    /// The bench loop, every 10 ms.
    #[task(priority = 1, local = [lines, bench], shared = [log, vf, meters])]
    async fn bench(mut cx: bench::Context) {
        let mut bench_loop = BenchLoop::new();
        let timeout_us = VfConfig::PCC_BOARD.edge_timeout_us;
        loop {
            let now = Mono::now().as_ticks();
            let now_ms = (now / 1_000) as u32;
            let now_us = now as u32;
            let levels = cx
                .shared
                .vf
                .lock(|vf| vf.each_ref().map(|input| input.is_set()));
            let hz = cx.shared.meters.lock(|meters| {
                meters
                    .each_mut()
                    .map(|meter| meter.reading(now_us, timeout_us))
            });
            let inputs = VfInputs { levels, hz };
            let after = bench_step(
                &mut bench_loop,
                cx.local.bench,
                now_ms,
                cx.local.lines,
                &inputs,
                &mut cx.shared.log,
                &REBOOT,
            );
            if after != After::Continue {
                // Two frame times at 500 kbit/s for the safe commands to leave the mailboxes.
                Mono::delay(2u64.millis()).await;
                hand_over(after);
            }
            Mono::delay(10u64.millis()).await;
        }
    }
}
