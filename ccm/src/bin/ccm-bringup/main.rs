//! CCM bring-up image (Teensy 4.1): checks every pin of the board on the bench and reports
//! over USB serial (any terminal: `screen /dev/ttyACM0`, `picocom`, the Arduino monitor).
//!
//! At start: firmware, board revision and every pin with its source, schema fingerprints,
//! reset cause (a `watchdog test` shows here after the reset), clocks. Every second: every
//! analog input's counts and volts, the digital inputs' levels, edge counts and rates (wheel
//! speed in Hz), both CAN controllers' state and what each heard (and, of a DTI on the
//! inverter bus, its node id, CAN map version, drive enable, fault code and command timeout),
//! the outputs. Outputs move only on a typed `out <signal> ...`; `can` runs both controllers'
//! loopback self-tests and starts heartbeats; `cal rest` / `cal full` record the pedal and
//! brake sensors and print the lines for `ccm/calibration.toml`; `dti enable` (after
//! `confirm hv-disconnected`, with the DTI's own DC link below 60 V) times the DTI's command
//! timeout at low voltage. `help` lists the commands. Every line is built by
//! `aer_ccm::console` (host-tested; docs/bench-day.md quotes the tests).
#![no_std]
#![no_main]

#[path = "../ccm/board.rs"]
mod board;
#[path = "../ccm/pwm.rs"]
mod pwm;

use teensy4_panic as _;

#[rtic::app(device = teensy4_bsp, peripherals = true, dispatchers = [KPP])]
mod app {
    use crate::board;
    use crate::pwm::PwmBlock;
    use aer_boards::Pin;
    use aer_ccm::calibration::{BenchPoint, BenchRecorder};
    use aer_ccm::console::bringup::{self, LOG_BYTES, Report};
    use aer_ccm::console::dti::DtiBench;
    use aer_console::bringup::{
        AnalogReading, BusLine, Clocks, DigitalReading, Heard, HvGate, HvReadings, ReportHeader,
        ResetCause, SelfTestLine, edge_rate_hz,
    };
    use aer_console::command::HELP;
    use aer_console::usb::{Bus, EndpointState, Memory, UsbConsole, chip_serial};
    use aer_console::{
        Command, CommandError, Level, LineReader, LogBuffer, PedalPosition, RebootRequest,
    };
    use aer_flexcan::{CanFrame, Flexcan};
    use core::sync::atomic::{AtomicU32, Ordering};
    use embedded_can::{ExtendedId, Frame, Id, StandardId};
    use heapless::spsc::{Consumer, Producer, Queue};
    use rtic_monotonics::imxrt::prelude::*;
    use teensy4_bsp::{
        board as bsp,
        hal::{
            self, adc, flexpwm, gpio,
            iomuxc::{self, Config, PullKeeper},
        },
        ral,
    };

    imxrt_gpt1_monotonic!(Mono, 1_000_000);

    /// The clocks the report prints are the BSP's.
    const _: () = assert!(
        bsp::ARM_FREQUENCY == Clocks::TEENSY4.core_hz
            && bsp::IPG_FREQUENCY == Clocks::TEENSY4.ipg_hz
            && bsp::PERCLK_FREQUENCY == Clocks::TEENSY4.perclk_hz
            && board::CAN_BITRATE == Clocks::TEENSY4.can_bitrate
    );
    /// `bootloader` typed, or 134 baud from the host.
    static REBOOT: RebootRequest = RebootRequest::new();
    /// Discharged below this (V): the rules' 60 V DC.
    const DISCHARGED_V: f32 = 60.0;
    /// Heartbeats this board sends on `can` (not identifiers of the car's schema).
    const HEARTBEAT_IDS: [u16; 2] = [0x7F3, 0x7F2];

    /// Rising edges of wheel-speed sensors 1 and 2.
    static WHEEL_EDGES: [AtomicU32; 2] = [AtomicU32::new(0), AtomicU32::new(0)];

