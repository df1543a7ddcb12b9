//! PCC bring-up image (Teensy 4.0): checks every pin of the board on the bench and reports
//! over USB serial (any terminal: `screen /dev/ttyACM0`, `picocom`, the Arduino monitor).
//!
//! At start: firmware, board revision, schema fingerprint, reset cause (a `watchdog test`
//! shows here after the reset), clocks. Every second: both V/F converters' levels, edge counts
//! and frequencies (with the voltage they mean), both thermistor inputs' counts and volts,
//! the CAN controller's state and what it heard. Pin 11 (AIR+) stays low unless typed:
//! `confirm hv-disconnected` (taken only while both converters read below 60 V), then
//! `out air-plus-close on` within 30 s; it drops again when the confirmation expires, when a
//! converter reads 60 V or more, on `off`, on `bootloader` and on every reset. `help` lists
//! the commands. Every line is built by `aer_pcc::console` (host-tested; docs/bench-day.md
//! quotes the tests).
#![no_std]
#![no_main]

#[path = "../pcc/board.rs"]
mod board;

use core::panic::PanicInfo;
use teensy4_bsp::ral;

/// Drops pin 11, then waits for the watchdog (as the race image does).
#[panic_handler]
fn panic(_: &PanicInfo<'_>) -> ! {
    // SAFETY: DR_CLEAR is write-only and only clears pin 11's bit (board.rs).
    unsafe {
        let gpio2 = ral::gpio::GPIO2::instance();
        ral::write_reg!(ral::gpio, gpio2, DR_CLEAR, board::AIR_PLUS_GPIO2_MASK);
    }
    loop {
        core::hint::spin_loop();
    }
}

#[rtic::app(device = teensy4_bsp, peripherals = true, dispatchers = [KPP])]
mod app {
    use crate::board;
    use aer_console::bringup::{
        AnalogReading, BusLine, Clocks, DigitalReading, Heard, HvGate, HvReadings, ReportHeader,
        ResetCause, SelfTestLine, edge_rate_hz,
    };
    use aer_console::command::HELP;
    use aer_console::usb::{Bus, EndpointState, Memory, UsbConsole, chip_serial};
    use aer_console::{Command, CommandError, LineReader, LogBuffer, RebootRequest};
    use aer_flexcan::{CanFrame, Flexcan};
    use aer_pcc::console::{BRINGUP_LOG_BYTES as LOG_BYTES, BringupReport, VfReading};
    use aer_pcc::{PrechargeConfig, VfConfig};
    use core::sync::atomic::{AtomicU32, Ordering};
    use embedded_can::{Frame, Id, StandardId};
    use heapless::spsc::{Consumer, Producer, Queue};
    use rtic_monotonics::imxrt::prelude::*;
    use teensy4_bsp::{
        board as bsp,
        hal::{
            self, adc, gpio,
            iomuxc::{self, Config, PullKeeper},
        },
        ral,
    };

    imxrt_gpt1_monotonic!(Mono, 1_000_000);

    /// The clocks the start-up lines print are the BSP's.
    const _: () = assert!(
        bsp::ARM_FREQUENCY == Clocks::TEENSY4.core_hz
            && bsp::IPG_FREQUENCY == Clocks::TEENSY4.ipg_hz
            && bsp::PERCLK_FREQUENCY == Clocks::TEENSY4.perclk_hz
            && board::CAN_BITRATE == Clocks::TEENSY4.can_bitrate
    );
    /// `bootloader` typed, or 134 baud from the host.
    static REBOOT: RebootRequest = RebootRequest::new();
    /// The heartbeat this board sends on `can` (not an identifier of the car's schema).
    const HEARTBEAT_ID: u16 = 0x7F2;

    /// Rising edges of the accumulator and tractive-system V/F converters.
    static EDGES: [AtomicU32; 2] = [AtomicU32::new(0), AtomicU32::new(0)];

    /// A typed line, handed from the USB interrupt to the bench task.
    type Line = heapless::String<64>;

    #[shared]
    struct Shared {
        log: LogBuffer<LOG_BYTES>,
        /// The V/F converters' inputs: the edge interrupt counts, the report reads levels.
        vf: [gpio::Input; 2],
    }

