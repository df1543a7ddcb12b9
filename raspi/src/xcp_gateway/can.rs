//! The gateway's CAN side on SocketCAN: its own raw socket on the slave's interface, which
//! receives only the slave's id (XCP_Res) and sends the master's (XCP_Cmd). Ingest's sockets
//! see both directions on the bus (the kernel loops sent frames back to other sockets), so
//! the store keeps the calibration traffic. A socket that fails (the interface went away) is
//! opened again every second until it works. The task ends when the gateway does (its
//! command queue closes), after writing what the gateway queued last: the DISCONNECT that
//! ends a master's session when the service stops.

use super::{SlaveLink, TO_SLAVE_FRAMES};
use aer::calibration::xcp::{CAN_ID_MASTER, CAN_ID_SLAVE};
use aer_xcp::transport::CAN_DLC;
use socketcan::{CanFilter, EmbeddedFrame, SocketOptions, StandardId};
use std::time::Duration;
use tokio::sync::mpsc;
use tracing::{info, warn};

const REOPEN_EVERY: Duration = Duration::from_secs(1);

/// Starts the task that moves frames between `interface` and the gateway. Fails if the
/// interface cannot be opened now (a wrong name in the configuration).
pub fn open(interface: &str) -> std::io::Result<SlaveLink> {
    let first = open_socket(interface)?;
    let (to_slave, mut commands) = mpsc::channel::<[u8; CAN_DLC]>(TO_SLAVE_FRAMES);
    let (answers, from_slave) = mpsc::channel::<Vec<u8>>(TO_SLAVE_FRAMES);
    let name = interface.to_owned();
    tokio::spawn(async move {
        let mut socket = Some(first);
        loop {
            let Some(open) = socket.take() else {
                tokio::select! {
                    // Commands while the bus is away are lost (the gateway hears no answer).
                    command = commands.recv() => if command.is_none() { return },
                    () = tokio::time::sleep(REOPEN_EVERY) => {}
                }
                socket = open_socket(&name).ok();
                if socket.is_some() {
                    info!(interface = %name, "XCP gateway: the bus is back");
                }
                continue;
            };
            match serve(&open, &mut commands, &answers).await {
                Ok(()) => return,
                Err(err) => {
                    warn!(interface = %name, error = %err, "XCP gateway: the bus failed; opening it again");
                }
            }
        }
    });
    Ok(SlaveLink {
        to_slave,
        from_slave,
    })
}

fn open_socket(interface: &str) -> std::io::Result<socketcan::tokio::CanSocket> {
    use socketcan::id::{CAN_EFF_FLAG, CAN_RTR_FLAG, CAN_SFF_MASK};
    let socket = socketcan::tokio::CanSocket::open(interface)?;
    // Standard data frames with exactly the slave's id: an extended or remote frame is not
    // the slave's.
    let mask = CAN_SFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG;
    socket.set_filters(&[CanFilter::new(CAN_ID_SLAVE, mask)])?;
    Ok(socket)
}

/// Moves frames until the socket fails (`Err`) or the gateway ends (`Ok`).
async fn serve(
    socket: &socketcan::tokio::CanSocket,
    commands: &mut mpsc::Receiver<[u8; CAN_DLC]>,
    answers: &mpsc::Sender<Vec<u8>>,
) -> std::io::Result<()> {
    let command_id = u16::try_from(CAN_ID_MASTER)
        .ok()
        .and_then(StandardId::new)
        .ok_or_else(|| std::io::Error::other("XCP_Cmd's id is not a standard id"))?;
    loop {
        tokio::select! {
            read = socket.read_frame() => {
                if let socketcan::CanFrame::Data(frame) = read?
                    && answers.send(frame.data().to_vec()).await.is_err()
                {
                    return Ok(());
                }
            }
            command = commands.recv() => {
                let Some(data) = command else { return Ok(()) };
                if let Some(frame) = socketcan::CanFrame::new(command_id, &data) {
                    socket.write_frame(frame).await?;
                }
            }
        }
    }
}
