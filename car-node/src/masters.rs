//! The desk car's transports, each on its own threads so that no master can hold up the
//! model: a TCP listener that takes any number of connections (each read by one thread and
//! written by another through a bounded queue), or a SocketCAN interface (the bus is one
//! client). Everything a master sends arrives on one bounded channel as [`Inbound`]; the model
//! thread answers through each client's [`Outbox`], which never blocks: a full outbox means
//! the master stopped reading.

use crate::link::decode_stream;
use aer_xcp::transport::{TCP_FRAME_MAX, TcpDecoder, TcpEncoder};
use anyhow::{Context, Result};
use std::io::{ErrorKind, Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::thread::JoinHandle;
use std::time::Duration;

/// Packets waiting for one client's writer: about 4 s of DAQ at the slave's frame budget.
/// A master that lets this many pile up has stopped reading.
pub const OUTBOX_LEN: usize = 1_024;
/// Events waiting for the model thread: a flooding master's reader waits (TCP pushes back)
/// once this many are queued.
pub const INBOUND_LEN: usize = 256;
/// TCP clients served at once; one more is closed as it connects (each costs two threads).
pub const MAX_CLIENTS: usize = 32;
/// Bytes the kernel may hold for one client's connection beyond its outbox.
const SEND_BUFFER: usize = 16 * 1024;
/// How often threads that wait for something else look at the stop flag.
const STOP_POLL: Duration = Duration::from_millis(20);

/// A client's number, unique for the server's life.
pub type ClientId = u64;

/// What the transports tell the model thread.
pub enum Inbound {
    /// A client connected (TCP) or the bus opened (CAN).
    Opened {
        /// Which.
        client: ClientId,
        /// Where it is, for people.
        peer: String,
        /// Its answers go here.
        outbox: Outbox,
    },
    /// A command packet.
    Packet {
        /// From whom.
        client: ClientId,
        /// The packet (CTO).
        packet: Vec<u8>,
    },
    /// A frame on the bus that is not XCP (the wrong length), ignored.
    Malformed,
    /// The client's transport ended: it closed, broke, or sent a frame that cannot be
    /// decoded (`malformed`).
    Closed {
        /// Which.
        client: ClientId,
        /// A broken frame ended it.
        malformed: bool,
    },
}

/// Why a packet did not go out.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NotSent {
    /// The client's queue is full: it stopped reading.
    Full,
    /// The client is gone.
    Gone,
}

/// One client's way out: a bounded queue to its writer, and a way to end its transport.
pub struct Outbox {
    queue: SyncSender<Vec<u8>>,
    close: Box<dyn Fn() + Send>,
    /// The transport outlives any session on it (a CAN bus): ending a session keeps it.
    lasting: bool,
}

impl Outbox {
    /// An outbox over `queue` (its receiver is the client's writer) that ends the client's
    /// transport with `close`: for a transport of the caller's own (a test's channels).
    pub fn new(queue: SyncSender<Vec<u8>>, close: Box<dyn Fn() + Send>) -> Self {
        Self {
            queue,
            close,
            lasting: false,
        }
    }

    /// An outbox over a transport that outlives its sessions (a bus of the caller's own).
    pub fn lasting(queue: SyncSender<Vec<u8>>, close: Box<dyn Fn() + Send>) -> Self {
        Self {
            queue,
            close,
            lasting: true,
        }
    }

    /// Whether the transport outlives the sessions on it (a CAN bus, where any node may be
    /// the next master): the desk ends a session there but keeps listening.
    pub fn is_lasting(&self) -> bool {
        self.lasting
    }

    /// Queues `packet` without waiting.
    pub fn send(&self, packet: &[u8]) -> Result<(), NotSent> {
        match self.queue.try_send(packet.to_vec()) {
            Ok(()) => Ok(()),
            Err(TrySendError::Full(_)) => Err(NotSent::Full),
            Err(TrySendError::Disconnected(_)) => Err(NotSent::Gone),
        }
    }

    /// Ends the client's transport now, whatever is still queued (a TCP connection is shut
    /// down; its threads end).
    pub fn close(&self) {
        (self.close)();
    }

    /// Ends the client's transport once what is queued has gone out (a last answer, the
    /// event that ends a session).
    pub fn finish(self) {
        // The writer sends what is queued, finds the queue closed and shuts the connection.
        drop(self);
    }
}

/// The running transport: its threads stop when it is dropped.
pub struct Transport {
    /// Events from every client.
    pub inbound: Receiver<Inbound>,
    /// Where masters reach it, for people.
    pub describe: String,
    stop: Arc<AtomicBool>,
    threads: Vec<JoinHandle<()>>,
}

