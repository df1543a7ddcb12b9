//! The sensing tasks: front wheel-speed edges (interrupt) and the 1 kHz analog sampling.

use crate::app::{sensors, wheel_edge};
use crate::xcp::send_dto;
use crate::{Mono, PEDAL_BUS_ERRORS, WHEELS, now_ms, now_us};
use aer::calibration::xcp::EVENT_SENSORS;
use aer_ccm::SensorSample;
use aer_ccm::analog;
use aer_ccm::hw::{board, pedals};
use aer_ccm::watchdog::Task;
use core::sync::atomic::Ordering;
use rtic::Mutex;
use rtic::mutex_prelude::*;
use rtic_monotonics::imxrt::prelude::*;

/// Time-stamps the pulse of whichever wheel-speed input rose.
pub(crate) fn wheel_edge(cx: wheel_edge::Context) {
    let now = now_us();
    for (input, timer) in cx.local.wheels.iter_mut().zip(&WHEELS) {
        if input.is_triggered() {
            input.clear_triggered();
            timer.on_pulse(now);
        }
    }
}

/// Every millisecond: both pedal sensors, both brake sensors and the four shocks.
pub(crate) async fn sensors(mut cx: sensors::Context<'_>) {
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
        let (apps_v, pedal_bus_errors) = pedals::read(adc, cx.local.pedals);
        PEDAL_BUS_ERRORS.store(pedal_bus_errors, Ordering::Relaxed);
        let sample = SensorSample {
            apps_v,
            brake_v: (
                analog::sensor_volts(bse1, divider),
                analog::sensor_volts(bse2, divider),
            ),
            shock_raw: [s1, s2, s3, s4],
        };
        let now = now_ms();
        let calibration = cx
            .shared
            .calibration
            .lock(|calibration| *calibration.active());
        cx.shared
            .sensors
            .lock(|sensors| sensors.sample(&calibration, &sample, now));
        // The sensor event: DAQ lists on it sample the latest measurements every sample.
        let now_micros = now_us();
        (
            &mut cx.shared.xcp,
            &mut cx.shared.calibration,
            &mut cx.shared.inverter_can,
        )
            .lock(|node, calibration, can| {
                node.event(calibration, EVENT_SENSORS, now_micros, &mut |dto| {
                    send_dto(can, dto)
                })
            });
        cx.shared
            .supervisor
            .lock(|supervisor| supervisor.beat(Task::Sensors, now));
        Mono::delay_until(next).await;
    }
}
