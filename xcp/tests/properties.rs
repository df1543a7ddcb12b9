//! Properties over arbitrary input: the slave never panics, every answer is a well-formed
//! packet, the target is only ever asked for memory in its map (or refuses), calibration only
//! changes while unlocked and never to an invalid page, DAQ stays within the frame budget, and
//! the TCP framing survives any stream and round-trips what it encodes.

mod common;

use aer_xcp::transport::{CAN_PAD, TCP_FRAME_MAX, TcpDecoder, TcpEncoder, TcpError, can_frame};
use common::*;
use proptest::prelude::*;

/// Every command code the slave implements, plus a few it does not.
const CODES: &[u8] = &[
    0xFF, 0xFE, 0xFD, 0xFC, 0xFB, 0xFA, 0xF9, 0xF8, 0xF7, 0xF6, 0xF5, 0xF4, 0xF3, 0xF0, 0xEF, 0xED,
    0xEB, 0xEA, 0xE9, 0xE8, 0xE7, 0xE4, 0xE3, 0xE2, 0xE1, 0xE0, 0xDF, 0xDE, 0xDD, 0xDC, 0xDA, 0xD9,
    0xD7, 0xD6, 0xD5, 0xD4, 0xD3, 0xC0, 0xEC, 0x12,
];

/// What the test harness does next.
#[derive(Debug, Clone)]
enum Op {
    /// A command packet.
    Packet(Vec<u8>),
    /// CONNECT (again): random packets disconnect now and then.
    Connect,
    /// GET_SEED + UNLOCK with the right key (if connected).
    Unlock,
    /// One simulated second of events: sensors every 1 ms, control every 10 ms.
    Second,
    /// The car starts or stops moving.
    Moving(bool),
    /// A well-formed DAQ configuration (lists of (ODTs, event, prescaler, timestamp)), started
    /// together (START_STOP_SYNCH) or one by one.
    Daq {
        lists: Vec<(u8, u8, u8, bool)>,
        together: bool,
    },
    /// A well-formed write of `data` at the working page's `offset` (one DOWNLOAD, or a block).
    Write { offset: u32, data: Vec<u8> },
}

/// Addresses near and inside the map, so generated commands reach it.
fn address() -> impl Strategy<Value = u32> {
    prop_oneof![
        (0u32..40).prop_map(|offset| CAL.wrapping_add(offset).wrapping_sub(4)),
        (0u32..20).prop_map(|offset| MEAS.wrapping_add(offset).wrapping_sub(2)),
        (0u32..24).prop_map(|offset| EPK_ADDR + offset),
        any::<u32>(),
    ]
}

/// A command packet: a known code, small parameters, sometimes an address at bytes 4..8.
fn packet() -> impl Strategy<Value = Vec<u8>> {
    (
        prop::sample::select(CODES),
        prop::collection::vec(prop_oneof![0u8..8, any::<u8>()], 0..8),
        prop::option::of(address()),
        prop::bool::weighted(0.03),
    )
        .prop_map(|(code, mut body, address, oversize)| {
            if let Some(address) = address {
                body.resize(7, 0);
                body[3..7].copy_from_slice(&address.to_le_bytes());
            }
            if oversize {
                body.resize(9, 0xAA);
            }
            let mut packet = vec![code];
            packet.extend(body);
            packet
        })
}

fn op() -> impl Strategy<Value = Op> {
    prop_oneof![
        30 => packet().prop_map(Op::Packet),
        2 => Just(Op::Connect),
        3 => Just(Op::Unlock),
        2 => Just(Op::Second),
        1 => any::<bool>().prop_map(Op::Moving),
        3 => (prop::collection::vec((1u8..4, 0u8..2, 1u8..12, any::<bool>()), 1..4), any::<bool>())
            .prop_map(|(lists, together)| Op::Daq { lists, together }),
        4 => (0u32..34, prop::collection::vec(any::<u8>(), 1..=48)).prop_map(|(offset, data)| Op::Write { offset, data }),
    ]
}

/// Sends a packet; the answer, checked for form.
fn send(bench: &mut Bench, packet: &[u8]) -> Option<Vec<u8>> {
    let answer = bench.cmd(packet);
    if let Some(answer) = &answer {
        assert_valid_answer(answer);
    }
    answer
}

