//! PCC firmware for the Teensy 4.0 (RTIC 2). This file is the schedule: the tasks, their
//! priorities and what they share; each task's body is in the file named after it, the
//! hardware set-up in `aer_pcc::hw` (shared with the bring-up image) and every decision in
//! the `aer_pcc` library.
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
//!   `bootloader`, or `teensy_loader_cli -s` (134 baud), asks for the bootloader, and
//!   `restart` for a software reset; the control task grants either only in STANDBY or ERROR
//!   with the tractive system below 60 V (`Precharge::handover`), after opening AIR+, and
//!   otherwise refuses with the reason.
//!
//! The board (`aer_boards::pcc::COMP_CAR`, typed in `aer_pcc::hw::board`) has one relay
//! output: pin 11 closes AIR+. AIR- and the precharge relay are the shutdown circuit's.
//!
//! Failing safe: pin 11 is low (AIR+ open) from reset until a control step in ONLINE or
//! CHARGING raises it; its pad gets the internal 100 kOhm pull-down before it becomes an
//! output (between reset and init it is an input with only the pad keeper, so the board's
//! driver stage needs its own pull-down: check it on the bench). WDOG1 (0.5 s) is serviced
//! only by an on-time control loop, so a hang restarts the PCC, and a restart leaves pin 11 an
//! input again; the panic handler (`aer_pcc::hw`) drives pin 11 low before anything else and
//! then lets the watchdog restart it. After a watchdog restart the PCC starts in ERROR with
//! the "undefined state" cause latched until a power cycle (LV off and USB unplugged) or a
//! typed `restart` (a software reset, which the next start does not take for a watchdog's).
#![no_std]
#![no_main]

mod control;
mod inputs;

use aer_console::{RebootRequest, StatusRequest};
use core::sync::atomic::AtomicU32;
use rtic_monotonics::imxrt::prelude::*;

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
/// `status` typed; the control task prints it.
static STATUS: StatusRequest = StatusRequest::new();

#[rtic::app(device = teensy4_bsp, peripherals = true, dispatchers = [KPP])]
mod app {
    use crate::control::{RelayPins, Thermistors, control};
    use crate::inputs::{can_receive, voltage_edge};
    use crate::{Mono, REBOOT, RX_QUEUE, STATUS};
    use aer_console::usb::{Bus, EndpointState, Memory, UsbConsole, UsbMemory, serve_race};
    use aer_console::{LineReader, LogBuffer};
    use aer_flexcan::{CanFrame, Flexcan};
    use aer_pcc::console::{LOG_BYTES, RaceLog};
    use aer_pcc::constants::CONVERTERS;
    use aer_pcc::hw::{self, WatchdogTimeout, board, halt_safe};
    use aer_pcc::measurement::VoltageChannel;
    use aer_pcc::watchdog::reset_by_watchdog;
    use aer_pcc::{Relays, TASK_PERIOD_MS};
    use heapless::spsc::{Consumer, Producer, Queue};
    use rtic_monotonics::imxrt::prelude::*;
    use teensy4_bsp::{hal::gpio, ral};

    #[shared]
    struct Shared {
        accumulator: VoltageChannel,
        tractive: VoltageChannel,
        can: Flexcan<{ board::CAN_INSTANCE }>,
        log: LogBuffer<LOG_BYTES>,
    }

    #[local]
    struct Local {
        vf: [gpio::Input; 2],
        relays: RelayPins,
        led: gpio::Output,
        rx_producer: Producer<'static, CanFrame>,
        rx_consumer: Consumer<'static, CanFrame>,
        wdog: ral::wdog::WDOG1,
        watchdog_reset: bool,
        race_log: RaceLog,
        thermistors: Thermistors,
        console: Option<UsbConsole>,
        typed: LineReader<64>,
    }

    #[init(local = [
        rx_queue: Queue<CanFrame, RX_QUEUE> = Queue::new(),
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
        let Ok(board) = hw::start(cx.device, usb, "AER PCC") else {
            halt_safe()
        };
        let mut relays = RelayPins::new(board.air_plus);
        relays.apply(Relays::ALL_OPEN);
        let adc = board.adc;
        let (thermistor1, thermistor2) = board.thermistors;
        let (Ok(thermistor1), Ok(thermistor2)) = (
            adc.input::<_, 1>(thermistor1),
            adc.input::<_, 1>(thermistor2),
        ) else {
            halt_safe()
        };
        let thermistors = Thermistors {
            adc,
            inputs: [thermistor1, thermistor2],
        };
        // SAFETY: `hw::start` configured GPT1 and does not use it again; the monotonic owns it.
        Mono::start(
            unsafe { ral::gpt::GPT1::instance() },
            Priority::rtic_default(),
        );
        // The relays are open; without CAN the PCC cannot see the BMS, so it stays here.
        let Ok(mut can) = board.can else { halt_safe() };
        can.enable_rx_interrupt();
        hw::start_watchdog(&board.wdog, WatchdogTimeout::HalfSecond);
        let mut log = LogBuffer::new();
        aer_pcc::console::race_startup(&mut log, &board::REVISION, board.reset_cause, board.board);

        let (rx_producer, rx_consumer) = cx.local.rx_queue.split();
        let [accumulator_vf, tractive_vf] = CONVERTERS;
        let shared = Shared {
            accumulator: VoltageChannel::new(accumulator_vf, TASK_PERIOD_MS),
            tractive: VoltageChannel::new(tractive_vf, TASK_PERIOD_MS),
            can,
            log,
        };
        if control::spawn().is_err() {
            halt_safe();
        }
        (
            shared,
            Local {
                vf: board.vf,
                relays,
                led: board.led,
                rx_producer,
                rx_consumer,
                wdog: board.wdog,
                watchdog_reset: reset_by_watchdog(board.reset_cause.0),
                race_log: RaceLog::default(),
                thermistors,
                console: board.console,
                typed: LineReader::new(),
            },
        )
    }

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
        #[task(binds = GPIO1_COMBINED_16_31, priority = 3, local = [vf],
               shared = [accumulator, tractive])]
        fn voltage_edge(cx: voltage_edge::Context);

        #[task(binds = CAN2, priority = 2, local = [rx_producer], shared = [can])]
        fn can_receive(cx: can_receive::Context);

        #[task(priority = 1, local = [relays, led, rx_consumer, wdog, watchdog_reset, race_log, thermistors],
               shared = [accumulator, tractive, can, log])]
        async fn control(cx: control::Context);
    }
}
