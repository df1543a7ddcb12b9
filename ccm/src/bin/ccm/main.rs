//! CCM firmware for the Teensy 4.1 (RTIC 2).
//!
//! Tasks, highest priority first:
//! - `wheel_edge` (GPIO4 interrupt, 5): time-stamps front wheel-speed pulses into lock-free
//!   timers; it shares no resource, so no lock ever masks it.
//! - `sensors` (1 kHz, 4): on-chip ADC (pedals, brakes, shocks), or the ADS1115 for the pedals
//!   on that board option (every I2C transaction bounded by the controller's pin-low timeout,
//!   and a failing converter backed off, so a stuck bus cannot starve the other tasks).
//! - `vehicle_receive` (CAN3) / `inverter_receive` (CAN2) (interrupts, 3): drain the FlexCAN
//!   FIFOs into bounded queues (overflows counted); the Pi's ISO-TP flow control (0x777) goes
//!   straight to the telemetry sender.
//! - `control` (100 Hz, 2): CAN intake, bus health, state machine, torque, outputs;
//!   the inverter's commands every command period (the DTI's current, drive enable and DC
//!   limits every 10 ms, or the bench IFL100's VCU1/BMS1/BMS2 every 20 ms; a command still
//!   pending replaces the older one), CCM_Status every 100 ms.
//! - `telemetry` (100 Hz, 1): snapshot -> generated packer -> ISO-TP on 0x666 on CAN3.
//! - `watchdog` (10 Hz, 1): feeds WDOG1 (1 s timeout) only while every task's heartbeat is
//!   younger than 100 ms.
//! - `usb` (USB interrupt, 1): the USB serial console. `control` logs state changes, faults
//!   and bus errors into a bounded buffer (a full one drops lines and counts them; nothing
//!   waits for the host); typing `bootloader`, or `teensy_loader_cli -s` (134 baud), asks for
//!   the bootloader, which the control task grants only outside DRIVING with zero torque
//!   commanded (`Control::handover`), after sending the inverter zero torque and drive
//!   disabled, and otherwise refuses with the reason.
//!
//! Every decision is in the `aer_ccm` library; this file moves data between it and the
//! hardware, whose pins come from `board.rs` (checked against `aer_boards::ccm`). Torque is
//! zero until the first control step says otherwise. The LED on pin 13 toggles every second
//! (0.5 Hz) while the control task runs.
//!
//! Shared state is split by writer, so each lock's ceiling is only as high as its users:
//! `sensors` (written at 4; read by control and telemetry), `link` (the receive interrupts at
//! 3 and telemetry), `control` (written at 2; read by telemetry), `supervisor` (4).
#![no_std]
#![no_main]

mod board;
mod pwm;

use teensy4_panic as _;

#[rtic::app(device = teensy4_bsp, peripherals = true, dispatchers = [KPP, PIT, GPT2])]
mod app {
    use crate::board;
    use crate::pwm::PwmBlock;
    use aer::can::CcmStatus;
    use aer::telemetry::Telemetry;
    #[cfg(feature = "pedals-ads1115")]
    use aer_ccm::ads1115::Ads1115;
    use aer_ccm::analog;
    use aer_ccm::calibration::measured::MEASURED;
    use aer_ccm::chassis::PulseTimer;
    use aer_ccm::console::{BootloaderAnswer, LOG_BYTES};
    use aer_ccm::constants::WHEEL_TEETH;
    use aer_ccm::constants::{CONTROL_PERIOD_MS, INVERTER, TELEMETRY_PERIOD_MS, WATCHDOG_CHECK_MS};
    use aer_ccm::control::Control;
    use aer_ccm::faults::{Fault, FaultMap};
    use aer_ccm::sensors::Sensors;
    use aer_ccm::telemetry::TelemetryLink;
    use aer_ccm::watchdog::{Supervisor, Task};
    use aer_ccm::{BusHealth, DriverCounters, DriverInputs, SensorSample};
    use aer_console::usb::{Bus, EndpointState, Memory, UsbConsole, chip_serial};
    use aer_console::{Command, LineReader, LogBuffer, RebootRequest, Watch, bringup::ResetCause};
    use aer_flexcan::{BusStatus, CanFrame, FaultState, Flexcan};
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

