//! The XCP slave on the inverter bus (where the Pi's gateway is too; the vehicle bus's room is
//! the telemetry's): commands from XCP_Cmd (0x6F0) answered on XCP_Res
//! (0x6F1), and the DAQ packets of the two event channels (sent by the sensor and telemetry
//! tasks through [`send_dto`]). The library's `XcpNode` does the protocol, checks every
//! calibration change and ends idle sessions; this file only moves frames and runs its clock.

use crate::app::xcp;
use crate::{Mono, TX_NOT_SENT, now_us};
use aer::can::XcpRes;
use aer_flexcan::{CanFrame, Flexcan};
use aer_xcp::MAX_CTO;
use aer_xcp::transport::can_frame;
use core::sync::atomic::Ordering;
use embedded_can::{Frame, StandardId};
use rtic::Mutex;
use rtic::mutex_prelude::*;
use rtic_monotonics::imxrt::prelude::*;

/// How often the task looks for commands: a master waits at most this long for an answer
/// beyond the bus (its timeout T1 is 2 s).
const POLL_MS: u64 = 1;

/// Answers every command the receive interrupt queued.
pub(crate) async fn xcp(mut cx: xcp::Context<'_>) {
    loop {
        while let Some(frame) = cx.local.xcp_commands.dequeue() {
            let vehicle = cx.shared.control.lock(|control| control.vehicle_state());
            let now = now_us();
            let mut reply = [0u8; MAX_CTO];
            let answer =
                (&mut cx.shared.xcp, &mut cx.shared.calibration).lock(|node, calibration| {
                    node.command(calibration, vehicle, frame.data(), now, &mut reply)
                });
            if let Some(len) = answer {
                let sent = cx
                    .shared
                    .inverter_can
                    .lock(|can| send_dto(can, reply.get(..len).unwrap_or(&[])));
                if !sent {
                    TX_NOT_SENT.fetch_add(1, Ordering::Relaxed);
                }
            }
        }
        // The slave's clock: a session idle past its time-out ends (the event goes out
        // on XCP_Res like any packet).
        let now = now_us();
        (
            &mut cx.shared.xcp,
            &mut cx.shared.calibration,
            &mut cx.shared.inverter_can,
        )
            .lock(|node, calibration, can| {
                node.poll(calibration, now, &mut |packet| send_dto(can, packet))
            });
        Mono::delay(POLL_MS.millis()).await;
    }
}

/// Puts one XCP packet on the inverter bus as XCP_Res, padded to 8 bytes; false if no mailbox
/// took it (the slave counts a DAQ packet so lost).
pub(crate) fn send_dto(can: &mut Flexcan<2>, packet: &[u8]) -> bool {
    let Some(data) = can_frame(packet) else {
        return false;
    };
    StandardId::new(XcpRes::ID as u16)
        .and_then(|id| CanFrame::new(id, &data))
        .is_some_and(|frame| can.transmit(&frame).is_ok())
}
