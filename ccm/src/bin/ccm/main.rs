//! CCM firmware for the Teensy 4.1 (RTIC 2). This file is the schedule: the tasks, their
//! priorities and what they share; each task's body is in the file named after it, the
//! hardware set-up in `aer_ccm::hw` (shared with the bring-up image) and every decision in
//! the `aer_ccm` library.
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
//! - `control` (100 Hz, 2): CAN intake, bus health, state machine, torque, outputs, and the
//!   frames the library's schedule says are due (`Control::due`: the inverter's commands
//!   every command period, a command still pending replaced by the newer one; CCM_Status
//!   every 100 ms).
//! - `telemetry` (100 Hz, 1): snapshot -> generated packer -> ISO-TP on 0x666 on CAN3.
//! - `watchdog` (10 Hz, 1): feeds WDOG1 (1 s timeout) only while every task's heartbeat is
//!   younger than 100 ms.
//! - `usb` (USB interrupt, 1): the USB serial console. `control` logs state changes, faults
//!   and bus errors into a bounded buffer (a full one drops lines and counts them; nothing
//!   waits for the host); typing `bootloader`, or `teensy_loader_cli -s` (134 baud), asks for
//!   the bootloader, and `restart` for a software reset; the control task grants either only
//!   outside DRIVING with zero torque commanded (`Control::handover`), after sending the
//!   inverter zero torque and drive disabled, and otherwise refuses with the reason.
//!
//! Torque is zero until the first control step says otherwise. The LED on pin 13 toggles
//! every second (0.5 Hz) while the control task runs.
//!
//! Shared state is split by writer, so each lock's ceiling is only as high as its users:
//! `sensors` (written at 4; read by control and telemetry), `link` (the receive interrupts at
//! 3 and telemetry), `control` (written at 2; read by telemetry), `supervisor` (4).
#![no_std]
#![no_main]

mod can_rx;
mod control;
mod sensors;
mod telemetry;
mod watchdog;
mod xcp;

use aer_ccm::chassis::PulseTimer;
use aer_console::{RebootRequest, StatusRequest};
use core::sync::atomic::AtomicU32;
use rtic_monotonics::imxrt::prelude::*;

imxrt_gpt1_monotonic!(Mono, 1_000_000);

/// Received frames waiting for the control task, per bus.
const RX_QUEUE: usize = 64;
/// XCP commands waiting for the XCP task: a whole master block (MAX_BS packets) and more.
const XCP_QUEUE: usize = 64;

/// Frames dropped because a receive queue was full.
static RX_QUEUE_OVERFLOWS: AtomicU32 = AtomicU32::new(0);
/// Frames not sent: every mailbox busy (bus-off or flooded bus), or the frame could not be
/// encoded. Reported in telemetry with the controllers' own drops.
static TX_NOT_SENT: AtomicU32 = AtomicU32::new(0);
/// Failed I2C transactions with the pedal converter (copied from the sensors task; stays 0
/// with the pedals on the on-chip ADC).
static PEDAL_BUS_ERRORS: AtomicU32 = AtomicU32::new(0);
/// `bootloader` typed, or 134 baud from the host; the control task decides.
static REBOOT: RebootRequest = RebootRequest::new();
/// `status` typed; the control task prints it.
static STATUS: StatusRequest = StatusRequest::new();
/// Front wheel pulse times: written only by `wheel_edge`, read by `control`.
static WHEELS: [PulseTimer; 2] = [PulseTimer::new(), PulseTimer::new()];

/// Microseconds since start; 32 bits wrap every 71 minutes, the library uses differences only.
fn now_us() -> u32 {
    Mono::now().as_ticks() as u32
}

/// Milliseconds since start.
fn now_ms() -> u32 {
    (Mono::now().as_ticks() / 1_000) as u32
}