/// Configures and starts DAQ lists with correct commands (the slave may still refuse them,
/// e.g. over the budget).
fn configure_daq(bench: &mut Bench, lists: &[(u8, u8, u8, bool)], together: bool) {
    send(bench, &[0xD6]);
    send(bench, &[0xD5, 0, lists.len() as u8, 0]);
    for (number, (odts, ..)) in lists.iter().enumerate() {
        send(bench, &[0xD4, 0, number as u8, 0, *odts]);
    }
    for (number, (odts, ..)) in lists.iter().enumerate() {
        for odt in 0..*odts {
            send(bench, &[0xD3, 0, number as u8, 0, odt, 1]);
        }
    }
    for (number, (odts, event, prescaler, timestamp)) in lists.iter().enumerate() {
        for odt in 0..*odts {
            send(bench, &[0xE2, 0, number as u8, 0, odt, 0]);
            let a = (MEAS + u32::from(odt) * 3).to_le_bytes();
            send(bench, &[0xE1, 0xFF, 1 + odt % 3, 0, a[0], a[1], a[2], a[3]]);
        }
        let mode = if *timestamp { 0x10 } else { 0 };
        send(
            bench,
            &[0xE0, mode, number as u8, 0, *event, 0, *prescaler, 0],
        );
        send(
            bench,
            &[0xDE, if together { 2 } else { 1 }, number as u8, 0],
        );
    }
    if together {
        send(bench, &[0xDD, 0x01]);
    }
}

/// Writes `data` at the working page's `offset` as pyxcp does in master block mode; the last
/// answer.
fn write_block(bench: &mut Bench, offset: u32, data: &[u8]) -> Option<Vec<u8>> {
    let a = (CAL + offset).to_le_bytes();
    send(bench, &[0xF6, 0, 0, 0, a[0], a[1], a[2], a[3]])?;
    let mut answer = send(
        bench,
        &[&[0xF0, data.len() as u8][..], &data[..data.len().min(6)]].concat(),
    );
    let mut sent = data.len().min(6);
    while sent < data.len() {
        let chunk = &data[sent..data.len().min(sent + 6)];
        answer = send(
            bench,
            &[&[0xEF, (data.len() - sent) as u8][..], chunk].concat(),
        );
        sent += chunk.len();
    }
    answer
}

/// An answer must be a response or an error packet of 1..=8 bytes (errors carry a code).
fn assert_valid_answer(answer: &[u8]) {
    assert!(
        (1..=8).contains(&answer.len()),
        "answer length {}",
        answer.len()
    );
    match answer[0] {
        0xFF => {}
        0xFE => assert!(answer.len() >= 2, "error packet without a code"),
        other => panic!("answer PID {other:02X}"),
    }
}

/// Every access the target accepted was inside its map.
fn assert_accesses_in_map(target: &FakeTarget) {
    for read in target.reads.borrow().iter().filter(|read| read.accepted) {
        assert!(
            FakeTarget::in_map(read.ext, read.address, read.len),
            "read outside the map: {read:?}"
        );
    }
    for (ext, address, data, accepted) in &target.writes {
        if *accepted {
            assert!(
                *ext == 0
                    && *address >= CAL
                    && *address as usize + data.len() <= CAL as usize + CAL_LEN
            );
        }
    }
}

/// GET_SEED and UNLOCK with the right key, without assuming the slave is connected.
fn try_unlock(bench: &mut Bench) {
    let Some(seed) = bench.cmd(&[0xF8, 0x00, 0x01]) else {
        return;
    };
    if seed.len() != 8 || seed[..2] != [0xFF, 6] {
        return;
    }
    let key = FakeTarget::key_for(&seed[2..]);
    for packet in [
        [&[0xF7, KEY_LEN as u8][..], &key[..6]].concat(),
        [&[0xF7, 2][..], &key[6..]].concat(),
    ] {
        if let Some(answer) = bench.cmd(&packet) {
            assert_valid_answer(&answer);
        }
    }
}