    type Line = heapless::String<64>;

    /// The analog inputs the on-chip ADC reads, with their board entries.
    #[cfg(not(feature = "pedals-ads1115"))]
    const ANALOG: usize = 9;
    #[cfg(feature = "pedals-ads1115")]
    const ANALOG: usize = 7;

    #[cfg(feature = "pedals-ads1115")]
    type Ads = aer_ccm::ads1115::Ads1115<hal::lpi2c::Lpi2c>;

    #[shared]
    struct Shared {
        log: LogBuffer<LOG_BYTES>,
        wheels: [gpio::Input; 2],
    }

    #[local]
    struct Local {
        usb: Option<UsbConsole>,
        typed: LineReader<64>,
        lines_in: Producer<'static, Line>,
        lines: Consumer<'static, Line>,
        bench: Bench,
    }

    /// Everything the bench task drives and reads.
    pub struct Bench {
        adc: adc::Adc,
        analog: [(Pin, adc::AnalogInput); ANALOG],
        #[cfg(feature = "pedals-ads1115")]
        ads: Ads,
        buttons: [(Pin, gpio::Input); 2],
        brake_light: gpio::Output,
        led: gpio::Output,
        pumps: PwmBlock,
        fan: PwmBlock,
        buzzer: PwmBlock,
        vehicle_can: Option<Flexcan<3>>,
        inverter_can: Option<Flexcan<2>>,
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
            mut gpio2,
            mut gpio4,
            mut gpt1,
            ccm,
            adc1,
            lpi2c1,
            flexpwm1,
            flexpwm2,
            flexpwm3,
            usb,
            ..
        } = bsp::t41(cx.device);
        let mut pins = board::pins(pins);
        let b = board::REVISION;

        let (Ok(brake_light), Ok(led)) = (gpio2.output(pins.brake_light), gpio2.output(pins.led))
        else {
            halt()
        };
        let pull_down = Config::modify().set_pull_keeper(Some(PullKeeper::Pulldown100k));
        let pull_up = Config::modify().set_pull_keeper(Some(PullKeeper::Pullup22k));
        iomuxc::configure(&mut pins.ready_to_move, pull_down);
        iomuxc::configure(&mut pins.launch, pull_down);
        iomuxc::configure(&mut pins.wheels.0, pull_up);
        iomuxc::configure(&mut pins.wheels.1, pull_up);
        let (Ok(ready_to_move), Ok(launch), Ok(wheel1), Ok(wheel2)) = (
            gpio2.input(pins.ready_to_move),
            gpio4.input(pins.launch),
            gpio4.input(pins.wheels.0),
            gpio4.input(pins.wheels.1),
        ) else {
            halt()
        };
        let rising = Some(gpio::Trigger::RisingEdge);
        if gpio4.set_interrupt(&wheel1, rising).is_err()
            || gpio4.set_interrupt(&wheel2, rising).is_err()
        {
            halt();
        }

        let (mut pump1, mut pump2) = pins.pumps;
        let (mut fan_pin, mut buzzer_pin) = (pins.fan, pins.buzzer);
        hal::iomuxc::flexpwm::prepare(&mut pump1);
        hal::iomuxc::flexpwm::prepare(&mut pump2);
        hal::iomuxc::flexpwm::prepare(&mut fan_pin);
        hal::iomuxc::flexpwm::prepare(&mut buzzer_pin);
        let (Some(pumps), Some(fan), Some(buzzer)) = (
            PwmBlock::new(flexpwm3, flexpwm::SM::SM1, board::PUMP_PWM_HZ),
            PwmBlock::new(flexpwm1, flexpwm::SM::SM3, board::FAN_PWM_HZ),
            PwmBlock::new(flexpwm2, flexpwm::SM::SM0, board::BUZZER_HZ),
        ) else {
            halt()
        };

