//! How XCP packets reach the master: XCP on TCP (one connection at a time, the master
//! reconnects after the CCM restarts) or XCP on CAN (a SocketCAN interface, the DBC's
//! XCP_Cmd/XCP_Res ids, every frame 8 bytes). Both wait at most about a millisecond for a
//! command, so the caller's loop also serves its other inputs.

use aer_xcp::transport::{TCP_FRAME_MAX, TcpDecoder, TcpEncoder};
use anyhow::{Context, Result, bail};
use std::collections::VecDeque;
use std::io::{ErrorKind, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::time::Duration;

/// How long one [`Link::receive`] may wait for a command.
const POLL: Duration = Duration::from_millis(1);

/// A transport between the CCM's slave and one master.
pub trait Link {
    /// The next command packet from the master, if one arrives within about a millisecond.
    fn receive(&mut self) -> Result<Option<Vec<u8>>>;
    /// Sends a response or DTO; false if it could not be delivered (no master, or the link
    /// refused it).
    fn send(&mut self, packet: &[u8]) -> bool;
    /// Waits until a master can talk to the slave: TCP accepts its connection (checking
    /// `still_waiting` between attempts, which ends the wait with its error); CAN has nothing
    /// to wait for.
    fn await_master(&mut self, still_waiting: &mut dyn FnMut() -> Result<()>) -> Result<()>;
    /// Forgets the master (the CCM power-cycles: a TCP master must reconnect).
    fn drop_master(&mut self);
    /// Whether the master's transport ended (its TCP connection closed or broke) since the
    /// last call: the slave's session must end with it.
    fn take_lost(&mut self) -> bool;
    /// Packets received that were not XCP (a broken TCP frame, a CAN frame of the wrong
    /// length), all ignored so far.
    fn malformed(&self) -> u64;
    /// What a pyxcp script needs to reach this link, as the scenario script's environment.
    fn script_env(&self) -> Vec<(String, String)>;
    /// Where a master finds the slave, for people.
    fn describe(&self) -> String;
}

/// A TCP stream's frame that cannot be decoded: the stream cannot be resynchronised.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Malformed;

/// Decodes the XCP-on-TCP frames in `input` (continuing what `decoder` holds) and hands each
/// packet to `packet`; stops at the first broken frame.
pub fn decode_stream(
    decoder: &mut TcpDecoder,
    mut input: &[u8],
    mut packet: impl FnMut(Vec<u8>),
) -> Result<(), Malformed> {
    while !input.is_empty() {
        let (used, decoded) = decoder.decode(input);
        input = input.get(used..).unwrap_or_default();
        match decoded {
            Some(Ok(decoded)) => packet(decoded.data.to_vec()),
            Some(Err(_)) => return Err(Malformed),
            None => {}
        }
        if used == 0 {
            break;
        }
    }
    Ok(())
}

/// XCP on TCP: a listener and at most one connected master.
pub struct TcpLink {
    listener: TcpListener,
    address: SocketAddr,
    stream: Option<TcpStream>,
    decoder: TcpDecoder,
    encoder: TcpEncoder,
    /// Packets decoded but not yet handed out (one read may carry several).
    pending: VecDeque<Vec<u8>>,
    /// Malformed TCP frames received (the connection is closed on each).
    malformed: u64,
    /// The master's connection ended since [`Link::take_lost`] last said so.
    lost: bool,
}

impl TcpLink {
    /// Listens on `address` (port 0: any free port).
    pub fn bind(address: SocketAddr) -> Result<Self> {
        let listener =
            TcpListener::bind(address).with_context(|| format!("listening on {address}"))?;
        let address = listener.local_addr()?;
        listener.set_nonblocking(true)?;
        Ok(Self {
            listener,
            address,
            stream: None,
            decoder: TcpDecoder::new(),
            encoder: TcpEncoder::new(),
            pending: VecDeque::new(),
            malformed: 0,
            lost: false,
        })
    }

    /// The address it listens on.
    pub fn address(&self) -> SocketAddr {
        self.address
    }

    /// The master's connection ended (closed, broken or malformed).
    fn lost(&mut self) {
        self.stream = None;
        self.lost = true;
    }

    /// Takes a waiting connection, if any (a new master replaces the old one).
    fn try_accept(&mut self) -> Result<bool> {
        match self.listener.accept() {
            Ok((stream, _)) => {
                stream.set_read_timeout(Some(POLL))?;
                stream.set_nodelay(true)?;
                self.stream = Some(stream);
                self.decoder.reset();
                self.encoder = TcpEncoder::new();
                self.pending.clear();
                Ok(true)
            }
            Err(error) if error.kind() == ErrorKind::WouldBlock => Ok(false),
            Err(error) => Err(error).context("accepting a master"),
        }
    }
}

impl Link for TcpLink {
    fn receive(&mut self) -> Result<Option<Vec<u8>>> {
        if let Some(packet) = self.pending.pop_front() {
            return Ok(Some(packet));
        }
        if self.stream.is_none() && !self.try_accept()? {
            std::thread::sleep(POLL);
            return Ok(None);
        }
        let Some(stream) = self.stream.as_mut() else {
            return Ok(None);
        };
        let mut buffer = [0u8; 512];
        let read = match stream.read(&mut buffer) {
            Ok(0) => {
                self.lost();
                return Ok(None);
            }
            Ok(read) => read,
            Err(error) if matches!(error.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {
                return Ok(None);
            }
            Err(_) => {
                self.lost();
                return Ok(None);
            }
        };
        let pending = &mut self.pending;
        let decoded = decode_stream(
            &mut self.decoder,
            buffer.get(..read).unwrap_or_default(),
            |packet| pending.push_back(packet),
        );
        if decoded.is_err() {
            // A broken stream cannot be resynchronised: drop the master, as a slave on the car
            // would.
            self.malformed += 1;
            self.lost();
        }
        Ok(self.pending.pop_front())
    }

    fn send(&mut self, packet: &[u8]) -> bool {
        let Some(stream) = self.stream.as_mut() else {
            return false;
        };
        let mut frame = [0u8; TCP_FRAME_MAX];
        let Ok(len) = self.encoder.encode(packet, &mut frame) else {
            return false;
        };
        stream
            .write_all(frame.get(..len).unwrap_or_default())
            .is_ok()
    }

    fn await_master(&mut self, still_waiting: &mut dyn FnMut() -> Result<()>) -> Result<()> {
        while !self.try_accept()? {
            still_waiting()?;
            // Waiting for a connection, not for time: the loop ends on an event.
            std::thread::sleep(POLL);
        }
        Ok(())
    }

    fn drop_master(&mut self) {
        self.stream = None;
        self.pending.clear();
        self.lost = false;
    }

    fn take_lost(&mut self) -> bool {
        std::mem::take(&mut self.lost)
    }

    fn malformed(&self) -> u64 {
        self.malformed
    }

    fn script_env(&self) -> Vec<(String, String)> {
        vec![
            ("AER_XCP_TRANSPORT".into(), "tcp".into()),
            ("AER_XCP_HOST".into(), self.address.ip().to_string()),
            ("AER_XCP_PORT".into(), self.address.port().to_string()),
        ]
    }

    fn describe(&self) -> String {
        format!("XCP on TCP at {}", self.address)
    }
}

/// XCP on CAN on a SocketCAN interface.
#[cfg(target_os = "linux")]
pub struct CanLink {
    socket: socketcan::CanSocket,
    interface: String,
    /// Frames on the command id that are not 8 bytes (the DBC's XCP_Cmd is), ignored.
    malformed: u64,
}

#[cfg(target_os = "linux")]
impl CanLink {
    /// Opens `interface`, receiving only the master's command id.
    pub fn open(interface: &str) -> Result<Self> {
        use aer::calibration::xcp::CAN_ID_MASTER;
        use socketcan::{CanFilter, Socket, SocketOptions};
        let socket = socketcan::CanSocket::open(interface)
            .with_context(|| format!("opening the CAN interface {interface}"))?;
        use socketcan::id::{CAN_EFF_FLAG, CAN_RTR_FLAG, CAN_SFF_MASK};
        // Standard data frames with exactly that id: an extended or remote frame is not ours.
        let mask = CAN_SFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG;
        socket.set_filters(&[CanFilter::new(CAN_ID_MASTER, mask)])?;
        Ok(Self {
            socket,
            interface: interface.to_owned(),
            malformed: 0,
        })
    }
}

#[cfg(target_os = "linux")]
impl Link for CanLink {
    fn receive(&mut self) -> Result<Option<Vec<u8>>> {
        use aer_xcp::transport::CAN_DLC;
        use socketcan::{EmbeddedFrame, Socket};
        match self.socket.read_frame_timeout(POLL) {
            Ok(socketcan::CanFrame::Data(frame)) if frame.data().len() == CAN_DLC => {
                Ok(Some(frame.data().to_vec()))
            }
            Ok(_) => {
                self.malformed += 1;
                Ok(None)
            }
            Err(error) if matches!(error.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {
                Ok(None)
            }
            Err(error) => Err(error).with_context(|| format!("reading {}", self.interface)),
        }
    }

    fn send(&mut self, packet: &[u8]) -> bool {
        use aer::calibration::xcp::CAN_ID_SLAVE;
        use aer_xcp::transport::can_frame;
        use socketcan::{EmbeddedFrame, Socket, StandardId};
        let (Some(data), Some(id)) = (can_frame(packet), StandardId::new(CAN_ID_SLAVE as u16))
        else {
            return false;
        };
        let Some(frame) = socketcan::CanFrame::new(id, &data) else {
            return false;
        };
        self.socket.write_frame_insist(&frame).is_ok()
    }

    fn await_master(&mut self, _still_waiting: &mut dyn FnMut() -> Result<()>) -> Result<()> {
        Ok(())
    }

    fn drop_master(&mut self) {}

    fn take_lost(&mut self) -> bool {
        false
    }

    fn malformed(&self) -> u64 {
        self.malformed
    }

    fn script_env(&self) -> Vec<(String, String)> {
        use aer::calibration::xcp::{BIT_RATE, CAN_ID_MASTER, CAN_ID_SLAVE};
        vec![
            ("AER_XCP_TRANSPORT".into(), "can".into()),
            ("AER_XCP_CAN_CHANNEL".into(), self.interface.clone()),
            ("AER_XCP_CAN_ID_MASTER".into(), CAN_ID_MASTER.to_string()),
            ("AER_XCP_CAN_ID_SLAVE".into(), CAN_ID_SLAVE.to_string()),
            ("AER_XCP_CAN_BIT_RATE".into(), BIT_RATE.to_string()),
        ]
    }

    fn describe(&self) -> String {
        use aer::calibration::xcp::{CAN_ID_MASTER, CAN_ID_SLAVE};
        format!(
            "XCP on CAN on {}, commands {CAN_ID_MASTER:#x}, responses {CAN_ID_SLAVE:#x}",
            self.interface
        )
    }
}

/// Opens the link a command line names: `tcp:ADDRESS` or `can:INTERFACE`.
pub fn open(spec: &str) -> Result<Box<dyn Link>> {
    if let Some(address) = spec.strip_prefix("tcp:") {
        let address: SocketAddr = address
            .parse()
            .with_context(|| format!("{address:?} is not an address such as 127.0.0.1:5555"))?;
        return Ok(Box::new(TcpLink::bind(address)?));
    }
    if let Some(interface) = spec.strip_prefix("can:") {
        #[cfg(target_os = "linux")]
        return Ok(Box::new(CanLink::open(interface)?));
        #[cfg(not(target_os = "linux"))]
        bail!("XCP on CAN needs Linux's SocketCAN ({interface})");
    }
    bail!("{spec:?}: expected tcp:ADDRESS or can:INTERFACE")
}
