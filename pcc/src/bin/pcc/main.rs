//! PCC firmware for the Teensy 4.0 (RTIC 2).
//!
//! Tasks, highest priority first:
//! - `voltage_edge` (GPIO1 interrupt, priority 3): time-stamps the V/F converters' edges.
//! - `can_receive` (CAN2 interrupt, priority 2): drains the FlexCAN RX FIFO into a bounded
//!   queue; a full queue drops the frame and counts it.
//! - `control` (every 10 ms, priority 1): samples the voltages, feeds BMS frames to the link
//!   monitor, steps the state machine, applies the relays in the same period, sends the
//!   status frame 0x222, logs state changes, and services the watchdog if the loop is on
//!   schedule.
//! - `usb` (USB interrupt, priority 1): the USB serial console. The log is a bounded buffer
//!   (a full one drops lines and counts them; nothing waits for the host); typing
//!   `bootloader`, or `teensy_loader_cli -s` (134 baud), asks for the bootloader, which the
//!   control task grants only in STANDBY or ERROR with the tractive system below 60 V
//!   (`Precharge::handover`), after opening AIR+, and otherwise refuses with the reason.
//!
//! All decisions are in the `aer_pcc` library; this file only moves data between it and the
//! hardware.
//!
//! The board (`aer_boards::pcc::COMP_CAR`, typed in `board.rs`) has one relay output: pin 11
//! closes AIR+. AIR- and the precharge relay are the shutdown circuit's.
//!
//! Failing safe: pin 11 is low (AIR+ open) from reset until a control step in ONLINE or
//! CHARGING raises it; its pad gets the internal 100 kOhm pull-down before it becomes an
//! output (between reset and init it is an input with only the pad keeper, so the board's
//! driver stage needs its own pull-down: check it on the bench). WDOG1 (0.5 s) is serviced
//! only by an on-time control loop, so a hang restarts the PCC, and a restart leaves pin 11 an
//! input again; the panic handler drives pin 11 low before anything else and then lets the
//! watchdog restart it. After a watchdog restart the PCC starts in ERROR with the "undefined
//! state" cause latched until a power cycle.
#![no_std]
#![no_main]

mod board;

use core::panic::PanicInfo;
use teensy4_bsp::ral;

/// Opens AIR+, then waits for the watchdog. Runs with whatever state the code had when it
/// panicked, so it touches nothing but pin 11's write-only clear register.
#[panic_handler]
fn panic(_: &PanicInfo<'_>) -> ! {
    // SAFETY: DR_CLEAR is write-only and only clears the given bits; the mask is pin 11
    // (board.rs), an output from init onwards, so this can only open AIR+. Nothing else in
    // the program can run after a panic.
    unsafe {
        let gpio2 = ral::gpio::GPIO2::instance();
        ral::write_reg!(ral::gpio, gpio2, DR_CLEAR, board::AIR_PLUS_GPIO2_MASK);
    }
    loop {
        cortex_m::asm::nop();
    }
}

#[rtic::app(device = teensy4_bsp, peripherals = true, dispatchers = [KPP])]
mod app {
    use crate::board;
    use aer_console::usb::{Bus, Memory, UsbConsole, chip_serial};
    use aer_console::{Command, LineReader, LogBuffer, RebootRequest, Watch, bringup::ResetCause};
    use aer_flexcan::{CanFrame, Flexcan};
    use aer_pcc::console::{BootloaderAnswer, CountersLine, LOG_BYTES, StateLine};
    use aer_pcc::watchdog::{LoopMonitor, reset_by_watchdog};
    use aer_pcc::{
        Inputs, Precharge, PrechargeConfig, Relays, TASK_PERIOD_MS, VfConfig, bms::BmsLink,
        measurement::VoltageChannel,
    };
    use core::sync::atomic::{AtomicU32, Ordering};
    use heapless::spsc::{Consumer, Producer, Queue};
    use rtic_monotonics::imxrt::prelude::*;
    use teensy4_bsp::{
        board as bsp,
        hal::{
            self, gpio,
            iomuxc::{self, Config, PullKeeper},
        },
        ral,
    };

    imxrt_gpt1_monotonic!(Mono, 1_000_000);

    /// Received frames waiting for the control task (about 4 periods of a busy bus's BMS
    /// traffic; the control task empties it every 10 ms).
    const RX_QUEUE: usize = 32;