/// One simulated second of events; the DTOs sent.
fn one_second(bench: &mut Bench) -> usize {
    let mut dtos = 0usize;
    for ms in 0..1000u32 {
        bench.now_us = bench.now_us.wrapping_add(1000);
        bench.target.reads.borrow_mut().clear();
        let channels: &[u16] = if ms % 10 == 0 { &[1, 0] } else { &[1] };
        for &channel in channels {
            let report =
                bench
                    .slave
                    .event(&bench.target, channel, bench.now_us, &mut |dto: &[u8]| {
                        assert!((1..=8).contains(&dto.len()), "DTO length {}", dto.len());
                        assert!(dto[0] < 0xFC, "DTO PID {:02X}", dto[0]);
                        true
                    });
            assert_eq!(report.dropped, 0);
            dtos += report.sent as usize;
        }
        // DAQ never samples anything the target refused or that is outside the map.
        for read in bench.target.reads.borrow().iter() {
            assert!(
                read.accepted && FakeTarget::in_map(read.ext, read.address, read.len),
                "DAQ read {read:?}"
            );
        }
    }
    dtos
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, ..ProptestConfig::default() })]

    #[test]
    fn arbitrary_packets_from_cold_never_panic(packets in prop::collection::vec(prop::collection::vec(any::<u8>(), 0..12), 0..40)) {
        let mut bench = Bench::new();
        for packet in &packets {
            if let Some(answer) = bench.cmd(packet) {
                assert_valid_answer(&answer);
            }
        }
        assert_accesses_in_map(&bench.target);
        prop_assert_eq!(bench.target.reference, FakeTarget::new().reference);
    }

    #[test]
    fn command_sequences_keep_every_invariant(ops in prop::collection::vec(op(), 1..60)) {
        let mut bench = Bench::connected();
        let reference = bench.target.reference;
        for op in ops {
            let locked = bench.slave.is_calibration_locked();
            let writes = bench.target.writes.len();
            let page_calls = bench.target.page_calls;
            let working = bench.target.working;
            match &op {
                Op::Packet(packet) => {
                    if let Some(answer) = bench.cmd(packet) {
                        assert_valid_answer(&answer);
                    }
                    if locked {
                        prop_assert_eq!(bench.target.writes.len(), writes, "write while locked: {:02X?}", packet);
                        prop_assert_eq!(bench.target.page_calls, page_calls, "page change while locked");
                    }
                    if bench.target.moving {
                        prop_assert_eq!(bench.target.working, working, "change while moving");
                    }
                }
                Op::Connect => {
                    prop_assert_eq!(send(&mut bench, &[0xFF, 0]).map(|answer| answer[0]), Some(0xFF));
                }
                Op::Unlock => try_unlock(&mut bench),
                Op::Second => {
                    let dtos = one_second(&mut bench);
                    // DAQ may use 200 of the 250 frames/s; rounding of prescaled lists over a
                    // one-second window adds at most one DTO per ODT (16 ODTs).
                    prop_assert!(dtos <= 200 + 16, "{} DTOs in one second", dtos);
                }
                Op::Moving(moving) => bench.target.moving = *moving,
                Op::Daq { lists, together } => configure_daq(&mut bench, lists, *together),
                Op::Write { offset, data } => {
                    let answer = write_block(&mut bench, *offset, data);
                    let start = *offset as usize;
                    if answer.as_deref() == Some(&[0xFF][..]) {
                        prop_assert!(!locked && !bench.target.moving);
                        prop_assert_eq!(&bench.target.working[start..start + data.len()], &data[..]);
                        prop_assert_eq!(bench.target.writes.len(), writes + 1, "one write per block");
                    } else {
                        prop_assert_eq!(bench.target.working, working, "a refused block changed the page");
                    }
                }
            }
            prop_assert_eq!(bench.target.reference, reference, "the reference page changed");
            let page = bench.target.working;
            prop_assert!(page[LIMITED] <= 100);
            prop_assert!(u16::from_le_bytes([page[4], page[5]]) < u16::from_le_bytes([page[6], page[7]]));
            assert_accesses_in_map(&bench.target);
        }
    }

    #[test]
    fn tcp_decoder_survives_any_stream(stream in prop::collection::vec(any::<u8>(), 0..200), cuts in prop::collection::vec(1usize..16, 1..20)) {
        let mut decoder = TcpDecoder::new();
        let mut rest = &stream[..];
        let mut broken = false;
        for cut in cuts.iter().cycle() {
            if rest.is_empty() {
                break;
            }
            let mut piece = &rest[..(*cut).min(rest.len())];
            rest = &rest[piece.len()..];
            loop {
                let (used, item) = decoder.decode(piece);
                prop_assert!(used <= piece.len());
                piece = &piece[used..];
                match item {
                    Some(Ok(packet)) => {
                        prop_assert!(!broken, "a packet after a framing error");
                        prop_assert!((1..=8).contains(&packet.data.len()));
                    }
                    Some(Err(TcpError::BadLength(length))) => {
                        prop_assert!(length == 0 || length > 8);
                        broken = true;
                        break;
                    }
                    Some(Err(other)) => prop_assert!(false, "unexpected {:?}", other),
                    None => {
                        prop_assert!(piece.is_empty());
                        break;
                    }
                }
            }
        }
    }

    #[test]
    fn tcp_round_trips_packets_in_any_split(packets in prop::collection::vec(prop::collection::vec(any::<u8>(), 1..=8), 0..30), cuts in prop::collection::vec(1usize..20, 1..10), start in any::<u16>()) {
        let mut encoder = TcpEncoder::new();
        for _ in 0..start % 5 {
            let mut scratch = [0u8; TCP_FRAME_MAX];
            encoder.encode(&[0xFF], &mut scratch).unwrap();
        }
        let first_ctr = encoder.next_ctr();
        let mut stream = Vec::new();
        for packet in &packets {
            let mut frame = [0u8; TCP_FRAME_MAX];
            let len = encoder.encode(packet, &mut frame).unwrap();
            prop_assert_eq!(len, packet.len() + 4);
            stream.extend_from_slice(&frame[..len]);
        }
        let mut decoder = TcpDecoder::new();
        let mut decoded = Vec::new();
        let mut rest = &stream[..];
        for cut in cuts.iter().cycle() {
            if rest.is_empty() {
                break;
            }
            let mut piece = &rest[..(*cut).min(rest.len())];
            rest = &rest[piece.len()..];
            while !piece.is_empty() {
                let (used, item) = decoder.decode(piece);
                piece = &piece[used..];
                if let Some(item) = item {
                    let packet = item.unwrap();
                    decoded.push((packet.ctr, packet.data.to_vec()));
                }
            }
        }
        let expected: Vec<(u16, Vec<u8>)> = packets.iter().enumerate().map(|(i, packet)| (first_ctr.wrapping_add(i as u16), packet.clone())).collect();
        prop_assert_eq!(decoded, expected);
    }

    #[test]
    fn can_frames_are_padded_packets(packet in prop::collection::vec(any::<u8>(), 0..12)) {
        match can_frame(&packet) {
            Some(frame) => {
                prop_assert!(packet.len() <= 8);
                prop_assert_eq!(&frame[..packet.len()], &packet[..]);
                prop_assert!(frame[packet.len()..].iter().all(|&byte| byte == CAN_PAD));
            }
            None => prop_assert!(packet.len() > 8),
        }
    }
}

