//! The 100 Hz control task: CAN intake, bus health, the library's control step, the outputs,
//! the frames the library's schedule says are due, the console's log lines and the handover
//! to the bootloader or a restart.

use crate::app::control;
use crate::{Mono, PEDAL_BUS_ERRORS, REBOOT, RX_QUEUE_OVERFLOWS, STATUS, TX_NOT_SENT, WHEELS};
use crate::{now_ms, now_us};
use aer_boards::assumed::Board as AssumedBoard;
use aer_ccm::console::{FaultNames, LOG_BYTES, PccLine, RebootAnswer, StatusLine};
use aer_ccm::constants::{CONTROL_PERIOD_MS, PCC_STATUS_TIMEOUT_MS, WHEEL_TEETH};
use aer_ccm::faults::FaultMap;
use aer_ccm::own_frames::OwnFrames;
use aer_ccm::stop::STOP;
use aer_ccm::watchdog::Task;
use aer_ccm::{BusHealth, ControlOutputs, DriverCounters, DriverInputs, OutFrames};
use aer_console::bringup::write_assumed;
use aer_console::{LogBuffer, Reboot, Watch};
use aer_flexcan::{BusStatus, CanFrame, FaultState, Flexcan};
use core::sync::atomic::Ordering;
use embedded_can::{ExtendedId, Frame, Id, StandardId};
use rtic::Mutex;
use rtic_monotonics::imxrt::prelude::*;
use teensy4_bsp::hal::flexpwm::Channel;