        let mut adc = adc1;
        adc.set_resolution(adc::ResolutionBits::Res12);
        let (bse1, bse2) = pins.brakes;
        let (s1, s2, s3, s4) = pins.shocks;
        let [pin_bse1, pin_bse2] = b.brakes;
        let [pin_s1, pin_s2, pin_s3, pin_s4] = b.shocks;
        let (Ok(a3), Ok(a2), Ok(a6), Ok(a7), Ok(a8), Ok(a9), Ok(a0)) = (
            adc.input::<_, 1>(bse1),
            adc.input::<_, 1>(bse2),
            adc.input::<_, 1>(s1),
            adc.input::<_, 1>(s2),
            adc.input::<_, 1>(s3),
            adc.input::<_, 1>(s4),
            adc.input::<_, 1>(pins.thermistor),
        ) else {
            halt()
        };
        let common = [
            (pin_bse1, a3),
            (pin_bse2, a2),
            (pin_s1, a6),
            (pin_s2, a7),
            (pin_s3, a8),
            (pin_s4, a9),
            (b.thermistor, a0),
        ];
        #[cfg(not(feature = "pedals-ads1115"))]
        let analog = {
            let aer_boards::ccm::Pedals::OnChipAdc {
                apps: [pin_apps1, pin_apps2],
            } = b.pedals
            else {
                halt()
            };
            let (apps1, apps2) = pins.pedals;
            let (Ok(a5), Ok(a4)) = (adc.input::<_, 1>(apps1), adc.input::<_, 1>(apps2)) else {
                halt()
            };
            let [c0, c1, c2, c3, c4, c5, c6] = common;
            [(pin_apps1, a5), (pin_apps2, a4), c0, c1, c2, c3, c4, c5, c6]
        };
        #[cfg(feature = "pedals-ads1115")]
        let analog = common;
        #[cfg(feature = "pedals-ads1115")]
        let ads = {
            let (scl, sda) = pins.pedals;
            let mut i2c = bsp::lpi2c(lpi2c1, scl, sda, bsp::Lpi2cClockSpeed::KHz400);
            i2c.disabled(|_| {
                // SAFETY: LPI2C1 is owned by `i2c` and disabled here; only its timeout changes.
                let regs = unsafe { ral::lpi2c::LPI2C1::instance() };
                ral::modify_reg!(ral::lpi2c, regs, MCFGR1, TIMECFG: 1);
                ral::modify_reg!(ral::lpi2c, regs, MCFGR3, PINLOW: 32);
            });
            aer_ccm::ads1115::Ads1115::new(i2c)
        };
        #[cfg(not(feature = "pedals-ads1115"))]
        let _unused_i2c = lpi2c1;

        gpt1.set_clock_source(hal::gpt::ClockSource::PeripheralClock);
        gpt1.set_divider(bsp::PERCLK_FREQUENCY / 1_000_000);
        // SAFETY: `gpt1` is configured above and not used again; the monotonic owns it.
        Mono::start(
            unsafe { ral::gpt::GPT1::instance() },
            Priority::rtic_default(),
        );

        // SAFETY: the BSP does not hand out FlexCAN, SRC or WDOG1; nothing else uses them.
        let (can3_regs, can2_regs, wdog, src) = unsafe {
            (
                ral::can3::CAN3::instance(),
                ral::can::CAN2::instance(),
                ral::wdog::WDOG1::instance(),
                ral::src::SRC::instance(),
            )
        };
        let srsr = ral::read_reg!(ral::src, src, SRSR);
        ral::write_reg!(ral::src, src, SRSR, srsr);
        let mut log = LogBuffer::new();
        bringup::startup(&mut log, &b, ResetCause(srsr));
        let (tx3, rx3) = pins.vehicle_can;
        let (tx2, rx2) = pins.inverter_can;
        let vehicle_can = Flexcan::new_can3(can3_regs, tx3, rx3, &ccm, board::CAN_BITRATE)
            .map_err(|error| log.line(format_args!("CAN3 did not start: {error}")))
            .ok();
        let inverter_can = Flexcan::new(can2_regs, tx2, rx2, &ccm, board::CAN_BITRATE)
            .map_err(|error| log.line(format_args!("CAN2 did not start: {error}")))
            .ok();
        // WDOG1 at 1 s, fed by the bench task (`watchdog test` stops feeding it).
        ral::write_reg!(ral::wdog, wdog, WMCR, 0);
        ral::modify_reg!(ral::wdog, wdog, WCR, WT: 1, WDE: 1);