    /// Received frames waiting for the control task, per bus.
    const RX_QUEUE: usize = 64;

    /// Frames dropped because a receive queue was full.
    static RX_QUEUE_OVERFLOWS: AtomicU32 = AtomicU32::new(0);
    /// Frames not sent: every mailbox busy (bus-off or flooded bus), or the frame could not
    /// be encoded. Reported in telemetry with the controllers' own drops.
    static TX_NOT_SENT: AtomicU32 = AtomicU32::new(0);
    /// Failed I2C transactions with the pedal converter (copied from the sensors task; stays 0
    /// with the pedals on the on-chip ADC).
    static PEDAL_BUS_ERRORS: AtomicU32 = AtomicU32::new(0);
    /// `bootloader` typed, or 134 baud from the host; the control task decides.
    static REBOOT: RebootRequest = RebootRequest::new();
    /// Front wheel pulse times: written only by `wheel_edge`, read by `control`.
    static WHEELS: [PulseTimer; 2] = [PulseTimer::new(), PulseTimer::new()];

    #[shared]
    struct Shared {
        sensors: Sensors,
        link: TelemetryLink,
        control: Control,
        vehicle_can: Flexcan<3>,
        inverter_can: Flexcan<2>,
        supervisor: Supervisor,
        log: LogBuffer<LOG_BYTES>,
    }

    /// The pedal front-end: the on-chip ADC's two inputs, or the ADS1115.
    #[cfg(not(feature = "pedals-ads1115"))]
    type PedalFrontEnd = [adc::AnalogInput; 2];
    #[cfg(feature = "pedals-ads1115")]
    type PedalFrontEnd = Ads1115<hal::lpi2c::Lpi2c>;

    #[local]
    struct Local {
        adc: adc::Adc,
        /// BSE1, BSE2, shocks 1-4.
        analog: [adc::AnalogInput; 6],
        pedals: PedalFrontEnd,
        wheel_left: gpio::Input,
        wheel_right: gpio::Input,
        ready_to_move: gpio::Input,
        launch: gpio::Input,
        brake_light: gpio::Output,
        led: gpio::Output,
        pumps: PwmBlock,
        fan: PwmBlock,
        buzzer: PwmBlock,
        vehicle_rx: Producer<'static, CanFrame>,
        inverter_rx: Producer<'static, CanFrame>,
        vehicle_frames: Consumer<'static, CanFrame>,
        inverter_frames: Consumer<'static, CanFrame>,
        wdog: ral::wdog::WDOG1,
        usb: Option<UsbConsole>,
        typed: LineReader<64>,
    }

    #[init(local = [
        vehicle_queue: Queue<CanFrame, RX_QUEUE> = Queue::new(),
        inverter_queue: Queue<CanFrame, RX_QUEUE> = Queue::new(),
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

        let Ok(brake_light) = gpio2.output(pins.brake_light) else {
            halt()
        };
        let Ok(led) = gpio2.output(pins.led) else {
            halt()
        };
        // The buttons read low (off) when a wire is open; the wheel-speed sensors' open
        // collectors need the pull-up.
        let pull_down = Config::modify().set_pull_keeper(Some(PullKeeper::Pulldown100k));
        let pull_up = Config::modify().set_pull_keeper(Some(PullKeeper::Pullup22k));
        iomuxc::configure(&mut pins.ready_to_move, pull_down);
        iomuxc::configure(&mut pins.launch, pull_down);
        iomuxc::configure(&mut pins.wheels.0, pull_up);
        iomuxc::configure(&mut pins.wheels.1, pull_up);
        let (Ok(ready_to_move), Ok(launch)) =
            (gpio2.input(pins.ready_to_move), gpio4.input(pins.launch))
        else {
            halt()
        };
        let (Ok(wheel_left), Ok(wheel_right)) =
            (gpio4.input(pins.wheels.0), gpio4.input(pins.wheels.1))
        else {
            halt()
        };
        let rising = Some(gpio::Trigger::RisingEdge);
        if gpio4.set_interrupt(&wheel_left, rising).is_err()
            || gpio4.set_interrupt(&wheel_right, rising).is_err()
        {
            halt();
        }

