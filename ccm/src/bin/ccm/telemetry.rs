//! The telemetry packet: a snapshot every 10 ms, packed by the generated packer and sent as
//! ISO-TP on 0x666 on the vehicle bus, frame by frame as mailboxes free up.

use crate::app::telemetry;
use crate::xcp::send_dto;
use crate::{Mono, now_ms, now_us};
use aer::calibration::xcp::EVENT_CONTROL;
use aer::telemetry::Telemetry;
use aer_ccm::constants::TELEMETRY_PERIOD_MS;
use aer_ccm::watchdog::Task;
use aer_ccm::xcp::Measurements;
use aer_flexcan::CanFrame;
use embedded_can::{Frame, StandardId};
use rtic::Mutex;
use rtic::mutex_prelude::*;
use rtic_monotonics::imxrt::prelude::*;

pub(crate) async fn telemetry(mut cx: telemetry::Context<'_>) {
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
        // The control event: DAQ samples the packet just packed and the control step's
        // internals.
        let telemetry = cx.shared.link.lock(|link| *link.last_packet());
        let internals = cx
            .shared
            .control
            .lock(|control| control.internals())
            .to_bytes();
        (
            &mut cx.shared.xcp,
            &mut cx.shared.calibration,
            &mut cx.shared.inverter_can,
        )
            .lock(|node, calibration, can| {
                node.measurements = Measurements {
                    telemetry,
                    internals,
                };
                node.event(calibration, EVENT_CONTROL, started, &mut |dto| {
                    send_dto(can, dto)
                })
            });
        // Feed the ISO-TP frames out as mailboxes free up, until the packet is done or the
        // next snapshot is due (which then supersedes it, counted by the link).
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
