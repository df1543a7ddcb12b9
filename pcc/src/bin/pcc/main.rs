//! PCC firmware for the Teensy 4.0 (RTIC 2).
//!
//! Tasks, highest priority first:
//! - `voltage_edge` (GPIO1 interrupt, priority 3): time-stamps the V/F converters' edges.
//! - `can_receive` (CAN2 interrupt, priority 2): drains the FlexCAN RX FIFO into a bounded
//!   queue; a full queue drops the frame and counts it.
//! - `control` (every 10 ms, priority 1): samples the voltages, feeds BMS frames to the link
//!   monitor, steps the state machine, applies the relays in the same period, and sends the
//!   status frame 0x222.
//!
//! All decisions are in the `aer_pcc` library; this file only moves data between it and the
//! hardware. At reset every relay output is low (open) until the first control step.
#![no_std]
#![no_main]

mod board;

use teensy4_panic as _;

#[rtic::app(device = teensy4_bsp, peripherals = true, dispatchers = [KPP])]
mod app {
    use crate::board;
    use aer_flexcan::{CanFrame, Flexcan};
    use aer_pcc::{
        Inputs, Precharge, PrechargeConfig, Relays, TASK_PERIOD_MS, VfConfig, bms::BmsLink,
        measurement::VoltageChannel,
    };
    use core::sync::atomic::{AtomicU32, Ordering};
    use heapless::spsc::{Consumer, Producer, Queue};
    use rtic_monotonics::imxrt::prelude::*;
    use teensy4_bsp::{
        board as bsp,
        hal::{self, gpio},
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

    /// The relay driver outputs.
    pub struct RelayPins {
        air_plus: gpio::Output,
        air_minus: gpio::Output,
        precharge: gpio::Output,
        shutdown: gpio::Output,
    }

    impl RelayPins {
        fn apply(&mut self, relays: Relays) {
            set(&self.air_plus, relays.air_plus);
            set(&self.air_minus, relays.air_minus);
            set(&self.precharge, relays.precharge);
            set(&self.shutdown, relays.shutdown);
        }
    }

    fn set(pin: &gpio::Output, high: bool) {
        if high { pin.set() } else { pin.clear() }
    }

    #[shared]
    struct Shared {
        accumulator: VoltageChannel,
        tractive: VoltageChannel,
        can: Flexcan<{ board::CAN_INSTANCE }>,
    }

    #[local]
    struct Local {
        accumulator_edges: gpio::Input,
        tractive_edges: gpio::Input,
        shutdown_in: gpio::Input,
        relays: RelayPins,
        rx_producer: Producer<'static, CanFrame>,
        rx_consumer: Consumer<'static, CanFrame>,
    }

    #[init(local = [rx_queue: Queue<CanFrame, RX_QUEUE> = Queue::new()])]
    fn init(cx: init::Context) -> (Shared, Local) {
        let bsp::Resources {
            pins,
            mut gpio1,
            mut gpio2,
            mut gpio4,
            mut gpt1,
            ccm,
            ..
        } = bsp::t40(cx.device);
        let pins = board::pins(pins);

        // Relays first, driven open, before anything else can run. A pin on the wrong port
        // is a build-time mistake in board.rs; the outputs then stay unconfigured (high-Z,
        // relays open) and the PCC halts.
        let (Ok(air_plus), Ok(air_minus), Ok(precharge), Ok(shutdown)) = (
            gpio4.output(pins.air_plus),
            gpio4.output(pins.air_minus),
            gpio4.output(pins.precharge),
            gpio2.output(pins.shutdown_control),
        ) else {
            halt_safe()
        };
        let mut relays = RelayPins {
            air_plus,
            air_minus,
            precharge,
            shutdown,
        };
        relays.apply(Relays::ALL_OPEN);
        let Ok(shutdown_in) = gpio2.input(pins.shutdown_in) else {
            halt_safe()
        };

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

        // SAFETY: the BSP does not hand out the FlexCAN instances; nothing else uses CAN2.
        let can_regs = unsafe { ral::can::CAN2::instance() };
        let mut can =
            match Flexcan::new(can_regs, pins.can_tx, pins.can_rx, &ccm, board::CAN_BITRATE) {
                Ok(can) => can,
                // The relays are open; without CAN the PCC cannot see the BMS, so it stays here.
                Err(_) => halt_safe(),
            };
        can.enable_rx_interrupt();

        let (rx_producer, rx_consumer) = cx.local.rx_queue.split();
        let vf = VfConfig::PCC_BOARD;
        let shared = Shared {
            accumulator: VoltageChannel::new(vf, TASK_PERIOD_MS),
            tractive: VoltageChannel::new(vf, TASK_PERIOD_MS),
            can,
        };
        if control::spawn().is_err() {
            halt_safe();
        }
        (
            shared,
            Local {
                accumulator_edges,
                tractive_edges,
                shutdown_in,
                relays,
                rx_producer,
                rx_consumer,
            },
        )
    }

    /// Parks the core with every relay output low. Only reachable at start-up.
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

    #[task(priority = 1, local = [relays, shutdown_in, rx_consumer],
           shared = [accumulator, tractive, can])]
    async fn control(mut cx: control::Context) {
        let start = Mono::now();
        let mut pcc = Precharge::new(PrechargeConfig::CAR, (start.as_ticks() / 1_000) as u32);
        let mut bms = BmsLink::default();
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
                shutdown_open: cx.local.shutdown_in.is_set(),
                bms_last_seen_ms: bms.last_seen_ms(),
                charger_safety: bms.charger_safety(),
            };
            let relays = pcc.step(&inputs);
            cx.local.relays.apply(relays);

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
            Mono::delay_until(next).await;
        }
    }
}
