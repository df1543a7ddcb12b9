//! The 10 ms control task: voltages and BMS frames in, the state machine, the relays in the
//! same period, the status frame, the console's log lines, the watchdog's service and the
//! handover to the bootloader or a restart.

use crate::app::control;
use crate::{Mono, REBOOT, RX_QUEUE_OVERFLOWS, STATUS, STATUS_ENCODE_FAILURES, TX_BUSY};
use aer_console::Reboot;
use aer_flexcan::CanFrame;
use aer_pcc::console::{ConverterVolts, CountersLine, RaceLog, RebootAnswer, ResistorTemperature};
use aer_pcc::constants::THERMISTORS;
use aer_pcc::hw::{board, feed_watchdog};
use aer_pcc::watchdog::LoopMonitor;
use aer_pcc::{Inputs, Precharge, PrechargeConfig, Relays, TASK_PERIOD_MS, bms::BmsLink};
use core::sync::atomic::Ordering;
use rtic::Mutex;
use rtic_monotonics::imxrt::prelude::*;
use teensy4_bsp::hal::{adc, gpio};

/// PCC_Thermal's period (ms): the schema's cycle time.
const THERMAL_PERIOD_MS: u32 = aer::can::PccThermal::CYCLE_TIME_MS;

/// The precharge resistor's thermistors on the on-chip ADC (pins 21 and 22).
pub(crate) struct Thermistors {
    pub(crate) adc: adc::Adc,
    pub(crate) inputs: [adc::AnalogInput; 2],
}

impl Thermistors {
    /// Both temperatures (degC), `None` for a thermistor with no reading.
    fn read(&mut self) -> [Option<f32>; 2] {
        self.inputs
            .each_mut()
            .map(|input| THERMISTORS.temperature_c(self.adc.read_blocking(input)))
    }
}

/// The board's one relay output: pin 11, close AIR+.
pub(crate) struct RelayPins {
    air_plus: gpio::Output,
}

impl RelayPins {
    pub(crate) fn new(air_plus: gpio::Output) -> Self {
        Self { air_plus }
    }

    /// Drives the board's relay outputs (`Relays::outputs` over the board map: pin 11, the
    /// typed pin checked against it in `aer_pcc::hw::board`).
    pub(crate) fn apply(&mut self, relays: Relays) {
        let [(_pin_11, high)] = relays.outputs(&board::REVISION);
        if high {
            self.air_plus.set();
        } else {
            self.air_plus.clear();
        }
    }
}

pub(crate) async fn control(mut cx: control::Context<'_>) {
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
        let accumulator = cx.shared.accumulator.lock(|channel| channel.sample(now_us));
        let tractive = cx.shared.tractive.lock(|channel| channel.sample(now_us));
        let inputs = Inputs {
            now_ms,
            accumulator_v: accumulator.volts,
            tractive_v: tractive.volts,
            raw_v: [accumulator.raw_volts, tractive.raw_volts],
            pulses: [accumulator.pulses, tractive.pulses],
            bms_last_seen_ms: bms.last_seen_ms(),
            charger_safety: bms.charger_safety(),
            resistor_c: cx.local.thermistors.read(),
        };
        let relays = pcc.step(&inputs);
        cx.local.relays.apply(relays);
        if let Some(reboot) = REBOOT.take() {
            let allowed = match reboot {
                Reboot::Restart => pcc.restart(),
                Reboot::Bootloader => pcc.handover(),
            };
            let outcome = allowed.map(|safe| cx.local.relays.apply(safe));
            let answer = RebootAnswer { reboot, outcome };
            cx.shared
                .log
                .lock(|log| log.line(format_args!("t={now_ms} ms {answer}")));
            match (outcome, reboot) {
                (Ok(()), Reboot::Bootloader) => aer_console::usb::reboot_to_bootloader(),
                (Ok(()), Reboot::Restart) => aer_console::usb::restart(),
                (Err(_), _) => {}
            }
        }
        let race_log = &mut cx.local.race_log;
        let status = STATUS.take();
        cx.shared.log.lock(|log| {
            race_log.changes(now_ms, &pcc, relays, log);
            if status {
                race_log.status(now_ms, &pcc, relays, log);
            }
        });
        if RaceLog::counters_due(now_ms) {
            let bus = cx.shared.can.lock(|can| can.status());
            cx.shared.log.lock(|log| {
                let [accumulator, tractive] = ConverterVolts::of(&pcc);
                let line = CountersLine {
                    now_ms,
                    accumulator,
                    tractive,
                    resistor: pcc.resistor_c().map(ResistorTemperature),
                    bus,
                    rx_queue_overflows: RX_QUEUE_OVERFLOWS.load(Ordering::Relaxed),
                    status_not_sent: TX_BUSY.load(Ordering::Relaxed),
                    log_dropped: log.dropped(),
                };
                log.line(format_args!("{line}"))
            });
        }
        // Heartbeat: the LED toggles every second (0.5 Hz) while the loop runs, so a hung PCC
        // shows on the bench.
        if now_ms % 1_000 < TASK_PERIOD_MS {
            cx.local.led.toggle();
        }

        let thermal_due = now_ms % THERMAL_PERIOD_MS < TASK_PERIOD_MS;
        let frames = [
            Some(pcc.status_frame::<CanFrame>()),
            thermal_due.then(|| pcc.thermal_frame::<CanFrame>()),
        ];
        for frame in frames.into_iter().flatten() {
            match frame {
                Some(frame) => {
                    if cx.shared.can.lock(|can| can.transmit(&frame)).is_err() {
                        TX_BUSY.fetch_add(1, Ordering::Relaxed);
                    }
                }
                None => {
                    STATUS_ENCODE_FAILURES.fetch_add(1, Ordering::Relaxed);
                }
            }
        }
        if health.step_completed(Mono::now().as_ticks() as u32) {
            feed_watchdog(cx.local.wdog);
        }
        Mono::delay_until(next).await;
    }
}