    #[local]
    struct Local {
        usb: Option<UsbConsole>,
        typed: LineReader<64>,
        lines_in: Producer<'static, Line>,
        lines: Consumer<'static, Line>,
        air_plus: gpio::Output,
        led: gpio::Output,
        adc: adc::Adc,
        thermistors: [adc::AnalogInput; 2],
        can: Option<Flexcan<{ board::CAN_INSTANCE }>>,
        wdog: ral::wdog::WDOG1,
    }

    #[init(local = [
        queue: Queue<Line, 4> = Queue::new(),
        usb_memory: Memory = Memory::new(),
        usb_state: EndpointState = EndpointState::max_endpoints(),
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
            adc1,
            usb,
            ..
        } = bsp::t40(cx.device);
        let mut pins = board::pins(pins);
        let pull_down = Config::modify().set_pull_keeper(Some(PullKeeper::Pulldown100k));
        iomuxc::configure(&mut pins.air_plus, pull_down);
        let Ok(air_plus) = gpio2.output(pins.air_plus) else {
            halt()
        };
        air_plus.clear();
        let Ok(led) = gpio2.output(pins.led) else {
            halt()
        };
        iomuxc::configure(&mut pins.accumulator_freq, pull_down);
        iomuxc::configure(&mut pins.tractive_freq, pull_down);
        let (Ok(accumulator), Ok(tractive)) = (
            gpio1.input(pins.accumulator_freq),
            gpio1.input(pins.tractive_freq),
        ) else {
            halt()
        };
        let vf = [accumulator, tractive];
        for input in &vf {
            if gpio1
                .set_interrupt(input, Some(gpio::Trigger::RisingEdge))
                .is_err()
            {
                halt();
            }
        }
        let mut adc = adc1;
        adc.set_resolution(adc::ResolutionBits::Res12);
        let (Ok(thermistor1), Ok(thermistor2)) = (
            adc.input::<_, 1>(pins.thermistors.0),
            adc.input::<_, 1>(pins.thermistors.1),
        ) else {
            halt()
        };
        let thermistors = [thermistor1, thermistor2];

        gpt1.set_clock_source(hal::gpt::ClockSource::PeripheralClock);
        gpt1.set_divider(bsp::PERCLK_FREQUENCY / 1_000_000);
        // SAFETY: `gpt1` is configured above and not used again; the monotonic owns it.
        Mono::start(
            unsafe { ral::gpt::GPT1::instance() },
            Priority::rtic_default(),
        );

        // SAFETY: the BSP does not hand out CAN2, SRC or WDOG1; nothing else uses them.
        let (can_regs, src, wdog) = unsafe {
            (
                ral::can::CAN2::instance(),
                ral::src::SRC::instance(),
                ral::wdog::WDOG1::instance(),
            )
        };
        let srsr = ral::read_reg!(ral::src, src, SRSR);
        ral::write_reg!(ral::src, src, SRSR, srsr);

        let mut log = LogBuffer::new();
        aer_pcc::console::bringup_startup(&mut log, &board::REVISION, ResetCause(srsr));
        let can = match Flexcan::new(can_regs, pins.can_tx, pins.can_rx, &ccm, board::CAN_BITRATE) {
            Ok(can) => Some(can),
            Err(error) => {
                log.line(format_args!("CAN2 did not start: {error}"));
                None
            }
        };
        // WDOG1 at 1 s, fed by the bench task (`watchdog test` stops feeding it).
        ral::write_reg!(ral::wdog, wdog, WMCR, 0);
        ral::modify_reg!(ral::wdog, wdog, WCR, WT: 1, WDE: 1);

        let usb = UsbConsole::new(
            usb,
            cx.local.usb_memory,
            cx.local.usb_state,
            cx.local.usb_bus,
            "AER PCC bring-up",
            chip_serial(cx.local.serial),
        )
        .ok();

        let (lines_in, lines) = cx.local.queue.split();
        bench::spawn().ok();
        (
            Shared { log, vf },
            Local {
                usb,
                typed: LineReader::new(),
                lines_in,
                lines,
                air_plus,
                led,
                adc,
                thermistors,
                can,
                wdog,
            },
        )
    }

    /// Parks the core with pin 11 low (start-up failed before the console runs).
    fn halt() -> ! {
        loop {
            cortex_m::asm::wfi();
        }
    }

    #[task(binds = GPIO1_COMBINED_16_31, priority = 2, shared = [vf])]
    fn vf_edge(mut cx: vf_edge::Context) {
        cx.shared
            .vf
            .lock(|vf| aer_console::usb::count_rising_edges(vf, &EDGES));
    }

    #[task(binds = USB_OTG1, priority = 1, local = [usb, typed, lines_in], shared = [log])]
    fn usb(mut cx: usb::Context) {
        let Some(usb) = cx.local.usb.as_mut() else {
            return;
        };
        let lines_in = cx.local.lines_in;
        let host_asks = usb.serve(&mut cx.shared.log, cx.local.typed, |line| {
            // Typing faster than the bench loop takes commands drops the line.
            let mut owned = Line::new();
            if owned.push_str(line).is_ok() {
                let _dropped = lines_in.enqueue(owned);
            }
        });
        if host_asks {
            REBOOT.request();
        }
    }

    #[task(priority = 1, local = [lines, air_plus, led, adc, thermistors, can, wdog],
           shared = [log, vf])]
    async fn bench(mut cx: bench::Context) {
        let mut gate = HvGate::new(PrechargeConfig::CAR.discharged_v);
        let vf_board = VfConfig::PCC_BOARD;
        // Both converters' voltages from the last report period's edge rates.
        let mut volts = [None::<f32>; 2];
        let mut feeding = true;
        let mut heard = Heard::default();
        let mut edges_before = [0u32; 2];
        let mut heartbeat: u8 = 0;
        let mut last_report_ms = 0u32;
        loop {
            let now_ms = (Mono::now().as_ticks() / 1_000) as u32;
            if feeding {
                ral::write_reg!(ral::wdog, cx.local.wdog, WSR, 0x5555);
                ral::write_reg!(ral::wdog, cx.local.wdog, WSR, 0xAAAA);
            }
            if let Some(can) = cx.local.can.as_mut() {
                while let Some(frame) = can.receive() {
                    heard.frame(raw_id(&frame));
                }
            }
            if REBOOT.take() {
                cx.local.air_plus.clear();
                aer_console::usb::reboot_to_bootloader();
            }
            let [accumulator_v, tractive_v] = volts;
            let readings = [
                ("accumulator (pin 14)", accumulator_v),
                ("tractive system (pin 15)", tractive_v),
            ];
            let readings = HvReadings { volts: &readings };
            if cx.local.air_plus.is_set() {
                if let Err(refusal) = gate.allows(now_ms, readings) {
                    cx.local.air_plus.clear();
                    gate.revoke();
                    cx.shared
                        .log
                        .lock(|log| log.line(format_args!("pin 11 (AIR+) low: {refusal}")));
                }
            }
            while let Some(line) = cx.local.lines.dequeue() {
                let outcome = match Command::parse(&line) {
                    Ok(Command::Help) => {
                        cx.shared.log.lock(|log| {
                            for text in HELP {
                                log.line(format_args!("{text}"));
                            }
                        });
                        continue;
                    }
                    Ok(Command::Report) => {
                        last_report_ms = now_ms.wrapping_sub(2_000);
                        continue;
                    }
                    Ok(Command::ConfirmHvDisconnected) => match gate.confirm(now_ms, readings) {
                        Ok(()) => "HV outputs armed for 30 s (both converters read below 60 V)",
                        Err(refusal) => {
                            cx.shared
                                .log
                                .lock(|log| log.line(format_args!("refused: {refusal}")));
                            "not confirmed"
                        }
                    },
                    Ok(Command::Output {
                        signal: "air-plus-close",
                        level,
                    }) => {
                        if !level.high() {
                            cx.local.air_plus.clear();
                            "pin 11 (AIR+) low"
                        } else {
                            match gate.allows(now_ms, readings) {
                                Ok(()) => {
                                    cx.local.air_plus.set();
                                    "pin 11 (AIR+) HIGH for at most 30 s from the confirmation"
                                }
                                Err(refusal) => {
                                    cx.shared
                                        .log
                                        .lock(|log| log.line(format_args!("refused: {refusal}")));
                                    "pin 11 (AIR+) stays low"
                                }
                            }
                        }
                    }
                    Ok(Command::Output {
                        signal: "led",
                        level,
                    }) => {
                        if level.high() {
                            cx.local.led.set();
                        } else {
                            cx.local.led.clear();
                        }
                        "led set"
                    }
                    Ok(Command::Output { .. }) => "no such output on the PCC: air-plus-close, led",
                    Ok(Command::AllOff) => {
                        cx.local.air_plus.clear();
                        gate.revoke();
                        "every output low"
                    }
                    Ok(Command::CanTest) => {
                        let result = cx.local.can.as_mut().map(|can| {
                            let frame = StandardId::new(HEARTBEAT_ID)
                                .and_then(|id| CanFrame::new(id, &[0xA5, 0x5A, 2]));
                            frame.map(|frame| can.self_test(&frame))
                        });
                        cx.shared.log.lock(|log| {
                            log.line(format_args!(
                                "{}",
                                SelfTestLine {
                                    name: "CAN2",
                                    result: result.flatten()
                                }
                            ))
                        });
                        "heartbeats 0x7F2 every second from now"
                    }
                    Ok(Command::WatchdogTest) => {
                        feeding = false;
                        "watchdog no longer fed: the PCC resets within 1 s and reports the cause"
                    }
                    Ok(Command::Bootloader) => {
                        REBOOT.request();
                        "rebooting into the bootloader, pin 11 (AIR+) low"
                    }
                    Ok(Command::Calibrate(_) | Command::I2cScan | Command::DtiEnable) => {
                        "not on the PCC"
                    }
                    Err(CommandError::Unknown(_)) => "unknown command: `help`",
                    Err(CommandError::Usage(usage)) => usage,
                };
                cx.shared
                    .log
                    .lock(|log| log.line(format_args!("> {line}: {outcome}")));
            }
            let elapsed_ms = now_ms.wrapping_sub(last_report_ms);
            if elapsed_ms >= 1_000 {
                last_report_ms = now_ms;
                cx.local.led.toggle();
                let edges = EDGES.each_ref().map(|edges| edges.load(Ordering::Relaxed));
                let counts = cx
                    .local
                    .thermistors
                    .each_mut()
                    .map(|input| cx.local.adc.read_blocking(input));
                let can_status = cx.local.can.as_mut().map(|can| can.status());
                if let Some(can) = cx.local.can.as_mut() {
                    heartbeat = heartbeat.wrapping_add(1);
                    if let Some(frame) =
                        StandardId::new(HEARTBEAT_ID).and_then(|id| CanFrame::new(id, &[heartbeat]))
                    {
                        let _queued = can.transmit(&frame);
                    }
                }
                let levels = cx
                    .shared
                    .vf
                    .lock(|vf| vf.each_ref().map(|input| input.is_set()));
                let mut vf = board::REVISION.voltage_freq.map(|pin| VfReading {
                    input: DigitalReading {
                        pin,
                        high: false,
                        edges: 0,
                        hz: 0.0,
                    },
                    vf: vf_board,
                });
                for (((reading, high), before), after) in
                    vf.iter_mut().zip(levels).zip(edges_before).zip(edges)
                {
                    reading.input.high = high;
                    reading.input.edges = after;
                    reading.input.hz = edge_rate_hz(before, after, elapsed_ms);
                }
                volts = vf.map(|reading| Some(reading.volts()));
                let [pin1, pin2] = board::REVISION.thermistors;
                let [counts1, counts2] = counts;
                let report = BringupReport {
                    header: ReportHeader { now_ms, dropped: 0 },
                    vf,
                    thermistors: [
                        AnalogReading {
                            pin: pin1,
                            counts: counts1,
                            divider: 1.0,
                        },
                        AnalogReading {
                            pin: pin2,
                            counts: counts2,
                            divider: 1.0,
                        },
                    ],
                    bus: BusLine {
                        name: "CAN2",
                        status: can_status,
                        heard: &heard,
                    },
                    air_plus: cx.local.air_plus.is_set(),
                };
                cx.shared.log.lock(|log| {
                    BringupReport {
                        header: ReportHeader {
                            now_ms,
                            dropped: log.dropped(),
                        },
                        ..report
                    }
                    .write(log)
                });
                edges_before = edges;
                heard = Heard::default();
            }
            Mono::delay(10u64.millis()).await;
        }
    }

    fn raw_id(frame: &CanFrame) -> u32 {
        match frame.id() {
            Id::Standard(id) => u32::from(id.as_raw()),
            Id::Extended(id) => id.as_raw(),
        }
    }
}