#[test]
fn tcp_errors_are_typed() {
    let mut decoder = TcpDecoder::new();
    assert_eq!(
        decoder.decode(&[0, 0, 1, 0]),
        (4, Some(Err(TcpError::BadLength(0))))
    );
    assert_eq!(
        decoder.decode(&[1, 0, 0, 0, 0xFF]),
        (0, Some(Err(TcpError::BadLength(0)))),
        "stays broken"
    );
    decoder.reset();
    assert_eq!(
        decoder.decode(&[9, 0, 1, 0]),
        (4, Some(Err(TcpError::BadLength(9))))
    );
    decoder.reset();
    let (used, item) = decoder.decode(&[2, 0, 7, 0, 0xFF, 0x00, 0x99]);
    assert_eq!(used, 6);
    let packet = item.unwrap().unwrap();
    assert_eq!((packet.ctr, packet.data), (7, &[0xFF, 0x00][..]));
    let mut encoder = TcpEncoder::new();
    let mut out = [0u8; TCP_FRAME_MAX];
    assert_eq!(encoder.encode(&[], &mut out), Err(TcpError::PacketSize(0)));
    assert_eq!(
        encoder.encode(&[0; 9], &mut out),
        Err(TcpError::PacketSize(9))
    );
    assert_eq!(encoder.encode(&[0xFF, 0x05], &mut out), Ok(6));
    assert_eq!(out[..6], [2, 0, 0, 0, 0xFF, 0x05]);
    assert_eq!(encoder.encode(&[0xFE, 0x20], &mut out), Ok(6));
    assert_eq!(out[..4], [2, 0, 1, 0], "the counter advances");
}

#[test]
fn a_slave_served_over_tcp_answers_pyxcps_connect() {
    // The host server's loop: decode, command, encode; CONNECT then GET_STATUS in one segment.
    let mut bench = Bench::new();
    let mut decoder = TcpDecoder::new();
    let mut encoder = TcpEncoder::new();
    let stream = [2, 0, 0, 0, 0xFF, 0x00, 1, 0, 1, 0, 0xFD];
    let mut rest = &stream[..];
    let mut out = Vec::new();
    while !rest.is_empty() {
        let (used, item) = decoder.decode(rest);
        rest = &rest[used..];
        let Some(Ok(packet)) = item else { continue };
        let mut reply = [0u8; 8];
        let len = bench
            .slave
            .command(&mut bench.target, packet.data, 0, &mut reply)
            .unwrap();
        let mut frame = [0u8; TCP_FRAME_MAX];
        let n = encoder.encode(&reply[..len], &mut frame).unwrap();
        out.extend_from_slice(&frame[..n]);
    }
    assert_eq!(
        out,
        [
            8, 0, 0, 0, 0xFF, 0x05, 0x80, 8, 8, 0, 1, 1, 6, 0, 1, 0, 0xFF, 0x00, 0x01, 0x00, 0x00,
            0x00
        ]
    );
}
