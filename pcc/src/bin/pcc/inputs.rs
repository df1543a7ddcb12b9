//! The interrupts that take inputs in: the V/F converters' edges and the CAN receive FIFO.

use crate::app::{can_receive, voltage_edge};
use crate::{Mono, RX_QUEUE_OVERFLOWS};
use core::sync::atomic::Ordering;
use rtic::Mutex;
use rtic_monotonics::imxrt::prelude::*;

/// Time-stamps the edge of whichever converter rose. The 64-bit tick count wraps the 32-bit
/// stamps every 71 minutes; the library only uses differences.
pub(crate) fn voltage_edge(mut cx: voltage_edge::Context) {
    let now = Mono::now().as_ticks() as u32;
    let [accumulator, tractive] = cx.local.vf;
    if accumulator.is_triggered() {
        accumulator.clear_triggered();
        cx.shared.accumulator.lock(|channel| channel.on_edge(now));
    }
    if tractive.is_triggered() {
        tractive.clear_triggered();
        cx.shared.tractive.lock(|channel| channel.on_edge(now));
    }
}

/// Drains the FIFO into the control task's queue; a full queue drops the frame and counts it.
pub(crate) fn can_receive(mut cx: can_receive::Context) {
    cx.shared.can.lock(|can| {
        while let Some(frame) = can.receive() {
            if cx.local.rx_producer.enqueue(frame).is_err() {
                RX_QUEUE_OVERFLOWS.fetch_add(1, Ordering::Relaxed);
            }
        }
    });
}