pub(crate) async fn control(mut cx: control::Context<'_>) {
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
        let calibration = cx
            .shared
            .calibration
            .lock(|calibration| *calibration.active());
        let [left, right] = &WHEELS;
        let wheels = [left.speed(WHEEL_TEETH), right.speed(WHEEL_TEETH)];
        let (outputs, due, handover, pcc) = cx.shared.control.lock(|control| {
            control.set_driver_counters(counters);
            while let Some(frame) = vehicle_frames.dequeue() {
                control.on_frame(&frame, now);
            }
            while let Some(frame) = inverter_frames.dequeue() {
                control.on_frame(&frame, now);
            }
            let outputs = control.step(&calibration, &sensors, wheels, driver, now, now_micros);
            let due = control.due(step);
            // What a panic would send from now on.
            match control.stop_frames() {
                Ok(frames) => STOP.publish(&frames),
                Err(_) => {
                    TX_NOT_SENT.fetch_add(1, Ordering::Relaxed);
                }
            }
            let handover = REBOOT.take().map(|reboot| (reboot, control.handover()));
            let pcc = control.bus().pcc.fresh(now, PCC_STATUS_TIMEOUT_MS);
            (outputs, due, handover, PccLine(pcc))
        });
        let watches = &mut cx.local.watches;
        let status = STATUS.take();
        cx.shared.log.lock(|log| {
            watches.log_changes(
                log,
                now,
                &outputs,
                &counters,
                [vehicle_bus.state, inverter_bus.state],
                pcc,
            );
            if status {
                let line = StatusLine {
                    now_ms: now,
                    state: outputs.vehicle.state,
                    faults: outputs.faults,
                    pcc,
                };
                log.line(format_args!("{line}"));
                write_assumed(log, AssumedBoard::Ccm);
            }
        });
        if outputs.brake_light {
            cx.local.brake_light.set();
        } else {
            cx.local.brake_light.clear();
        }
        // Both pumps run together; the fan is FlexPWM1 SM3's B output.
        cx.local.pumps.set_duty(Channel::A, outputs.cooling.pump);
        cx.local.pumps.set_duty(Channel::B, outputs.cooling.pump);
        cx.local.fan.set_duty(Channel::B, outputs.cooling.fan);
        if now % 1_000 < CONTROL_PERIOD_MS {
            cx.local.led.toggle();
        }
        cx.local.buzzer.set_duty(
            Channel::A,
            if outputs.vehicle.rtd_sound { 0.5 } else { 0.0 },
        );

        match due.inverter {
            // A torque command never waits behind an older one: it replaces it.
            Some(Ok(frames)) => send_inverter(&mut cx.shared.inverter_can, &frames),
            Some(Err(_)) => {
                TX_NOT_SENT.fetch_add(1, Ordering::Relaxed);
            }
            None => {}
        }
        // The CCM's own messages, on the buses the schema names (the car model sends the same).
        let calibration = due.calibration.then(|| {
            cx.shared
                .calibration
                .lock(|calibration| calibration.status())
        });
        let own = OwnFrames::of(&due, calibration);
        TX_NOT_SENT.fetch_add(own.not_encoded, Ordering::Relaxed);
        for own in own.iter() {
            let frame = &own.frame;
            if own.buses.vehicle {
                send(
                    &mut cx.shared.vehicle_can,
                    frame.id,
                    frame.extended,
                    frame.data(),
                    Queueing::Behind,
                );
            }
            if own.buses.inverter {
                send(
                    &mut cx.shared.inverter_can,
                    frame.id,
                    frame.extended,
                    frame.data(),
                    Queueing::Behind,
                );
            }
        }
        if let Some((reboot, handover)) = handover {
            let outcome = handover.map(|frames| {
                send_inverter(&mut cx.shared.inverter_can, &frames);
                cx.local.brake_light.clear();
                cx.local.pumps.set_duty(Channel::A, 0.0);
                cx.local.pumps.set_duty(Channel::B, 0.0);
                cx.local.fan.set_duty(Channel::B, 0.0);
                cx.local.buzzer.set_duty(Channel::A, 0.0);
            });
            let answer = RebootAnswer { reboot, outcome };
            cx.shared
                .log
                .lock(|log| log.line(format_args!("t={now} ms {answer}")));
            if outcome.is_ok() {
                // Two frame times at 500 kbit/s for the safe commands to leave the mailboxes.
                Mono::delay(2u64.millis()).await;
                match reboot {
                    Reboot::Bootloader => aer_console::usb::reboot_to_bootloader(),
                    Reboot::Restart => aer_console::usb::restart(),
                }
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

/// What the control task logs when it changes.
#[derive(Default)]
pub(crate) struct Watches {
    state: Watch<aer_ccm::vehicle::State>,
    faults: Watch<FaultMap>,
    buses: Watch<[FaultState; 2]>,
    pcc: Watch<Option<(aer::can::PrechargeState, u16)>>,
}

impl Watches {
    /// Logs what changed this control step: the vehicle state, the PCC's state and latched
    /// causes, the fault map, either bus's fault confinement state; every 5 s the drop
    /// counters.
    fn log_changes(
        &mut self,
        log: &mut LogBuffer<LOG_BYTES>,
        now: u32,
        outputs: &ControlOutputs,
        counters: &DriverCounters,
        buses: [FaultState; 2],
        pcc: PccLine,
    ) {
        if let Some(state) = self.state.changed(outputs.vehicle.state) {
            log.line(format_args!("t={now} ms vehicle {state:?}"));
        }
        if self.pcc.changed(pcc.key()).is_some() {
            log.line(format_args!("t={now} ms {pcc}"));
        }
        if let Some(faults) = self.faults.changed(outputs.faults) {
            log.line(format_args!(
                "t={now} ms faults {:#06x}:{}",
                faults.bits(),
                FaultNames(faults)
            ));
        }
        if let Some([vehicle, inverter]) = self.buses.changed(buses) {
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
}

fn health(status: &BusStatus) -> BusHealth {
    BusHealth {
        error_passive: status.state == FaultState::ErrorPassive,
        bus_off: status.state == FaultState::BusOff,
        bus_off_events: status.bus_off_events,
    }
}

/// How a frame is queued: behind a pending one with its identifier, or replacing it.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Queueing {
    Behind,
    Replacing,
}

/// The inverter's frames, each replacing a pending one with its identifier.
fn send_inverter(can: &mut impl Mutex<T = Flexcan<2>>, frames: &OutFrames) {
    for frame in frames.iter() {
        send(
            can,
            frame.id,
            frame.extended,
            frame.data(),
            Queueing::Replacing,
        );
    }
}

/// Queues one frame; one that cannot be built or finds every mailbox busy is counted.
fn send<const N: u8>(
    can: &mut impl Mutex<T = Flexcan<N>>,
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