        let (mut pump1, mut pump2) = pins.pumps;
        let mut fan_pin = pins.fan;
        let mut buzzer_pin = pins.buzzer;
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
        let (Ok(a3), Ok(a2), Ok(a6), Ok(a7), Ok(a8), Ok(a9)) = (
            adc.input::<_, 1>(bse1),
            adc.input::<_, 1>(bse2),
            adc.input::<_, 1>(s1),
            adc.input::<_, 1>(s2),
            adc.input::<_, 1>(s3),
            adc.input::<_, 1>(s4),
        ) else {
            halt()
        };
        let pedals = pedal_front_end(&mut adc, pins.pedals, lpi2c1);
        // Thermistor 1 has no telemetry field yet: the bring-up image reads it, this one
        // leaves the pad alone.
        let _thermistor = pins.thermistor;

        gpt1.set_clock_source(hal::gpt::ClockSource::PeripheralClock);
        gpt1.set_divider(bsp::PERCLK_FREQUENCY / 1_000_000);
        // SAFETY: `gpt1` is configured above and not used again; the monotonic owns it.
        Mono::start(
            unsafe { ral::gpt::GPT1::instance() },
            Priority::rtic_default(),
        );

        // SAFETY: the BSP does not hand out FlexCAN or WDOG1; nothing else uses them.
        let (can3_regs, can2_regs, wdog, src) = unsafe {
            (
                ral::can3::CAN3::instance(),
                ral::can::CAN2::instance(),
                ral::wdog::WDOG1::instance(),
                ral::src::SRC::instance(),
            )
        };
        // Why this start (SRC_SRSR, sticky: cleared so the next start is judged on its own).
        let srsr = ral::read_reg!(ral::src, src, SRSR);
        ral::write_reg!(ral::src, src, SRSR, srsr);
        // The console is a convenience: without it the CCM runs as before.
        let usb = UsbConsole::new(
            usb,
            cx.local.usb_memory,
            cx.local.usb_state,
            cx.local.usb_bus,
            match INVERTER {
                aer_ccm::InverterKind::Dti => "AER CCM DTI",
                aer_ccm::InverterKind::Ifl100 => "AER CCM IFL100",
            },
            chip_serial(cx.local.serial),
        )
        .ok();
        let mut log = LogBuffer::new();
        aer_ccm::console::race_startup(&mut log, board::REVISION.name, INVERTER, ResetCause(srsr));
        let (tx3, rx3) = pins.vehicle_can;
        let (tx2, rx2) = pins.inverter_can;
        let (Ok(mut vehicle_can), Ok(mut inverter_can)) = (
            Flexcan::new_can3(can3_regs, tx3, rx3, &ccm, board::CAN_BITRATE),
            Flexcan::new(can2_regs, tx2, rx2, &ccm, board::CAN_BITRATE),
        ) else {
            halt()
        };
        vehicle_can.enable_rx_interrupt();
        inverter_can.enable_rx_interrupt();
        start_watchdog(&wdog);