#[rtic::app(device = teensy4_bsp, peripherals = true, dispatchers = [KPP, PIT, GPT2])]
mod app {
    use crate::can_rx::{inverter_receive, vehicle_receive};
    use crate::control::{Watches, control};
    use crate::sensors::{sensors, wheel_edge};
    use crate::telemetry::telemetry;
    use crate::watchdog::watchdog;
    use crate::xcp::xcp;
    use crate::{Mono, REBOOT, RX_QUEUE, STATUS, XCP_QUEUE};
    use aer_ccm::calibration::EPK;
    use aer_ccm::calibration::measured::{MEASURED, SOURCE};
    use aer_ccm::calibration::state::CalibrationState;
    use aer_ccm::calibration::store::{CalibrationStore, crc32};
    use aer_ccm::console::{CalibrationLine, LOG_BYTES};
    use aer_ccm::constants::INVERTER;
    use aer_ccm::control::Control;
    use aer_ccm::hw::flash::TeensyFlash;
    use aer_ccm::hw::{self, halt, pedals::PedalFrontEnd, pwm::PwmBlock};
    use aer_ccm::sensors::Sensors;
    use aer_ccm::telemetry::TelemetryLink;
    use aer_ccm::watchdog::Supervisor;
    use aer_ccm::xcp::{SeedKey, XcpNode, team::XCP_SECRET};
    use aer_console::usb::{Bus, EndpointState, Memory, UsbConsole, UsbMemory, serve_race};
    use aer_console::{LineReader, LogBuffer};
    use aer_flexcan::{CanFrame, Flexcan};
    use heapless::spsc::{Consumer, Producer, Queue};
    use rtic_monotonics::imxrt::prelude::*;
    use teensy4_bsp::{
        hal::{adc, gpio},
        ral,
    };

    #[shared]
    struct Shared {
        /// The live calibration: the sensor and control steps copy its active page whole at
        /// the start of each step, so a change is never seen half done.
        calibration: CalibrationState,
        /// The XCP slave, its saved copies' flash and what DAQ samples.
        xcp: XcpNode<TeensyFlash>,
        sensors: Sensors,
        link: TelemetryLink,
        control: Control,
        vehicle_can: Flexcan<3>,
        inverter_can: Flexcan<2>,
        supervisor: Supervisor,
        log: LogBuffer<LOG_BYTES>,
    }

    #[local]
    struct Local {
        adc: adc::Adc,
        /// BSE1, BSE2, shocks 1-4.
        analog: [adc::AnalogInput; 6],
        pedals: PedalFrontEnd,
        wheels: [gpio::Input; 2],
        ready_to_move: gpio::Input,
        launch: gpio::Input,
        brake_light: gpio::Output,
        led: gpio::Output,
        pumps: PwmBlock,
        fan: PwmBlock,
        buzzer: PwmBlock,
        vehicle_rx: Producer<'static, CanFrame>,
        xcp_rx: Producer<'static, CanFrame>,
        xcp_commands: Consumer<'static, CanFrame>,
        inverter_rx: Producer<'static, CanFrame>,
        vehicle_frames: Consumer<'static, CanFrame>,
        inverter_frames: Consumer<'static, CanFrame>,
        watches: Watches,
        wdog: ral::wdog::WDOG1,
        console: Option<UsbConsole>,
        typed: LineReader<64>,
    }

    #[init(local = [
        vehicle_queue: Queue<CanFrame, RX_QUEUE> = Queue::new(),
        inverter_queue: Queue<CanFrame, RX_QUEUE> = Queue::new(),
        xcp_queue: Queue<CanFrame, XCP_QUEUE> = Queue::new(),
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
        let product = match INVERTER {
            aer_ccm::InverterKind::Dti => "AER CCM DTI",
            aer_ccm::InverterKind::Ifl100 => "AER CCM IFL100",
        };
        let Ok(board) = hw::start(cx.device, usb, product) else {
            halt()
        };
        // SAFETY: `hw::start` configured GPT1 and does not use it again; the monotonic owns it.
        Mono::start(
            unsafe { ral::gpt::GPT1::instance() },
            Priority::rtic_default(),
        );
        // The calibration, by the one rule: the newest good saved copy of this schema, else the
        // schema's defaults with ccm/calibration.toml's sensors; the start-up line says which.
        let mut flash = TeensyFlash::new(board.board.built_for);
        let (store, loaded) = CalibrationStore::load(&mut flash, EPK);
        let loaded = loaded.or_measured(MEASURED);
        let mut log = LogBuffer::new();
        aer_ccm::console::race_startup(
            &mut log,
            hw::board::REVISION.name,
            INVERTER,
            board.reset_cause,
            board.board,
            CalibrationLine {
                startup: loaded.startup,
                checksum: crc32(&loaded.calibration.to_page()),
                file_source: SOURCE,
            },
        );
        // Without both buses the CCM cannot command the inverter: it halts with no torque.
        let (Ok(mut vehicle_can), Ok(mut inverter_can)) = (board.vehicle_can, board.inverter_can)
        else {
            halt()
        };
        vehicle_can.enable_rx_interrupt();
        inverter_can.enable_rx_interrupt();
        // Thermistor 1 has no telemetry field yet: the bring-up image reads it, this one
        // leaves the pad alone.
        let _thermistor = board.thermistor;

