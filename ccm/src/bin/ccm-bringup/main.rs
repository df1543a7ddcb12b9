//! CCM bring-up image (Teensy 4.1): checks every pin of the board on the bench and reports
//! over USB serial (any terminal: `screen /dev/ttyACM0`, `picocom`, the Arduino monitor).
//!
//! At start: firmware, board revision and every pin with its source, schema fingerprints,
//! reset cause (a `watchdog test` shows here after the reset), clocks. Every second: every
//! analog input's counts and volts, the digital inputs' levels, edge counts and rates (wheel
//! speed in Hz), both CAN controllers' state and what each heard (and, of a DTI on the
//! inverter bus, its node id, CAN map version, drive enable, fault code and command timeout),
//! the outputs. Outputs move only on a typed `out <signal> ...`; `can` runs both controllers'
//! loopback self-tests and starts heartbeats; `cal rest` / `cal full` and `cal shock ...`
//! record the pedal, brake and shock sensors and print the lines for `ccm/calibration.toml`;
//! `cal save`, `cal load` and `cal erase` work the saved copies; `dti enable` times the DTI's
//! command timeout behind its guard (below 60 V after `confirm hv-disconnected`; at high
//! voltage after `confirm wheels-off-ground` with the PCC ONLINE). `help` lists the commands.
//!
//! The hardware is set up by `aer_ccm::hw`, as in the race image; the loop and the commands
//! every board answers alike are `aer_console::bench`; this board's checks and answers are
//! `aer_ccm::bench`, over the pins in `bench.rs`. docs/bench-day.md quotes that library
//! driven by a simulated board.
#![no_std]
#![no_main]

mod bench;

use aer_console::RebootRequest;
use core::sync::atomic::AtomicU32;
use rtic_monotonics::imxrt::prelude::*;

imxrt_gpt1_monotonic!(Mono, 1_000_000);

/// `bootloader` typed, or 134 baud from the host.
static REBOOT: RebootRequest = RebootRequest::new();
/// Rising edges of wheel-speed sensors 1 and 2.
static WHEEL_EDGES: [AtomicU32; 2] = [AtomicU32::new(0), AtomicU32::new(0)];

#[rtic::app(device = teensy4_bsp, peripherals = true, dispatchers = [KPP])]
mod app {
    use crate::bench::TeensyCcm;
    use crate::{Mono, REBOOT, WHEEL_EDGES};
    use aer_ccm::bench::CcmBench;
    use aer_ccm::console::bringup::{self, LOG_BYTES};
    use aer_ccm::hw::{self, halt};
    use aer_console::bench::{After, BenchLoop, Line, QUEUED_LINES};
    use aer_console::bringup::Clocks;
    use aer_console::usb::{
        Bus, EndpointState, Memory, UsbConsole, UsbMemory, bench_step, hand_over, serve_bench,
    };
    use aer_console::{LineReader, LogBuffer};
    use heapless::spsc::{Consumer, Producer, Queue};
    use rtic_monotonics::imxrt::prelude::*;
    use teensy4_bsp::{board as bsp, hal::gpio, ral};

    /// The clocks the report prints are the BSP's.
    const _: () = assert!(
        bsp::ARM_FREQUENCY == Clocks::TEENSY4.core_hz
            && bsp::IPG_FREQUENCY == Clocks::TEENSY4.ipg_hz
            && bsp::PERCLK_FREQUENCY == Clocks::TEENSY4.perclk_hz
            && hw::board::CAN_BITRATE == Clocks::TEENSY4.can_bitrate
    );

    #[shared]
    struct Shared {
        log: LogBuffer<LOG_BYTES>,
        wheels: [gpio::Input; 2],
    }

    #[local]
    struct Local {
        console: Option<UsbConsole>,
        typed: LineReader<64>,
        lines_in: Producer<'static, Line>,
        lines: Consumer<'static, Line>,
        bench: CcmBench<TeensyCcm>,
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
        let Ok(board) = hw::start(cx.device, usb, "AER CCM bring-up") else {
            halt()
        };
        // SAFETY: `hw::start` configured GPT1 and does not use it again; the monotonic owns it.
        Mono::start(
            unsafe { ral::gpt::GPT1::instance() },
            Priority::rtic_default(),
        );
        let mut log = LogBuffer::new();
        bringup::startup(
            &mut log,
            &hw::board::REVISION,
            board.reset_cause,
            board.board,
        );
        // What a panic (`panic test`, or a fault) sends the DTI: 0 A and drive disabled.
        if let Ok(frames) = aer_ccm::console::dti::EnableTest::disable_frames() {
            aer_ccm::stop::STOP.publish(&frames);
        }
        // The wheel inputs are shared with their edge interrupt, the console with the USB's.
        let Ok((teensy, wheels, console)) = TeensyCcm::new(board, &mut log) else {
            halt()
        };
        let bench = CcmBench::new(teensy, hw::board::REVISION);
        let (lines_in, lines) = cx.local.queue.split();
        if bench::spawn().is_err() {
            halt();
        }
        (
            Shared { log, wheels },
            Local {
                console,
                typed: LineReader::new(),
                lines_in,
                lines,
                bench,
            },
        )
    }

    #[task(binds = GPIO4_COMBINED_0_15, priority = 2, shared = [wheels])]
    fn wheel_edge(mut cx: wheel_edge::Context) {
        cx.shared
            .wheels
            .lock(|wheels| aer_console::usb::count_rising_edges(wheels, &WHEEL_EDGES));
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

    /// The bench loop, every millisecond (pedal calibration samples at 1 kHz).
    #[task(priority = 1, local = [lines, bench], shared = [log, wheels])]
    async fn bench(mut cx: bench::Context) {
        let mut bench_loop = BenchLoop::new();
        loop {
            let now_ms = (Mono::now().as_ticks() / 1_000) as u32;
            let levels = cx
                .shared
                .wheels
                .lock(|wheels| wheels.each_ref().map(|input| input.is_set()));
            let after = bench_step(
                &mut bench_loop,
                cx.local.bench,
                now_ms,
                cx.local.lines,
                &levels,
                &mut cx.shared.log,
                &REBOOT,
            );
            if after != After::Continue {
                // Two frame times at 500 kbit/s for the safe commands to leave the mailboxes.
                Mono::delay(2u64.millis()).await;
                hand_over(after);
            }
            Mono::delay(1u64.millis()).await;
        }
    }
}