        let (vehicle_rx, vehicle_frames) = cx.local.vehicle_queue.split();
        let (inverter_rx, inverter_frames) = cx.local.inverter_queue.split();
        if sensors::spawn().is_err()
            || control::spawn().is_err()
            || telemetry::spawn().is_err()
            || watchdog::spawn().is_err()
        {
            halt();
        }
        (
            Shared {
                sensors: Sensors::new(MEASURED),
                link: TelemetryLink::new(),
                control: Control::new(INVERTER),
                vehicle_can,
                inverter_can,
                supervisor: Supervisor::default(),
                log,
            },
            Local {
                adc,
                analog: [a3, a2, a6, a7, a8, a9],
                pedals,
                wheel_left,
                wheel_right,
                ready_to_move,
                launch,
                brake_light,
                led,
                pumps,
                fan,
                buzzer,
                vehicle_rx,
                inverter_rx,
                vehicle_frames,
                inverter_frames,
                wdog,
                usb,
                typed: LineReader::new(),
            },
        )
    }

    /// The sensor calibration the image runs with passes the library's check, or the image
    /// does not build (`cargo test -p aer-ccm --test calibration` says why).
    const _: () = if let Err(error) = MEASURED.check() {
        panic!("{}", error.summary())
    };

    /// The USB console: log out, typed bytes in. The race image takes `bootloader` only, as
    /// a request the control task grants or refuses.
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

    /// Logs what changed this control step: the vehicle state, the fault map, either bus's
    /// fault confinement state; every 5 s the drop counters.
    fn log_changes(
        log: &mut LogBuffer<LOG_BYTES>,
        watches: &mut Watches,
        now: u32,
        outputs: &aer_ccm::ControlOutputs,
        counters: &DriverCounters,
        buses: [FaultState; 2],
    ) {
        if let Some(state) = watches.state.changed(outputs.vehicle.state) {
            log.line(format_args!("t={now} ms vehicle {state:?}"));
        }
        if let Some(faults) = watches.faults.changed(outputs.faults) {
            log.line(format_args!(
                "t={now} ms faults {:#06x}:{}",
                faults.bits(),
                FaultNames(faults)
            ));
        }
        if let Some([vehicle, inverter]) = watches.buses.changed(buses) {
            log.line(format_args!(
                "t={now} ms vehicle bus (CAN3) {vehicle:?}, inverter bus (CAN2) {inverter:?}"
            ));
        }
        if now % 5_000 < CONTROL_PERIOD_MS {
            let dropped = log.dropped();
            log.line(format_args!(
                "t={now} ms rx dropped {}, tx dropped {}, pedal bus errors {}, bus-off events {}/{}, log lines dropped {dropped}",
                counters.rx_dropped,
                counters.tx_dropped,
                counters.pedal_bus_errors,
                counters.buses[0].bus_off_events,
                counters.buses[1].bus_off_events,
            ));
        }
    }

    /// What `log_changes` compares against.
    pub struct Watches {
        state: Watch<aer_ccm::vehicle::State>,
        faults: Watch<FaultMap>,
        buses: Watch<[FaultState; 2]>,
    }

    /// The active faults' names.
    struct FaultNames(FaultMap);

    impl core::fmt::Display for FaultNames {
        fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
            for fault in Fault::ALL {
                if self.0.has(fault) {
                    write!(f, " {fault:?}")?;
                }
            }
            Ok(())
        }
    }

    /// APPS1 (A5) and APPS2 (A4) on the on-chip ADC.
    #[cfg(not(feature = "pedals-ads1115"))]
    fn pedal_front_end(
        adc: &mut adc::Adc,
        (apps1, apps2): board::PedalPins,
        _: ral::lpi2c::LPI2C1,
    ) -> PedalFrontEnd {
        let (Ok(apps1), Ok(apps2)) = (adc.input::<_, 1>(apps1), adc.input::<_, 1>(apps2)) else {
            halt()
        };
        [apps1, apps2]
    }

    /// The ADS1115 on LPI2C1 (SCL 19, SDA 18), with the controller's pin-low timeout on:
    /// SCL or SDA held low for about 1 ms ends the transaction with an error instead of a
    /// wait without end (imxrt-hal's blocking I2C has no timeout of its own).
    #[cfg(feature = "pedals-ads1115")]
    fn pedal_front_end(
        _: &mut adc::Adc,
        (scl, sda): board::PedalPins,
        lpi2c1: ral::lpi2c::LPI2C1,
    ) -> PedalFrontEnd {
        let mut i2c = bsp::lpi2c(lpi2c1, scl, sda, bsp::Lpi2cClockSpeed::KHz400);
        i2c.disabled(|_| {
            // SAFETY: LPI2C1 is owned by `i2c` and disabled inside this closure; only its
            // timeout configuration changes.
            let regs = unsafe { ral::lpi2c::LPI2C1::instance() };
            // TIMECFG = 1: the timeout watches SDA as well as SCL.
            ral::modify_reg!(ral::lpi2c, regs, MCFGR1, TIMECFG: 1);
            ral::modify_reg!(ral::lpi2c, regs, MCFGR3, PINLOW: I2C_PIN_LOW_TIMEOUT);
        });
        Ads1115::new(i2c)
    }

    /// MCFGR3.PINLOW in units of 256 LPI2C clock cycles (8 MHz, prescaler 1 at 400 kHz):
    /// 32 x 32 us = about 1 ms.
    #[cfg(feature = "pedals-ads1115")]
    const I2C_PIN_LOW_TIMEOUT: u32 = 32;

    /// Start-up failed (a pin on the wrong port, a controller that does not start): outputs
    /// stay unconfigured (no torque is ever commanded) and the watchdog is never started.
    fn halt() -> ! {
        loop {
            cortex_m::asm::wfi();
        }
    }

    fn now_us() -> u32 {
        // 32-bit microseconds wrap every 71 minutes; the library uses differences only.
        Mono::now().as_ticks() as u32
    }

    fn now_ms() -> u32 {
        (Mono::now().as_ticks() / 1_000) as u32
    }

    /// WDOG1 with a 1 s timeout: WT = 1 (0.5 s steps, plus one), enabled. The power-down
    /// counter is switched off so only a missed service resets the CCM.
    fn start_watchdog(wdog: &ral::wdog::WDOG1) {
        ral::write_reg!(ral::wdog, wdog, WMCR, 0);
        ral::modify_reg!(ral::wdog, wdog, WCR, WT: 1, WDE: 1);
    }

    fn feed_watchdog(wdog: &ral::wdog::WDOG1) {
        ral::write_reg!(ral::wdog, wdog, WSR, 0x5555);
        ral::write_reg!(ral::wdog, wdog, WSR, 0xAAAA);
    }

    #[task(binds = GPIO4_COMBINED_0_15, priority = 5, local = [wheel_left, wheel_right])]
    fn wheel_edge(cx: wheel_edge::Context) {
        let now = now_us();
        let [left, right] = &WHEELS;
        if cx.local.wheel_left.is_triggered() {
            cx.local.wheel_left.clear_triggered();
            left.on_pulse(now);
        }
        if cx.local.wheel_right.is_triggered() {
            cx.local.wheel_right.clear_triggered();
            right.on_pulse(now);
        }
    }

    #[task(priority = 4, local = [adc, analog, pedals], shared = [sensors, supervisor])]
    async fn sensors(mut cx: sensors::Context) {
        let mut next = Mono::now();
        loop {
            next += 1u64.millis();
            let adc = &mut cx.local.adc;
            let [bse1, bse2, s1, s2, s3, s4] = cx
                .local
                .analog
                .each_mut()
                .map(|input| adc.read_blocking(input));
            let divider = board::REVISION.adc_divider;
            let sample = SensorSample {
                apps_v: read_pedals(adc, cx.local.pedals),
                brake_v: (
                    analog::sensor_volts(bse1, divider),
                    analog::sensor_volts(bse2, divider),
                ),
                shock_raw: [s1, s2, s3, s4],
            };
            let now = now_ms();
            cx.shared
                .sensors
                .lock(|sensors| sensors.sample(&sample, now));
            cx.shared
                .supervisor
                .lock(|supervisor| supervisor.beat(Task::Sensors, now));
            Mono::delay_until(next).await;
        }
    }

    #[cfg(not(feature = "pedals-ads1115"))]
    fn read_pedals(
        adc: &mut adc::Adc,
        [apps1, apps2]: &mut PedalFrontEnd,
    ) -> aer_ccm::apps::PedalVolts {
        let counts = [adc.read_blocking(apps1), adc.read_blocking(apps2)];
        analog::pedal_volts(counts, board::REVISION.adc_divider)
    }

    #[cfg(feature = "pedals-ads1115")]
    fn read_pedals(_: &mut adc::Adc, ads: &mut PedalFrontEnd) -> aer_ccm::apps::PedalVolts {
        let volts = aer_ccm::ads1115::pedal_volts(ads.poll());
        PEDAL_BUS_ERRORS.store(ads.bus_errors, Ordering::Relaxed);
        volts
    }

    /// Drains a FIFO; the Pi's flow control goes to the telemetry sender at once.
    fn drain<const N: u8>(
        can: &mut Flexcan<N>,
        queue: &mut Producer<'static, CanFrame>,
        link: &mut impl rtic::Mutex<T = TelemetryLink>,
    ) {
        while let Some(frame) = can.receive() {
            if frame.id() == Id::Standard(flow_control_id()) {
                let now = now_us();
                link.lock(|link| link.on_flow_control(frame.data(), now));
            } else if queue.enqueue(frame).is_err() {
                RX_QUEUE_OVERFLOWS.fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    fn flow_control_id() -> StandardId {
        StandardId::new(Telemetry::FLOW_CONTROL_ID).unwrap_or(StandardId::MAX)
    }

    #[task(binds = CAN3, priority = 3, local = [vehicle_rx], shared = [vehicle_can, link])]
    fn vehicle_receive(mut cx: vehicle_receive::Context) {
        let queue = cx.local.vehicle_rx;
        let link = &mut cx.shared.link;
        cx.shared.vehicle_can.lock(|can| drain(can, queue, link));
    }

    #[task(binds = CAN2, priority = 3, local = [inverter_rx], shared = [inverter_can, link])]
    fn inverter_receive(mut cx: inverter_receive::Context) {
        let queue = cx.local.inverter_rx;
        let link = &mut cx.shared.link;
        cx.shared.inverter_can.lock(|can| drain(can, queue, link));
    }

    /// How a frame is queued: behind a pending one with its identifier, or replacing it.
    #[derive(Clone, Copy, PartialEq, Eq)]
    enum Queueing {
        Behind,
        Replacing,
    }

    fn send<const N: u8>(
        can: &mut impl rtic::Mutex<T = Flexcan<N>>,
        id: u32,
        data: &[u8],
        queueing: Queueing,
    ) {
        send_as(can, id, false, data, queueing);
    }

    fn send_as<const N: u8>(
        can: &mut impl rtic::Mutex<T = Flexcan<N>>,
        id: u32,
        extended: bool,
        data: &[u8],
        queueing: Queueing,
    ) {
        let id = if extended {
            ExtendedId::new(id).map(Id::Extended)
        } else {
            u16::try_from(id)
                .ok()
                .and_then(StandardId::new)
                .map(Id::Standard)
        };
        let frame = id.and_then(|id| CanFrame::new(id, data));
        let sent = frame.is_some_and(|frame| {
            can.lock(|can| match queueing {
                Queueing::Behind => can.transmit(&frame),
                Queueing::Replacing => can.transmit_latest(&frame),
            })
            .is_ok()
        });
        if !sent {
            TX_NOT_SENT.fetch_add(1, Ordering::Relaxed);
        }
    }

    fn health(status: &BusStatus) -> BusHealth {
        BusHealth {
            error_passive: status.state == FaultState::ErrorPassive,
            bus_off: status.state == FaultState::BusOff,
            bus_off_events: status.bus_off_events,
        }
    }

    #[task(priority = 2,
           local = [ready_to_move, launch, brake_light, led, pumps, fan, buzzer, vehicle_frames,
                    inverter_frames,
                    watches: Watches = Watches {
                        state: Watch::new(),
                        faults: Watch::new(),
                        buses: Watch::new(),
                    }],
           shared = [sensors, control, vehicle_can, inverter_can, supervisor, log])]
    async fn control(mut cx: control::Context) {
        let mut next = Mono::now();
        let mut step: u32 = 0;
        loop {
            next += u64::from(CONTROL_PERIOD_MS).millis();
            let now = now_ms();
            let now_micros = now_us();
            let (vehicle_frames, inverter_frames) =
                (&mut cx.local.vehicle_frames, &mut cx.local.inverter_frames);
            let driver = DriverInputs {
                ready_to_move: cx.local.ready_to_move.is_set(),
                launch: cx.local.launch.is_set(),
            };
            let vehicle_bus = cx.shared.vehicle_can.lock(|can| can.check_errors());
            let inverter_bus = cx.shared.inverter_can.lock(|can| can.check_errors());
            let counters = DriverCounters {
                rx_dropped: RX_QUEUE_OVERFLOWS
                    .load(Ordering::Relaxed)
                    .wrapping_add(vehicle_bus.rx_fifo_overflows)
                    .wrapping_add(inverter_bus.rx_fifo_overflows),
                tx_dropped: TX_NOT_SENT
                    .load(Ordering::Relaxed)
                    .wrapping_add(vehicle_bus.tx_dropped)
                    .wrapping_add(inverter_bus.tx_dropped),
                pedal_bus_errors: PEDAL_BUS_ERRORS.load(Ordering::Relaxed),
                buses: [health(&vehicle_bus), health(&inverter_bus)],
            };
            let sensors = cx.shared.sensors.lock(|sensors| sensors.reading());
            let [left, right] = &WHEELS;
            let wheels = [left.speed(WHEEL_TEETH), right.speed(WHEEL_TEETH)];
            let (outputs, due, handover) = cx.shared.control.lock(|control| {
                control.set_driver_counters(counters);
                while let Some(frame) = vehicle_frames.dequeue() {
                    control.on_frame(&frame, now);
                }
                while let Some(frame) = inverter_frames.dequeue() {
                    control.on_frame(&frame, now);
                }
                let outputs = control.step(&sensors, wheels, driver, now, now_micros);
                let due = control.due(step);
                let handover = REBOOT.take().then(|| control.handover());
                (outputs, due, handover)
            });
            let watches = &mut cx.local.watches;
            cx.shared.log.lock(|log| {
                log_changes(
                    log,
                    watches,
                    now,
                    &outputs,
                    &counters,
                    [vehicle_bus.state, inverter_bus.state],
                )
            });
            if outputs.brake_light {
                cx.local.brake_light.set();
            } else {
                cx.local.brake_light.clear();
            }
            // Both pumps run together; the fan is FlexPWM1 SM3's B output.
            cx.local
                .pumps
                .set_duty(flexpwm::Channel::A, outputs.cooling.pump);
            cx.local
                .pumps
                .set_duty(flexpwm::Channel::B, outputs.cooling.pump);
            cx.local
                .fan
                .set_duty(flexpwm::Channel::B, outputs.cooling.fan);
            if now % 1_000 < CONTROL_PERIOD_MS {
                cx.local.led.toggle();
            }
            cx.local.buzzer.set_duty(
                flexpwm::Channel::A,
                if outputs.vehicle.rtd_sound { 0.5 } else { 0.0 },
            );

            match due.inverter {
                Some(Ok(frames)) => {
                    // A torque command never waits behind an older one: it replaces it.
                    for frame in frames.iter() {
                        send_as(
                            &mut cx.shared.inverter_can,
                            frame.id,
                            frame.extended,
                            frame.data(),
                            Queueing::Replacing,
                        );
                    }
                }
                Some(Err(_)) => {
                    TX_NOT_SENT.fetch_add(1, Ordering::Relaxed);
                }
                None => {}
            }
            if let Some(status) = due.status {
                let mut data = [0u8; CcmStatus::LEN];
                if status.encode(&mut data).is_ok() {
                    send(
                        &mut cx.shared.vehicle_can,
                        CcmStatus::ID,
                        &data,
                        Queueing::Behind,
                    );
                    send(
                        &mut cx.shared.inverter_can,
                        CcmStatus::ID,
                        &data,
                        Queueing::Behind,
                    );
                } else {
                    TX_NOT_SENT.fetch_add(2, Ordering::Relaxed);
                }
            }
            if let Some(handover) = handover {
                let answer = match handover {
                    Ok(frames) => {
                        for frame in frames.iter() {
                            send_as(
                                &mut cx.shared.inverter_can,
                                frame.id,
                                frame.extended,
                                frame.data(),
                                Queueing::Replacing,
                            );
                        }
                        cx.local.brake_light.clear();
                        cx.local.pumps.set_duty(flexpwm::Channel::A, 0.0);
                        cx.local.pumps.set_duty(flexpwm::Channel::B, 0.0);
                        cx.local.fan.set_duty(flexpwm::Channel::B, 0.0);
                        cx.local.buzzer.set_duty(flexpwm::Channel::A, 0.0);
                        BootloaderAnswer::Obeyed
                    }
                    Err(why) => BootloaderAnswer::Refused(why),
                };
                cx.shared
                    .log
                    .lock(|log| log.line(format_args!("t={now} ms {answer}")));
                if answer == BootloaderAnswer::Obeyed {
                    // Two frame times at 500 kbit/s for the safe commands to leave the
                    // mailboxes, then the bootloader.
                    Mono::delay(2u64.millis()).await;
                    aer_console::usb::reboot_to_bootloader();
                }
            }
            cx.shared.supervisor.lock(|supervisor| {
                supervisor.beat(Task::Control, now);
                supervisor.beat(Task::Inverter, now);
            });
            step = step.wrapping_add(1);
            Mono::delay_until(next).await;
        }
    }

    #[task(priority = 1, shared = [sensors, control, link, vehicle_can, supervisor])]
    async fn telemetry(mut cx: telemetry::Context) {
        let mut next = Mono::now();
        loop {
            next += u64::from(TELEMETRY_PERIOD_MS).millis();
            let started = now_us();
            let sensors = cx.shared.sensors.lock(|sensors| sensors.reading());
            let counters = cx.shared.link.lock(|link| link.counters());
            let snapshot = cx
                .shared
                .control
                .lock(|control| control.snapshot(&sensors, counters));
            cx.shared.link.lock(|link| link.send(&snapshot, started));
            // Feed the ISO-TP frames out as mailboxes free up, until the packet is done or
            // the next snapshot is due (which then supersedes it, counted by the link).
            while Mono::now() < next {
                let now = now_us();
                let Some(frame) = cx.shared.link.lock(|link| link.poll(now)) else {
                    // Waiting for flow control or STmin, or done: check again shortly.
                    Mono::delay(200u64.micros()).await;
                    continue;
                };
                let queued = StandardId::new(Telemetry::TX_ID)
                    .and_then(|id| CanFrame::new(id, frame.as_slice()))
                    .is_some_and(|can_frame| {
                        cx.shared
                            .vehicle_can
                            .lock(|can| can.transmit(&can_frame))
                            .is_ok()
                    });
                if queued {
                    cx.shared.link.lock(|link| link.sent(now));
                } else {
                    Mono::delay(100u64.micros()).await;
                }
            }
            let now = now_ms();
            cx.shared
                .supervisor
                .lock(|supervisor| supervisor.beat(Task::Telemetry, now));
            Mono::delay_until(next).await;
        }
    }

    #[task(priority = 1, local = [wdog], shared = [supervisor])]
    async fn watchdog(mut cx: watchdog::Context) {
        loop {
            let now = now_ms();
            if cx
                .shared
                .supervisor
                .lock(|supervisor| supervisor.overdue(now))
                == 0
            {
                feed_watchdog(cx.local.wdog);
            }
            Mono::delay(u64::from(WATCHDOG_CHECK_MS).millis()).await;
        }
    }
}
