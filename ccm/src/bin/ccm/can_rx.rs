//! The receive interrupts: each drains its controller's FIFO into the control task's queue;
//! the Pi's ISO-TP flow control goes to the telemetry sender at once.

use crate::app::{inverter_receive, vehicle_receive};
use crate::{RX_QUEUE_OVERFLOWS, now_us};
use aer::can::XcpCmd;
use aer::telemetry::Telemetry;
use aer_ccm::telemetry::TelemetryLink;
use aer_flexcan::{CanFrame, Flexcan};
use core::sync::atomic::Ordering;
use embedded_can::{Frame, Id, StandardId};
use heapless::spsc::Producer;
use rtic::Mutex;

pub(crate) fn vehicle_receive(mut cx: vehicle_receive::Context) {
    let queue = cx.local.vehicle_rx;
    let link = &mut cx.shared.link;
    cx.shared
        .vehicle_can
        .lock(|can| drain(can, queue, None, link));
}

pub(crate) fn inverter_receive(mut cx: inverter_receive::Context) {
    let queue = cx.local.inverter_rx;
    let xcp = Some(&mut *cx.local.xcp_rx);
    let link = &mut cx.shared.link;
    cx.shared
        .inverter_can
        .lock(|can| drain(can, queue, xcp, link));
}

/// Drains a FIFO; a full queue drops the frame and counts it. XCP commands (inverter bus only)
/// go to the XCP task's queue.
fn drain<const N: u8>(
    can: &mut Flexcan<N>,
    queue: &mut Producer<'static, CanFrame>,
    mut xcp: Option<&mut Producer<'static, CanFrame>>,
    link: &mut impl Mutex<T = TelemetryLink>,
) {
    let flow_control = StandardId::new(Telemetry::FLOW_CONTROL_ID).map(Id::Standard);
    let xcp_command = StandardId::new(XcpCmd::ID as u16).map(Id::Standard);
    while let Some(frame) = can.receive() {
        if let (Some(xcp), true) = (xcp.as_deref_mut(), Some(frame.id()) == xcp_command) {
            if xcp.enqueue(frame).is_err() {
                RX_QUEUE_OVERFLOWS.fetch_add(1, Ordering::Relaxed);
            }
        } else if Some(frame.id()) == flow_control {
            let now = now_us();
            link.lock(|link| link.on_flow_control(frame.data(), now));
        } else if queue.enqueue(frame).is_err() {
            RX_QUEUE_OVERFLOWS.fetch_add(1, Ordering::Relaxed);
        }
    }
}