    /// Frames dropped because the RX queue was full.
    static RX_QUEUE_OVERFLOWS: AtomicU32 = AtomicU32::new(0);
    /// Status frames not sent because every mailbox was busy (bus-off or a flooded bus).
    static TX_BUSY: AtomicU32 = AtomicU32::new(0);
    /// Status frames that could not be encoded (clamped values make this a codec defect).
    static STATUS_ENCODE_FAILURES: AtomicU32 = AtomicU32::new(0);
    /// `bootloader` typed, or 134 baud from the host; the control task decides.
    static REBOOT: RebootRequest = RebootRequest::new();

    /// The board's one relay output: pin 11, close AIR+.
    pub struct RelayPins {
        air_plus: gpio::Output,
    }

    impl RelayPins {
        /// Drives the board's relay outputs (`Relays::outputs` over the board map: pin 11,
        /// the typed pin checked against it in board.rs).
        fn apply(&mut self, relays: Relays) {
            let [(_pin_11, high)] = relays.outputs(&board::REVISION);
            if high {
                self.air_plus.set();
            } else {
                self.air_plus.clear();
            }
        }
    }

    #[shared]
    struct Shared {
        accumulator: VoltageChannel,
        tractive: VoltageChannel,
        can: Flexcan<{ board::CAN_INSTANCE }>,
        log: LogBuffer<LOG_BYTES>,
    }

    #[local]
    struct Local {
        accumulator_edges: gpio::Input,
        tractive_edges: gpio::Input,
        relays: RelayPins,
        led: gpio::Output,
        rx_producer: Producer<'static, CanFrame>,
        rx_consumer: Consumer<'static, CanFrame>,
        wdog: ral::wdog::WDOG1,
        watchdog_reset: bool,
        usb: Option<UsbConsole>,
        typed: LineReader<64>,
    }