        // The seed generator: 256 bits from the TRNG, personalised with the chip's unique id.
        let chip = aer_console::usb::chip_id().to_le_bytes();
        let keys = SeedKey::new(XCP_SECRET, board.entropy.as_ref().map(|e| &e[..]), &chip);
        if XCP_SECRET.is_some() && !keys.can_unlock() {
            log.line(format_args!(
                "XCP: the TRNG gave no entropy, so seeds would be predictable: calibration stays locked (measuring works)"
            ));
        }
        let xcp_node = XcpNode::new(keys, store, flash);

        let (vehicle_rx, vehicle_frames) = cx.local.vehicle_queue.split();
        let (xcp_rx, xcp_commands) = cx.local.xcp_queue.split();
        let (inverter_rx, inverter_frames) = cx.local.inverter_queue.split();
        if sensors::spawn().is_err()
            || control::spawn().is_err()
            || telemetry::spawn().is_err()
            || watchdog::spawn().is_err()
            || xcp::spawn().is_err()
        {
            halt();
        }
        let [bse1, bse2] = board.brakes;
        let [s1, s2, s3, s4] = board.shocks;
        (
            Shared {
                calibration: CalibrationState::new(loaded.calibration, loaded.startup),
                xcp: xcp_node,
                sensors: Sensors::new(),
                link: TelemetryLink::new(),
                control: Control::new(INVERTER),
                vehicle_can,
                inverter_can,
                supervisor: Supervisor::default(),
                log,
            },
            Local {
                adc: board.adc,
                analog: [bse1, bse2, s1, s2, s3, s4],
                pedals: board.pedals,
                wheels: board.wheels,
                ready_to_move: board.ready_to_move,
                launch: board.launch,
                brake_light: board.brake_light,
                led: board.led,
                pumps: board.pumps,
                fan: board.fan,
                buzzer: board.buzzer,
                vehicle_rx,
                xcp_rx,
                xcp_commands,
                inverter_rx,
                vehicle_frames,
                inverter_frames,
                watches: Watches::default(),
                wdog: board.wdog,
                console: board.console,
                typed: LineReader::new(),
            },
        )
    }

    /// The sensor calibration the image runs with passes the library's check, or the image
    /// does not build (`cargo test -p aer-ccm --test calibration` says why).
    const _: () = if let Err(error) = MEASURED.check() {
        panic!("{}", error.summary())
    };

    /// The USB console: log out, typed bytes in; `bootloader` only, as a request the control
    /// task grants or refuses.
    #[task(binds = USB_OTG1, priority = 1, local = [console, typed], shared = [log])]
    fn usb(mut cx: usb::Context) {
        serve_race(
            cx.local.console.as_mut(),
            &mut cx.shared.log,
            cx.local.typed,
            &REBOOT,
            &STATUS,
        );
    }

    extern "Rust" {
        #[task(binds = GPIO4_COMBINED_0_15, priority = 5, local = [wheels])]
        fn wheel_edge(cx: wheel_edge::Context);

        #[task(priority = 4, local = [adc, analog, pedals],
               shared = [calibration, xcp, sensors, inverter_can, supervisor])]
        async fn sensors(cx: sensors::Context);

        #[task(binds = CAN3, priority = 3, local = [vehicle_rx], shared = [vehicle_can, link])]
        fn vehicle_receive(cx: vehicle_receive::Context);

        #[task(binds = CAN2, priority = 3, local = [inverter_rx, xcp_rx], shared = [inverter_can, link])]
        fn inverter_receive(cx: inverter_receive::Context);

        #[task(priority = 2,
               local = [ready_to_move, launch, brake_light, led, pumps, fan, buzzer,
                        vehicle_frames, inverter_frames, watches],
               shared = [calibration, sensors, control, vehicle_can, inverter_can, supervisor, log])]
        async fn control(cx: control::Context);

        #[task(priority = 1, shared = [sensors, control, link, vehicle_can, inverter_can, calibration, xcp, supervisor])]
        async fn telemetry(cx: telemetry::Context);

        #[task(priority = 1, local = [xcp_commands], shared = [xcp, calibration, control, inverter_can])]
        async fn xcp(cx: xcp::Context);

        #[task(priority = 1, local = [wdog], shared = [supervisor])]
        async fn watchdog(cx: watchdog::Context);
    }
}