        let usb = UsbConsole::new(
            usb,
            cx.local.usb_memory,
            cx.local.usb_state,
            cx.local.usb_bus,
            "AER CCM bring-up",
            chip_serial(cx.local.serial),
        )
        .ok();

        let (lines_in, lines) = cx.local.queue.split();
        bench::spawn().ok();
        (
            Shared {
                log,
                wheels: [wheel1, wheel2],
            },
            Local {
                usb,
                typed: LineReader::new(),
                lines_in,
                lines,
                bench: Bench {
                    adc,
                    analog,
                    #[cfg(feature = "pedals-ads1115")]
                    ads,
                    buttons: [(b.ready_to_move, ready_to_move), (b.launch, launch)],
                    brake_light,
                    led,
                    pumps,
                    fan,
                    buzzer,
                    vehicle_can,
                    inverter_can,
                    wdog,
                },
            },
        )
    }

    /// Parks the core with every output off (start-up failed before the console runs).
    fn halt() -> ! {
        loop {
            cortex_m::asm::wfi();
        }
    }

    #[task(binds = GPIO4_COMBINED_0_15, priority = 2, shared = [wheels])]
    fn wheel_edge(mut cx: wheel_edge::Context) {
        cx.shared
            .wheels
            .lock(|wheels| aer_console::usb::count_rising_edges(wheels, &WHEEL_EDGES));
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

    /// The bench loop: 1 ms steps (pedal calibration samples), commands, a report a second.
    #[task(priority = 1, local = [lines, bench], shared = [log, wheels])]
    async fn bench(mut cx: bench::Context) {
        let bench = cx.local.bench;
        let mut feeding = true;
        let mut calibration = BenchRecorder::default();
        let mut heard = [Heard::default(); 2];
        let mut dti = DtiBench::default();
        let mut gate = HvGate::new(DISCHARGED_V);
        let mut heartbeats = false;
        let mut heartbeat: u8 = 0;
        let mut wheels_before = [0u32; 2];
        let mut buttons_before = [false; 2];
        let mut button_edges = [0u32; 2];
        let mut last_report_ms = 0u32;
        loop {
            let now_ms = (Mono::now().as_ticks() / 1_000) as u32;
            if feeding {
                ral::write_reg!(ral::wdog, bench.wdog, WSR, 0x5555);
                ral::write_reg!(ral::wdog, bench.wdog, WSR, 0xAAAA);
            }
            if REBOOT.take() {
                all_off(bench);
                aer_console::usb::reboot_to_bootloader();
            }
            if calibration.recording() && calibration.sample(pedal_volts(bench), brake_volts(bench))
            {
                cx.shared
                    .log
                    .lock(|log| bringup::calibration(log, &calibration));
            }
            for ((_, input), (before, edges)) in bench
                .buttons
                .iter()
                .zip(buttons_before.iter_mut().zip(button_edges.iter_mut()))
            {
                let high = input.is_set();
                if high && !*before {
                    *edges = edges.wrapping_add(1);
                }
                *before = high;
            }
            for (can, heard) in [
                bench.vehicle_can.as_mut().map(receive3),
                bench
                    .inverter_can
                    .as_mut()
                    .map(|can| receive2(can, now_ms, &mut dti)),
            ]
            .into_iter()
            .zip(heard.iter_mut())
            {
                for id in can.into_iter().flatten().flatten() {
                    heard.frame(id);
                }
            }
            dti.poll(now_ms);
            if dti.test.active() {
                let dc_link = [("DTI DC link", dti.dc_link_v(now_ms))];
                if let Err(refusal) = gate.allows(now_ms, HvReadings { volts: &dc_link }) {
                    dti.test.stop();
                    cx.shared
                        .log
                        .lock(|log| log.line(format_args!("dti enable stopped: {refusal}")));
                } else if let Some(frames) = dti.due(now_ms) {
                    send_dti(bench, frames);
                }
            }
            while let Some(line) = cx.local.lines.dequeue() {
                let outcome = command(
                    bench,
                    &line,
                    now_ms,
                    &mut Bring {
                        calibration: &mut calibration,
                        feeding: &mut feeding,
                        heartbeats: &mut heartbeats,
                        gate: &mut gate,
                        dti: &mut dti,
                    },
                    &mut cx.shared.log,
                );
                if outcome == "report" {
                    last_report_ms = now_ms.wrapping_sub(2_000);
                } else {
                    cx.shared
                        .log
                        .lock(|log| log.line(format_args!("> {line}: {outcome}")));
                }
            }
            let elapsed_ms = now_ms.wrapping_sub(last_report_ms);
            if elapsed_ms >= 1_000 {
                last_report_ms = now_ms;
                bench.led.toggle();
                if heartbeats {
                    heartbeat = heartbeat.wrapping_add(1);
                    send_heartbeats(bench, heartbeat);
                }
                let wheels_now = WHEEL_EDGES
                    .each_ref()
                    .map(|edges| edges.load(Ordering::Relaxed));
                let levels = cx
                    .shared
                    .wheels
                    .lock(|wheels| wheels.each_ref().map(|input| input.is_set()));
                report(
                    bench,
                    &mut cx.shared.log,
                    now_ms,
                    elapsed_ms,
                    (wheels_before, wheels_now, levels),
                    button_edges,
                    (&heard, &dti),
                );
                wheels_before = wheels_now;
                heard = [Heard::default(); 2];
                dti.report_done();
            }
            Mono::delay(1u64.millis()).await;
        }
    }

    fn receive3(can: &mut Flexcan<3>) -> [Option<u32>; 8] {
        core::array::from_fn(|_| can.receive().map(|frame| raw_id(&frame)))
    }

    /// The inverter bus also feeds the DTI checks (node id, CAN map, drive, fault, DC link,
    /// command timeout).
    fn receive2(can: &mut Flexcan<2>, now_ms: u32, dti: &mut DtiBench) -> [Option<u32>; 8] {
        core::array::from_fn(|_| {
            can.receive().map(|frame| {
                let id = raw_id(&frame);
                dti.frame(
                    now_ms,
                    id,
                    matches!(frame.id(), Id::Extended(_)),
                    frame.data(),
                );
                id
            })
        })
    }

    /// Queues the `dti enable` test's frames on the inverter bus (each replaces a pending
    /// frame with its id). A frame that did not encode is not sent: the DTI sees silence.
    fn send_dti(bench: &mut Bench, frames: Result<aer_ccm::OutFrames, aer::runtime::EncodeError>) {
        let (Some(can), Ok(frames)) = (bench.inverter_can.as_mut(), frames) else {
            return;
        };
        for frame in frames.iter() {
            let can_frame = ExtendedId::new(frame.id)
                .map(Id::Extended)
                .and_then(|id| CanFrame::new(id, frame.data()));
            if let Some(can_frame) = can_frame {
                let _queued = can.transmit_latest(&can_frame);
            }
        }
    }

    fn raw_id(frame: &CanFrame) -> u32 {
        match frame.id() {
            Id::Standard(id) => u32::from(id.as_raw()),
            Id::Extended(id) => id.as_raw(),
        }
    }

    fn heartbeat_frame(index: usize, payload: &[u8]) -> Option<CanFrame> {
        HEARTBEAT_IDS
            .get(index)
            .and_then(|&id| StandardId::new(id))
            .and_then(|id| CanFrame::new(id, payload))
    }

    fn send_heartbeats(bench: &mut Bench, counter: u8) {
        if let (Some(can), Some(frame)) =
            (bench.vehicle_can.as_mut(), heartbeat_frame(0, &[counter]))
        {
            let _queued = can.transmit(&frame);
        }
        if let (Some(can), Some(frame)) =
            (bench.inverter_can.as_mut(), heartbeat_frame(1, &[counter]))
        {
            let _queued = can.transmit(&frame);
        }
    }

    /// Both brake sensors (BSE1 front, BSE2 rear) in volts at the sensor, as the race image
    /// reads them.
    fn brake_volts(bench: &mut Bench) -> [f32; 2] {
        let divider = board::REVISION.adc_divider;
        let [front, rear] = BRAKES;
        [front, rear].map(|index| {
            bench.analog.get_mut(index).map_or(f32::NAN, |(_, input)| {
                aer_ccm::analog::sensor_volts(bench.adc.read_blocking(input), divider)
            })
        })
    }

    /// Where BSE1 and BSE2 sit in `Bench::analog` (after the pedals on the on-chip ADC).
    #[cfg(not(feature = "pedals-ads1115"))]
    const BRAKES: [usize; 2] = [2, 3];
    #[cfg(feature = "pedals-ads1115")]
    const BRAKES: [usize; 2] = [0, 1];

    /// Both pedal sensors in volts at the sensor, as the race image reads them.
    #[cfg(not(feature = "pedals-ads1115"))]
    fn pedal_volts(bench: &mut Bench) -> aer_ccm::apps::PedalVolts {
        let [(_, apps1), (_, apps2), ..] = &mut bench.analog;
        let counts = [
            bench.adc.read_blocking(apps1),
            bench.adc.read_blocking(apps2),
        ];
        aer_ccm::analog::pedal_volts(counts, board::REVISION.adc_divider)
    }

    #[cfg(feature = "pedals-ads1115")]
    fn pedal_volts(bench: &mut Bench) -> aer_ccm::apps::PedalVolts {
        aer_ccm::ads1115::pedal_volts(bench.ads.poll())
    }

    /// What the typed commands change besides the outputs.
    struct Bring<'a> {
        calibration: &'a mut BenchRecorder,
        feeding: &'a mut bool,
        heartbeats: &'a mut bool,
        gate: &'a mut HvGate,
        dti: &'a mut DtiBench,
    }

    /// Runs one typed command; returns what to print (`"report"`: print a report now).
    fn command(
        bench: &mut Bench,
        line: &str,
        now_ms: u32,
        bring: &mut Bring<'_>,
        log: &mut impl rtic::Mutex<T = LogBuffer<LOG_BYTES>>,
    ) -> &'static str {
        match Command::parse(line) {
            Ok(Command::Help) => {
                log.lock(|log| {
                    for text in HELP {
                        log.line(format_args!("{text}"));
                    }
                });
                "that is all"
            }
            Ok(Command::Report) => "report",
            Ok(Command::Output { signal, level }) => output(bench, signal, level),
            Ok(Command::AllOff) => {
                all_off(bench);
                bring.dti.test.stop();
                bring.gate.revoke();
                "every output off"
            }
            Ok(Command::ConfirmHvDisconnected) => {
                let dc_link = [("DTI DC link", bring.dti.dc_link_v(now_ms))];
                match bring.gate.confirm(now_ms, HvReadings { volts: &dc_link }) {
                    Ok(()) => {
                        "HV confirmed (the DTI reads its DC link below 60 V): `dti enable` armed for 30 s"
                    }
                    Err(refusal) => {
                        log.lock(|log| log.line(format_args!("refused: {refusal}")));
                        "not confirmed"
                    }
                }
            }
            Ok(Command::DtiEnable) => {
                let dc_link = [("DTI DC link", bring.dti.dc_link_v(now_ms))];
                match bring.gate.allows(now_ms, HvReadings { volts: &dc_link }) {
                    Ok(()) => {
                        bring.dti.test.start(now_ms);
                        "drive enable at 0 A for 1 s, then silence: the report's `DTI command timeout` line gives the result"
                    }
                    Err(refusal) => {
                        log.lock(|log| log.line(format_args!("refused: {refusal}")));
                        "not started"
                    }
                }
            }
            Ok(Command::CanTest) => {
                let vehicle = bench
                    .vehicle_can
                    .as_mut()
                    .zip(heartbeat_frame(0, &[0xA5, 0x5A, 3]))
                    .map(|(can, frame)| can.self_test(&frame));
                let inverter = bench
                    .inverter_can
                    .as_mut()
                    .zip(heartbeat_frame(1, &[0xA5, 0x5A, 2]))
                    .map(|(can, frame)| can.self_test(&frame));
                log.lock(|log| {
                    log.line(format_args!(
                        "{}",
                        SelfTestLine {
                            name: "CAN3 (vehicle)",
                            result: vehicle
                        }
                    ));
                    log.line(format_args!(
                        "{}",
                        SelfTestLine {
                            name: "CAN2 (inverter)",
                            result: inverter
                        }
                    ));
                });
                *bring.heartbeats = true;
                "heartbeats 0x7F3 on CAN3 and 0x7F2 on CAN2 every second from now"
            }
            Ok(Command::Calibrate(position)) => {
                bring.calibration.start(match position {
                    PedalPosition::Rest => BenchPoint::Rest,
                    PedalPosition::Full => BenchPoint::Full,
                });
                "recording for 1 s: hold the pedal still"
            }
            Ok(Command::I2cScan) => i2c_scan(bench, log),
            Ok(Command::WatchdogTest) => {
                *bring.feeding = false;
                "watchdog no longer fed: the CCM resets within 1 s and reports the cause"
            }
            Ok(Command::Bootloader) => {
                REBOOT.request();
                "rebooting into the bootloader, every output off"
            }
            Err(CommandError::Unknown(_)) => "unknown command: `help`",
            Err(CommandError::Usage(usage)) => usage,
        }
    }

    fn output(bench: &mut Bench, signal: &str, level: Level) -> &'static str {
        let digital = |pin: &gpio::Output| {
            if level.high() {
                pin.set();
            } else {
                pin.clear();
            }
        };
        match signal {
            "brake-light" => digital(&bench.brake_light),
            "led" => digital(&bench.led),
            "pump1" => bench.pumps.set_duty(flexpwm::Channel::A, level.duty()),
            "pump2" => bench.pumps.set_duty(flexpwm::Channel::B, level.duty()),
            "fan" => bench.fan.set_duty(flexpwm::Channel::B, level.duty()),
            "rtd-buzzer" => bench
                .buzzer
                .set_duty(flexpwm::Channel::A, level.duty() / 2.0),
            _ => return "no such output: brake-light, led, pump1, pump2, fan, rtd-buzzer",
        }
        "done"
    }

    fn all_off(bench: &mut Bench) {
        bench.brake_light.clear();
        bench.pumps.set_duty(flexpwm::Channel::A, 0.0);
        bench.pumps.set_duty(flexpwm::Channel::B, 0.0);
        bench.fan.set_duty(flexpwm::Channel::B, 0.0);
        bench.buzzer.set_duty(flexpwm::Channel::A, 0.0);
    }

    #[cfg(not(feature = "pedals-ads1115"))]
    fn i2c_scan(_: &mut Bench, _: &mut impl rtic::Mutex<T = LogBuffer<LOG_BYTES>>) -> &'static str {
        "this board reads the pedals on the on-chip ADC: no I2C (build with --features pedals-ads1115)"
    }

    /// Every 7-bit address that acknowledges a one-byte read, then the ADS1115's config
    /// register. Each transaction is bounded by the controller's pin-low timeout.
    #[cfg(feature = "pedals-ads1115")]
    fn i2c_scan(
        bench: &mut Bench,
        log: &mut impl rtic::Mutex<T = LogBuffer<LOG_BYTES>>,
    ) -> &'static str {
        use embedded_hal::i2c::I2c;
        let mut byte = [0u8; 1];
        for address in 0x08u8..0x78 {
            if bench.ads.bus().read(address, &mut byte).is_ok() {
                log.lock(|log| log.line(format_args!("i2c: {address:#04x} answers")));
            }
        }
        let config = bench.ads.read_config();
        log.lock(|log| log.line(format_args!("ADS1115 config register: {config:04x?}")));
        "scan done"
    }

    type WheelEdges = ([u32; 2], [u32; 2], [bool; 2]);

    fn report(
        bench: &mut Bench,
        log: &mut impl rtic::Mutex<T = LogBuffer<LOG_BYTES>>,
        now_ms: u32,
        elapsed_ms: u32,
        (wheels_before, wheels_now, wheel_levels): WheelEdges,
        button_edges: [u32; 2],
        (heard, dti): (&[Heard; 2], &DtiBench),
    ) {
        let divider = board::REVISION.adc_divider;
        let analog: [AnalogReading; ANALOG] = core::array::from_fn(|index| {
            let (pin, counts) = bench
                .analog
                .get_mut(index)
                .map_or((board::REVISION.thermistor, 0), |(pin, input)| {
                    (*pin, bench.adc.read_blocking(input))
                });
            AnalogReading {
                pin,
                counts,
                divider,
            }
        });
        #[cfg(feature = "pedals-ads1115")]
        let ads1115 = Some((pedal_volts(bench), bench.ads.bus_errors));
        #[cfg(not(feature = "pedals-ads1115"))]
        let ads1115 = None;
        let mut digital = [DigitalReading {
            pin: board::REVISION.led,
            high: false,
            edges: 0,
            hz: 0.0,
        }; 4];
        let wheels = board::REVISION
            .wheel_speed
            .into_iter()
            .zip(wheels_before.into_iter().zip(wheels_now).zip(wheel_levels))
            .map(|(pin, ((before, after), high))| DigitalReading {
                pin,
                high,
                edges: after,
                hz: edge_rate_hz(before, after, elapsed_ms),
            });
        let buttons = bench
            .buttons
            .iter()
            .zip(button_edges)
            .map(|((pin, input), edges)| DigitalReading {
                pin: *pin,
                high: input.is_set(),
                edges,
                hz: 0.0,
            });
        for (slot, reading) in digital.iter_mut().zip(wheels.chain(buttons)) {
            *slot = reading;
        }
        let [heard_vehicle, heard_inverter] = heard;
        let report = Report {
            header: ReportHeader { now_ms, dropped: 0 },
            analog: &analog,
            ads1115,
            digital: &digital,
            buses: [
                BusLine {
                    name: "CAN3 (vehicle)",
                    status: bench.vehicle_can.as_ref().map(|can| can.status()),
                    heard: heard_vehicle,
                },
                BusLine {
                    name: "CAN2 (inverter)",
                    status: bench.inverter_can.as_ref().map(|can| can.status()),
                    heard: heard_inverter,
                },
            ],
            dti,
            brake_light: bench.brake_light.is_set(),
        };
        log.lock(|log| {
            Report {
                header: ReportHeader {
                    now_ms,
                    dropped: log.dropped(),
                },
                ..report
            }
            .write(log)
        });
    }
}