impl Transport {
    /// A transport whose events the caller sends on `inbound`'s sender itself (a test's
    /// in-process link); `describe` says where it is.
    pub fn new(inbound: Receiver<Inbound>, describe: String) -> Self {
        Self {
            inbound,
            describe,
            stop: Arc::new(AtomicBool::new(false)),
            threads: Vec::new(),
        }
    }
}

impl Drop for Transport {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        for thread in self.threads.drain(..) {
            let _ = thread.join();
        }
    }
}

/// Opens the transport a command line names: `tcp:ADDRESS` or `can:INTERFACE`.
pub fn open(spec: &str) -> Result<Transport> {
    if let Some(address) = spec.strip_prefix("tcp:") {
        let address: SocketAddr = address
            .parse()
            .with_context(|| format!("{address:?} is not an address such as 127.0.0.1:5555"))?;
        let listener =
            TcpListener::bind(address).with_context(|| format!("listening on {address}"))?;
        return listen(listener);
    }
    if let Some(interface) = spec.strip_prefix("can:") {
        #[cfg(target_os = "linux")]
        return can::open(interface);
        #[cfg(not(target_os = "linux"))]
        anyhow::bail!("XCP on CAN needs Linux's SocketCAN ({interface})");
    }
    anyhow::bail!("{spec:?}: expected tcp:ADDRESS or can:INTERFACE")
}

/// Serves XCP on TCP on `listener`: every connection is a client.
pub fn listen(listener: TcpListener) -> Result<Transport> {
    let address = listener.local_addr()?;
    listener.set_nonblocking(true)?;
    let (events, inbound) = sync_channel(INBOUND_LEN);
    let stop = Arc::new(AtomicBool::new(false));
    let accepting = {
        let stop = Arc::clone(&stop);
        std::thread::spawn(move || accept(&listener, &events, &stop))
    };
    Ok(Transport {
        inbound,
        describe: format!("XCP on TCP at {address}"),
        stop,
        threads: vec![accepting],
    })
}

fn accept(listener: &TcpListener, events: &SyncSender<Inbound>, stop: &AtomicBool) {
    let mut next: ClientId = 1;
    let open = Arc::new(AtomicUsize::new(0));
    while !stop.load(Ordering::Relaxed) {
        match listener.accept() {
            Ok((stream, _)) if open.load(Ordering::Relaxed) >= MAX_CLIENTS => {
                // Too many at once: closed as it comes, before it costs a thread.
                let _ = stream.shutdown(Shutdown::Both);
            }
            Ok((stream, peer)) => {
                if client(stream, peer, next, events, &open).is_err() {
                    continue;
                }
                next += 1;
            }
            // Nothing waiting: look at the stop flag again shortly.
            Err(error) if error.kind() == ErrorKind::WouldBlock => std::thread::sleep(STOP_POLL),
            Err(_) => std::thread::sleep(STOP_POLL),
        }
    }
}

/// Starts one TCP client's reader and writer.
fn client(
    stream: TcpStream,
    peer: SocketAddr,
    id: ClientId,
    events: &SyncSender<Inbound>,
    open: &Arc<AtomicUsize>,
) -> std::io::Result<()> {
    stream.set_nonblocking(false)?;
    stream.set_nodelay(true)?;
    // The kernel's own buffering kept small (autotuning would grow it to megabytes): a master
    // that stops reading fills its outbox within a second, not after minutes.
    socket2::SockRef::from(&stream).set_send_buffer_size(SEND_BUFFER)?;
    // A writer stuck this long on a master that does not read gives up; the outbox fills
    // long before, and the model thread drops the master then.
    stream.set_write_timeout(Some(Duration::from_secs(2)))?;
    let reading = stream.try_clone()?;
    let writing = stream.try_clone()?;
    let (queue, outgoing) = sync_channel::<Vec<u8>>(OUTBOX_LEN);
    let outbox = Outbox {
        queue,
        close: Box::new(move || {
            let _ = stream.shutdown(Shutdown::Both);
        }),
        lasting: false,
    };
    if events
        .send(Inbound::Opened {
            client: id,
            peer: peer.to_string(),
            outbox,
        })
        .is_err()
    {
        return Ok(());
    }
    let events = events.clone();
    open.fetch_add(1, Ordering::Relaxed);
    let open = Arc::clone(open);
    std::thread::spawn(move || {
        read_client(reading, id, &events);
        open.fetch_sub(1, Ordering::Relaxed);
    });
    std::thread::spawn(move || write_client(writing, &outgoing));
    Ok(())
}