    #[init(local = [
        rx_queue: Queue<CanFrame, RX_QUEUE> = Queue::new(),
        usb_memory: Memory = Memory::new(),
        usb_state: aer_console::usb::EndpointState = aer_console::usb::EndpointState::max_endpoints(),
        usb_bus: Option<Bus> = None,
        serial: [u8; 16] = [0; 16],
    ])]
    fn init(cx: init::Context) -> (Shared, Local) {
        let bsp::Resources {
            pins,
            mut gpio1,
            mut gpio2,
            mut gpt1,
            ccm,
            usb,
            ..
        } = bsp::t40(cx.device);
        let mut pins = board::pins(pins);

        // AIR+ first, driven low, before anything else can run. The pad gets a pull-down
        // first; a pin on the wrong port is a build-time mistake in board.rs: the output then
        // stays unconfigured (low through the pull-down) and the PCC halts.
        let pull_down = Config::modify().set_pull_keeper(Some(PullKeeper::Pulldown100k));
        iomuxc::configure(&mut pins.air_plus, pull_down);
        let Ok(air_plus) = gpio2.output(pins.air_plus) else {
            halt_safe()
        };
        let mut relays = RelayPins { air_plus };
        relays.apply(Relays::ALL_OPEN);
        let Ok(led) = gpio2.output(pins.led) else {
            halt_safe()
        };
        // The thermistors are read by the bring-up image only.
        let _thermistors = pins.thermistors;
        // The V/F converters' outputs read low when a converter is unplugged.
        iomuxc::configure(&mut pins.accumulator_freq, pull_down);
        iomuxc::configure(&mut pins.tractive_freq, pull_down);

        // 1 MHz monotonic from PERCLK: microsecond edge stamps and the 10 ms schedule.
        gpt1.set_clock_source(hal::gpt::ClockSource::PeripheralClock);
        gpt1.set_divider(bsp::PERCLK_FREQUENCY / 1_000_000);
        // SAFETY: `gpt1` is only configured above and not used again; the monotonic owns it.
        Mono::start(
            unsafe { ral::gpt::GPT1::instance() },
            Priority::rtic_default(),
        );

        let (Ok(accumulator_edges), Ok(tractive_edges)) = (
            gpio1.input(pins.accumulator_freq),
            gpio1.input(pins.tractive_freq),
        ) else {
            halt_safe()
        };
        let rising = Some(gpio::Trigger::RisingEdge);
        if gpio1.set_interrupt(&accumulator_edges, rising).is_err()
            || gpio1.set_interrupt(&tractive_edges, rising).is_err()
        {
            halt_safe();
        }

        // SAFETY: the BSP does not hand out the FlexCAN instances, SRC or WDOG1; nothing else
        // uses CAN2, the reset status or the watchdog.
        let (can_regs, src, wdog) = unsafe {
            (
                ral::can::CAN2::instance(),
                ral::src::SRC::instance(),
                ral::wdog::WDOG1::instance(),
            )
        };
        // Was this start a watchdog restart? Clear the sticky flags so the next one is judged
        // on its own.
        let srsr = ral::read_reg!(ral::src, src, SRSR);
        ral::write_reg!(ral::src, src, SRSR, srsr);
        let watchdog_reset = reset_by_watchdog(srsr);
        let mut can =
            match Flexcan::new(can_regs, pins.can_tx, pins.can_rx, &ccm, board::CAN_BITRATE) {
                Ok(can) => can,
                // The relays are open; without CAN the PCC cannot see the BMS, so it stays here.
                Err(_) => halt_safe(),
            };
        can.enable_rx_interrupt();

        start_watchdog(&wdog);

        // The console is a convenience: without it the PCC runs as before.
        let usb = UsbConsole::new(
            usb,
            cx.local.usb_memory,
            cx.local.usb_state,
            cx.local.usb_bus,
            "AER PCC",
            chip_serial(cx.local.serial),
        )
        .ok();
        let mut log = LogBuffer::new();
        aer_pcc::console::race_startup(&mut log, &board::REVISION, ResetCause(srsr));

        let (rx_producer, rx_consumer) = cx.local.rx_queue.split();
        let vf = VfConfig::PCC_BOARD;
        let shared = Shared {
            accumulator: VoltageChannel::new(vf, TASK_PERIOD_MS),
            tractive: VoltageChannel::new(vf, TASK_PERIOD_MS),
            can,
            log,
        };
        if control::spawn().is_err() {
            halt_safe();
        }
        (
            shared,
            Local {
                accumulator_edges,
                tractive_edges,
                relays,
                led,
                rx_producer,
                rx_consumer,
                wdog,
                watchdog_reset,
                usb,
                typed: LineReader::new(),
            },
        )
    }

    /// The USB console: log out, typed bytes in. The race image takes `bootloader` only,
    /// as a request the control task grants or refuses.
    #[task(binds = USB_OTG1, priority = 1, local = [usb, typed], shared = [log])]
    fn usb(mut cx: usb::Context) {
        let Some(usb) = cx.local.usb.as_mut() else {
            return;
        };
        let host_asks = usb.serve(&mut cx.shared.log, cx.local.typed, |line| {
            if matches!(Command::parse(line), Ok(Command::Bootloader)) {
                REBOOT.request();
            }
        });
        if host_asks {
            REBOOT.request();
        }
    }

    /// WDOG1 with a 0.5 s timeout (WT = 0), enabled. The power-down counter is switched off
    /// so only a missed service restarts the PCC.
    fn start_watchdog(wdog: &ral::wdog::WDOG1) {
        ral::write_reg!(ral::wdog, wdog, WMCR, 0);
        ral::modify_reg!(ral::wdog, wdog, WCR, WT: 0, WDE: 1);
    }

    fn service_watchdog(wdog: &ral::wdog::WDOG1) {
        ral::write_reg!(ral::wdog, wdog, WSR, 0x5555);
        ral::write_reg!(ral::wdog, wdog, WSR, 0xAAAA);
    }

    /// Parks the core with every relay output low. Only reachable at start-up, before the
    /// watchdog runs.
    fn halt_safe() -> ! {
        loop {
            cortex_m::asm::wfi();
        }
    }

    fn now_us() -> u32 {
        // The 64-bit tick count wraps the 32-bit edge stamps every 71 minutes; the library
        // only uses differences.
        Mono::now().as_ticks() as u32
    }

    #[task(binds = GPIO1_COMBINED_16_31, priority = 3,
           local = [accumulator_edges, tractive_edges], shared = [accumulator, tractive])]
    fn voltage_edge(mut cx: voltage_edge::Context) {
        let now = now_us();
        if cx.local.accumulator_edges.is_triggered() {
            cx.local.accumulator_edges.clear_triggered();
            cx.shared.accumulator.lock(|channel| channel.on_edge(now));
        }
        if cx.local.tractive_edges.is_triggered() {
            cx.local.tractive_edges.clear_triggered();
            cx.shared.tractive.lock(|channel| channel.on_edge(now));
        }
    }

    #[task(binds = CAN2, priority = 2, local = [rx_producer], shared = [can])]
    fn can_receive(mut cx: can_receive::Context) {
        cx.shared.can.lock(|can| {
            while let Some(frame) = can.receive() {
                if cx.local.rx_producer.enqueue(frame).is_err() {
                    RX_QUEUE_OVERFLOWS.fetch_add(1, Ordering::Relaxed);
                }
            }
        });
    }

    #[task(priority = 1, local = [relays, led, rx_consumer, wdog, watchdog_reset,
                                  state: Watch<(aer_pcc::State, aer_pcc::Errors)> = Watch::new(),
                                  precharge: Watch<Option<aer_pcc::PrechargeTiming>> = Watch::new()],
           shared = [accumulator, tractive, can, log])]
    async fn control(mut cx: control::Context) {
        let start = Mono::now();
        let start_ms = (start.as_ticks() / 1_000) as u32;
        let mut pcc = if *cx.local.watchdog_reset {
            Precharge::after_watchdog_reset(PrechargeConfig::CAR, start_ms)
        } else {
            Precharge::new(PrechargeConfig::CAR, start_ms)
        };
        let mut bms = BmsLink::default();
        let mut health = LoopMonitor::new(TASK_PERIOD_MS);
        let mut next = start;
        loop {
            next += u64::from(TASK_PERIOD_MS).millis();
            let now = Mono::now();
            let now_ms = (now.as_ticks() / 1_000) as u32;
            let now_us = now.as_ticks() as u32;

            while let Some(frame) = cx.local.rx_consumer.dequeue() {
                bms.on_frame(now_ms, &frame);
            }
            let inputs = Inputs {
                now_ms,
                accumulator_v: cx.shared.accumulator.lock(|channel| channel.sample(now_us)),
                tractive_v: cx.shared.tractive.lock(|channel| channel.sample(now_us)),
                bms_last_seen_ms: bms.last_seen_ms(),
                charger_safety: bms.charger_safety(),
            };
            let relays = pcc.step(&inputs);
            cx.local.relays.apply(relays);
            if REBOOT.take() {
                let answer = match pcc.handover() {
                    Ok(safe) => {
                        cx.local.relays.apply(safe);
                        BootloaderAnswer::Obeyed
                    }
                    Err(why) => BootloaderAnswer::Refused(why),
                };
                cx.shared
                    .log
                    .lock(|log| log.line(format_args!("t={now_ms} ms {answer}")));
                if answer == BootloaderAnswer::Obeyed {
                    aer_console::usb::reboot_to_bootloader();
                }
            }
            if let Some((state, errors)) = cx.local.state.changed((pcc.state(), pcc.errors())) {
                let line = StateLine {
                    now_ms,
                    state,
                    relays,
                    errors,
                    accumulator_v: pcc.accumulator_v(),
                    tractive_v: pcc.tractive_v(),
                };
                cx.shared.log.lock(|log| log.line(format_args!("{line}")));
            }
            if let Some(Some(timing)) = cx.local.precharge.changed(pcc.last_precharge()) {
                cx.shared
                    .log
                    .lock(|log| log.line(format_args!("t={now_ms} ms {timing}")));
            }
            if now_ms % 5_000 < TASK_PERIOD_MS {
                let bus = cx.shared.can.lock(|can| can.status());
                cx.shared.log.lock(|log| {
                    let line = CountersLine {
                        now_ms,
                        bus,
                        rx_queue_overflows: RX_QUEUE_OVERFLOWS.load(Ordering::Relaxed),
                        status_not_sent: TX_BUSY.load(Ordering::Relaxed),
                        log_dropped: log.dropped(),
                    };
                    log.line(format_args!("{line}"))
                });
            }
            // Heartbeat: the LED toggles every second (0.5 Hz) while the loop runs, so a hung
            // PCC shows on the bench.
            if now_ms % 1_000 < TASK_PERIOD_MS {
                cx.local.led.toggle();
            }

            match pcc.status_frame::<CanFrame>() {
                Some(frame) => {
                    if cx.shared.can.lock(|can| can.transmit(&frame)).is_err() {
                        TX_BUSY.fetch_add(1, Ordering::Relaxed);
                    }
                }
                None => {
                    STATUS_ENCODE_FAILURES.fetch_add(1, Ordering::Relaxed);
                }
            }
            if health.step_completed(Mono::now().as_ticks() as u32) {
                service_watchdog(cx.local.wdog);
            }
            Mono::delay_until(next).await;
        }
    }
}
