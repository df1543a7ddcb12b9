//! The desk car as a tuner and a careless or hostile master meet it (`aer-car-node serve`):
//! it keeps real time whatever its masters do, one master holds the slave at a time and
//! every other client is told busy at once, a master that stops reading is dropped, and a
//! session ends with its master's connection, so a stranger cannot take over an unlocked one.

use aer_car_model::driver::Cycle;
use aer_car_node::{masters, scenarios, serve};
use aer_xcp::transport::{TCP_FRAME_MAX, TcpDecoder, TcpEncoder};
use std::io::{ErrorKind, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

const CONNECT: [u8; 2] = [0xFF, 0x00];
const GET_STATUS: [u8; 1] = [0xFD];
/// GET_STATUS's resource protection byte: calibration and paging locked.
const CAL_PAG_LOCKED: u8 = 0x01;

/// A master over XCP on TCP, written here from the standard (no tool's code).
struct Master {
    stream: TcpStream,
    decoder: TcpDecoder,
    encoder: TcpEncoder,
    buffer: Vec<u8>,
}

impl Master {
    fn connect(address: SocketAddr) -> Self {
        let stream = TcpStream::connect(address).expect("connect");
        // Only so a broken server fails the test instead of hanging it.
        stream
            .set_read_timeout(Some(Duration::from_secs(20)))
            .unwrap();
        Self {
            stream,
            decoder: TcpDecoder::new(),
            encoder: TcpEncoder::new(),
            buffer: Vec::new(),
        }
    }

    fn send(&mut self, packet: &[u8]) -> std::io::Result<()> {
        let mut frame = [0u8; TCP_FRAME_MAX];
        let len = self.encoder.encode(packet, &mut frame).expect("a packet");
        self.stream.write_all(&frame[..len])
    }

    /// The next packet, or `None` once the server closed the connection.
    fn receive(&mut self) -> Option<Vec<u8>> {
        loop {
            let (used, packet) = self.decoder.decode(&self.buffer);
            self.buffer.drain(..used);
            if let Some(packet) = packet {
                return Some(packet.expect("a well-formed frame").data.to_vec());
            }
            let mut chunk = [0u8; 256];
            match self.stream.read(&mut chunk) {
                Ok(0) => return None,
                Ok(read) => self.buffer.extend_from_slice(&chunk[..read]),
                Err(error) if error.kind() == ErrorKind::ConnectionReset => return None,
                Err(error) => panic!("reading the server: {error}"),
            }
        }
    }

    fn command(&mut self, packet: &[u8]) -> Vec<u8> {
        self.send(packet).expect("sending a command");
        self.receive().expect("an answer")
    }
}

/// The desk server on a free port, running `model_ms` model milliseconds (or until `stop`).
fn desk(model_ms: u32, stop: &Arc<AtomicBool>) -> (SocketAddr, JoinHandle<serve::DeskReport>) {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let address = listener.local_addr().unwrap();
    let transport = masters::listen(listener).unwrap();
    let stop = Arc::clone(stop);
    let server = std::thread::spawn(move || {
        serve::serve(
            &transport,
            Cycle::Practice,
            Some(scenarios::SECRET),
            &[0x5E; 32],
            |ms| ms < model_ms && !stop.load(Ordering::Acquire),
        )
        .unwrap()
    });
    (address, server)
}

/// The desk keeps real time with an idle client connected and a master that floods commands
/// and never reads its answers: that master is dropped once its queue is full, a third
/// client is told busy while the flooder holds the slave, and model time stays within 2 % of
/// the wall clock.
#[test]
fn the_desk_keeps_real_time_with_an_idle_client_and_a_master_that_floods_and_never_reads() {
    let stop = Arc::new(AtomicBool::new(false));
    let (address, server) = desk(5_000, &stop);
    let idle = Master::connect(address);

    let mut flooder = Master::connect(address);
    let connected = flooder.command(&CONNECT);
    assert_eq!(connected[0], 0xFF, "CONNECT: {connected:02x?}");

    // A second master while the flooder holds the slave: told busy at once, then closed.
    let mut second = Master::connect(address);
    let busy = second.command(&CONNECT);
    assert_eq!(busy, [0xFE, 0x33], "ERR_RESOURCE_TEMPORARY_NOT_ACCESSIBLE");
    assert_eq!(second.receive(), None, "closed after the answer");

    // GET_STATUS as fast as TCP takes it, never reading: the server must drop it.
    let mut frame = [0u8; TCP_FRAME_MAX];
    let mut batch = Vec::new();
    let mut encoder = TcpEncoder::new();
    for _ in 0..256 {
        let len = encoder.encode(&GET_STATUS, &mut frame).unwrap();
        batch.extend_from_slice(&frame[..len]);
    }
    let mut sent = 0u64;
    while flooder.stream.write_all(&batch).is_ok() {
        sent += 256;
    }
    drop(flooder);
    // The slot is free again: what the flooder still had queued takes nothing back (a new
    // master may be told busy only until the server has forgotten the flooder).
    let mut attempts = 0;
    let mut next = loop {
        attempts += 1;
        assert!(
            attempts < 10_000,
            "the slot never came free after the flooder"
        );
        let mut master = Master::connect(address);
        if master.command(&CONNECT)[0] == 0xFF {
            break master;
        }
    };
    assert_eq!(next.command(&[0xFE]), [0xFF], "DISCONNECT");
    let report = server.join().unwrap();
    drop(idle);
    eprintln!("{sent} commands flooded; {report:?}");
    assert_eq!(report.stopped_reading, 1, "the flooder was dropped");
    assert!(report.told_busy >= 1);
    assert!(report.clients >= 4);
    let ratio = report.real_time_ratio();
    assert!(
        (0.98..=1.02).contains(&ratio),
        "model time over wall time {ratio:.4}"
    );
}

/// A master that unlocked calibration and then vanished (its connection closed, no
/// DISCONNECT) leaves nothing behind: the next master finds calibration locked again.
#[test]
fn a_session_ends_with_its_masters_connection() {
    let stop = Arc::new(AtomicBool::new(false));
    let (address, server) = desk(u32::MAX, &stop);

    let mut first = Master::connect(address);
    assert_eq!(first.command(&CONNECT)[0], 0xFF);
    let seed = first.command(&[0xF8, 0, 0x01]);
    assert_eq!(seed[0], 0xFF, "GET_SEED: {seed:02x?}");
    let key = aer_ccm::xcp::key_for(&scenarios::SECRET, &seed[2..2 + usize::from(seed[1])]);
    let mut remaining = key.len();
    for chunk in key.chunks(6) {
        let mut unlock = vec![0xF7, remaining as u8];
        unlock.extend_from_slice(chunk);
        let answer = first.command(&unlock);
        assert_eq!(answer[0], 0xFF, "UNLOCK: {answer:02x?}");
        remaining -= chunk.len();
    }
    let status = first.command(&GET_STATUS);
    assert_eq!(status[2] & CAL_PAG_LOCKED, 0, "unlocked: {status:02x?}");
    drop(first);

    // The next master: until the server has seen the first one's connection end, it is
    // told busy and may try again at once.
    let mut attempts = 0;
    let mut next = loop {
        attempts += 1;
        assert!(attempts < 10_000, "the slot never came free");
        let mut master = Master::connect(address);
        if master.command(&CONNECT)[0] == 0xFF {
            break master;
        }
    };
    let status = next.command(&GET_STATUS);
    assert_eq!(
        status[2] & CAL_PAG_LOCKED,
        CAL_PAG_LOCKED,
        "locked again: {status:02x?}"
    );
    stop.store(true, Ordering::Release);
    let report = server.join().unwrap();
    assert_eq!(report.transport_ended, 1, "{report:?}");
}

/// A client holds the slave only while its XCP session lasts: after its DISCONNECT (its
/// connection still open), or sending commands without CONNECT, it does not keep another
/// master out.
#[test]
fn a_client_outside_a_session_holds_nothing() {
    let stop = Arc::new(AtomicBool::new(false));
    let (address, server) = desk(u32::MAX, &stop);

    let mut lingering = Master::connect(address);
    assert_eq!(lingering.command(&CONNECT)[0], 0xFF);
    assert_eq!(lingering.command(&[0xFE]), [0xFF], "DISCONNECT");
    let mut next = Master::connect(address);
    assert_eq!(
        next.command(&CONNECT)[0],
        0xFF,
        "after the other's DISCONNECT"
    );
    assert_eq!(next.command(&[0xFE]), [0xFF]);

    stop.store(true, Ordering::Release);
    let report = server.join().unwrap();
    drop(lingering);
    assert_eq!(report.told_busy, 0, "{report:?}");
}

/// A stranger that sends commands without CONNECT holds nothing, and a client the desk has
/// told busy is forgotten: its later packets take nothing. The events reach the desk in this
/// order through one in-process transport, as the TCP threads would hand them over.
#[test]
fn a_stranger_without_a_session_and_a_client_told_busy_take_nothing() {
    use aer_car_node::masters::{Inbound, Outbox, Transport};
    use std::sync::mpsc::sync_channel;
    let (events, inbound) = sync_channel(masters::INBOUND_LEN);
    let mut outgoing = Vec::new();
    for client in 1..=3 {
        let (queue, answers) = sync_channel::<Vec<u8>>(masters::OUTBOX_LEN);
        outgoing.push(answers);
        events
            .send(Inbound::Opened {
                client,
                peer: format!("client {client}"),
                outbox: Outbox::new(queue, Box::new(|| {})),
            })
            .unwrap();
    }
    let packet = |client, packet: &[u8]| Inbound::Packet {
        client,
        packet: packet.to_vec(),
    };
    // 1 never connects; 2 connects while 1 has sent; 3 is told busy, then sends again.
    for event in [
        packet(1, &GET_STATUS),
        packet(2, &CONNECT),
        packet(3, &CONNECT),
        packet(3, &CONNECT),
        packet(2, &[0xFE]),
        packet(1, &GET_STATUS),
    ] {
        events.send(event).unwrap();
    }
    let transport = Transport::new(inbound, "in process".into());
    let report = serve::serve(&transport, Cycle::Practice, None, &[0x5E; 32], |ms| {
        ms < 100
    })
    .unwrap();
    let answers: Vec<Vec<Vec<u8>>> = outgoing.iter().map(|a| a.try_iter().collect()).collect();
    assert!(answers[0].is_empty(), "the stranger: {:02x?}", answers[0]);
    assert_eq!(
        answers[1].len(),
        2,
        "CONNECT and DISCONNECT: {:02x?}",
        answers[1]
    );
    assert_eq!(answers[1][0][0], 0xFF);
    assert_eq!(answers[1][1], [0xFF]);
    assert_eq!(
        answers[2],
        [vec![0xFE, 0x33]],
        "told busy once, then forgotten"
    );
    assert_eq!(report.told_busy, 1);
}

/// On a bus (XCP on CAN: the transport outlives its sessions) a session the desk ends keeps
/// the bus: the next CONNECT on it is served. Here the bus's queue is never read, so each
/// session ends "stopped reading"; the second CONNECT still reaches the slave.
#[test]
fn a_bus_outlives_the_sessions_the_desk_ends() {
    use aer_car_node::masters::{Inbound, Outbox, Transport};
    use std::sync::mpsc::sync_channel;
    let (events, inbound) = sync_channel(masters::INBOUND_LEN);
    let (queue, _never_read) = sync_channel::<Vec<u8>>(1);
    events
        .send(Inbound::Opened {
            client: 0,
            peer: "the bus".into(),
            outbox: Outbox::lasting(queue, Box::new(|| {})),
        })
        .unwrap();
    let packet = |packet: &[u8]| Inbound::Packet {
        client: 0,
        packet: packet.to_vec(),
    };
    for event in [packet(&CONNECT), packet(&GET_STATUS), packet(&CONNECT)] {
        events.send(event).unwrap();
    }
    let transport = Transport::new(inbound, "in process".into());
    let report =
        serve::serve(&transport, Cycle::Practice, None, &[0x5E; 32], |ms| ms < 50).unwrap();
    assert_eq!(report.stopped_reading, 2, "{report:?}");
}