fn read_client(mut stream: TcpStream, client: ClientId, events: &SyncSender<Inbound>) {
    let mut decoder = TcpDecoder::new();
    let mut buffer = [0u8; 512];
    let malformed = loop {
        let read = match stream.read(&mut buffer) {
            Ok(0) | Err(_) => break false,
            Ok(read) => read,
        };
        let mut packets = Vec::new();
        let decoded = decode_stream(&mut decoder, buffer.get(..read).unwrap_or_default(), |p| {
            packets.push(p);
        });
        for packet in packets {
            // Waits while the model thread is behind: TCP then pushes back on the master.
            if events.send(Inbound::Packet { client, packet }).is_err() {
                return;
            }
        }
        if decoded.is_err() {
            break true;
        }
    };
    let _ = stream.shutdown(Shutdown::Both);
    let _ = events.send(Inbound::Closed { client, malformed });
}

fn write_client(mut stream: TcpStream, outgoing: &Receiver<Vec<u8>>) {
    let mut encoder = TcpEncoder::new();
    let mut frame = [0u8; TCP_FRAME_MAX];
    // Ends when the outbox is dropped (the client is forgotten or finished) or the socket
    // fails; either way the connection is shut, which ends its reader too.
    while let Ok(packet) = outgoing.recv() {
        let Ok(len) = encoder.encode(&packet, &mut frame) else {
            continue;
        };
        if stream
            .write_all(frame.get(..len).unwrap_or_default())
            .is_err()
        {
            break;
        }
    }
    let _ = stream.shutdown(Shutdown::Both);
}

#[cfg(target_os = "linux")]
mod can {
    use super::{INBOUND_LEN, Inbound, OUTBOX_LEN, Outbox, STOP_POLL, Transport};
    use aer::calibration::xcp::{CAN_ID_MASTER, CAN_ID_SLAVE};
    use aer_xcp::transport::{CAN_DLC, can_frame};
    use anyhow::{Context, Result};
    use socketcan::id::{CAN_EFF_FLAG, CAN_RTR_FLAG, CAN_SFF_MASK};
    use socketcan::{CanFilter, EmbeddedFrame, Socket, SocketOptions, StandardId};
    use std::io::ErrorKind;
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::sync::mpsc::{Receiver, sync_channel};

    /// XCP on CAN on `interface`: the bus is one client, whoever sends on XCP_Cmd.
    pub(super) fn open(interface: &str) -> Result<Transport> {
        let open = || {
            socketcan::CanSocket::open(interface)
                .with_context(|| format!("opening the CAN interface {interface}"))
        };
        let reading = open()?;
        // Standard data frames with exactly the command id: an extended or remote frame is
        // not ours.
        let mask = CAN_SFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG;
        reading.set_filters(&[CanFilter::new(CAN_ID_MASTER, mask)])?;
        reading.set_read_timeout(STOP_POLL)?;
        let writing = open()?;
        let (events, inbound) = sync_channel(INBOUND_LEN);
        let (queue, outgoing) = sync_channel::<Vec<u8>>(OUTBOX_LEN);
        let outbox = Outbox {
            queue,
            close: Box::new(|| {}),
            lasting: true,
        };
        let _ = events.send(Inbound::Opened {
            client: 0,
            peer: format!("the bus on {interface}"),
            outbox,
        });
        let stop = Arc::new(AtomicBool::new(false));
        let reader = {
            let stop = Arc::clone(&stop);
            std::thread::spawn(move || {
                while !stop.load(Ordering::Relaxed) {
                    let packet = match reading.read_frame() {
                        Ok(socketcan::CanFrame::Data(frame)) => frame.data().to_vec(),
                        Ok(_) => continue,
                        Err(error)
                            if matches!(
                                error.kind(),
                                ErrorKind::WouldBlock | ErrorKind::TimedOut
                            ) =>
                        {
                            continue;
                        }
                        Err(_) => break,
                    };
                    // The DBC's XCP_Cmd is always 8 bytes: another length is not XCP.
                    let event = if packet.len() == CAN_DLC {
                        Inbound::Packet { client: 0, packet }
                    } else {
                        Inbound::Malformed
                    };
                    if events.send(event).is_err() {
                        break;
                    }
                }
            })
        };
        let writer = std::thread::spawn(move || write_bus(&writing, &outgoing));
        Ok(Transport {
            inbound,
            describe: format!(
                "XCP on CAN on {interface}, commands {CAN_ID_MASTER:#x}, responses {CAN_ID_SLAVE:#x}"
            ),
            stop,
            threads: vec![reader, writer],
        })
    }

    fn write_bus(socket: &socketcan::CanSocket, outgoing: &Receiver<Vec<u8>>) {
        let Some(id) = StandardId::new(CAN_ID_SLAVE as u16) else {
            return;
        };
        while let Ok(packet) = outgoing.recv() {
            let frame = can_frame(&packet).and_then(|data| socketcan::CanFrame::new(id, &data));
            if let Some(frame) = frame {
                // A full queue on the interface loses the frame, as the car's mailboxes would.
                let _ = socket.write_frame(&frame);
            }
        }
    }
}
