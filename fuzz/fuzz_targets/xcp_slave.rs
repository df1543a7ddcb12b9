//! Arbitrary command packets into the XCP slave (what the CCM takes off the bus, or the host
//! off a TCP socket), against the fake ECU of the slave's tests. The slave must never panic,
//! answer only well-formed packets, send only well-formed DTOs, ask the target only for
//! memory in its map (or be refused), and change calibration only while unlocked, never the
//! reference page and never into an invalid page.
//!
//! Input: the first byte picks the framing. CAN (bit 0 clear): chunks of one header byte and a
//! packet; a header with bit 7 set is an action instead (fire event 0 or 1, toggle "moving",
//! unlock with the right key), otherwise its low nibble is the packet's length (up to 15, so
//! over-long packets occur too). TCP (bit 0 set): the rest is a byte stream for the TCP
//! decoder, cut into pieces by the input's own bytes; both events fire after every command.
#![no_main]

#[path = "../../xcp/tests/common/mod.rs"]
mod common;

use aer_xcp::transport::{TCP_FRAME_MAX, TcpDecoder, TcpEncoder};
use common::{Bench, CAL, CAL_LEN, FakeTarget, KEY_LEN, LIMITED, PEDAL_FULL, PEDAL_REST};
use libfuzzer_sys::fuzz_target;

/// Sends one packet and checks the answer's form and the target's invariants.
fn command(bench: &mut Bench, packet: &[u8], reference: &[u8; CAL_LEN]) -> Option<Vec<u8>> {
    let locked = bench.slave.is_calibration_locked();
    let writes = bench.target.writes.len();
    let page_calls = bench.target.page_calls;
    let answer = bench.cmd(packet);
    if let Some(answer) = &answer {
        assert!(
            matches!(answer[0], 0xFF | 0xFE),
            "answer PID {:02X}",
            answer[0]
        );
    }
    if locked {
        assert_eq!(bench.target.writes.len(), writes, "write while locked");
        assert_eq!(
            bench.target.page_calls, page_calls,
            "page change while locked"
        );
    }
    check(bench, reference);
    answer
}

/// The target's invariants.
fn check(bench: &Bench, reference: &[u8; CAL_LEN]) {
    let target = &bench.target;
    assert_eq!(&target.reference, reference);
    assert!(target.working[LIMITED] <= 100);
    let rest = u16::from_le_bytes([target.working[PEDAL_REST], target.working[PEDAL_REST + 1]]);
    let full = u16::from_le_bytes([target.working[PEDAL_FULL], target.working[PEDAL_FULL + 1]]);
    assert!(rest < full);
    for read in target.reads.borrow().iter().filter(|read| read.accepted) {
        assert!(FakeTarget::in_map(read.ext, read.address, read.len));
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

/// Fires an event channel and checks the DTOs.
fn event(bench: &mut Bench, channel: u16) {
    bench.now_us = bench.now_us.wrapping_add(1000);
    bench.target.reads.borrow_mut().clear();
    bench
        .slave
        .event(&bench.target, channel, bench.now_us, &mut |dto: &[u8]| {
            assert!((1..=8).contains(&dto.len()));
            assert!(dto[0] < 0xFC);
            true
        });
    for read in bench.target.reads.borrow().iter() {
        assert!(read.accepted && FakeTarget::in_map(read.ext, read.address, read.len));
    }
}

/// GET_SEED and UNLOCK with the right key.
fn unlock(bench: &mut Bench, reference: &[u8; CAL_LEN]) {
    let Some(seed) = command(bench, &[0xF8, 0x00, 0x01], reference) else {
        return;
    };
    if seed.len() != 8 || seed[..2] != [0xFF, 6] {
        return;
    }
    let key = FakeTarget::key_for(&seed[2..]);
    command(
        bench,
        &[&[0xF7, KEY_LEN as u8][..], &key[..6]].concat(),
        reference,
    );
    command(bench, &[&[0xF7, 2][..], &key[6..]].concat(), reference);
}

fuzz_target!(|data: &[u8]| {
    let Some((&mode, mut rest)) = data.split_first() else {
        return;
    };
    let mut bench = Bench::new();
    let reference = bench.target.reference;
    command(&mut bench, &[0xFF, 0x00], &reference);
    if mode & 1 == 0 {
        while let Some((&header, tail)) = rest.split_first() {
            rest = tail;
            if header & 0x80 != 0 {
                match header & 0x03 {
                    0 => event(&mut bench, 0),
                    1 => event(&mut bench, 1),
                    2 => bench.target.moving = !bench.target.moving,
                    _ => unlock(&mut bench, &reference),
                }
                continue;
            }
            let len = usize::from(header & 0x0F).min(rest.len());
            let (packet, tail) = rest.split_at(len);
            rest = tail;
            command(&mut bench, packet, &reference);
        }
        return;
    }
    let mut decoder = TcpDecoder::new();
    let mut encoder = TcpEncoder::new();
    let mut cut = 1usize;
    while !rest.is_empty() {
        let piece_len = cut.min(rest.len());
        let (mut piece, tail) = rest.split_at(piece_len);
        rest = tail;
        cut = usize::from(piece.first().copied().unwrap_or(1) % 13) + 1;
        while !piece.is_empty() {
            let (used, item) = decoder.decode(piece);
            piece = &piece[used..];
            match item {
                Some(Ok(packet)) => {
                    let packet = packet.data.to_vec();
                    if let Some(answer) = command(&mut bench, &packet, &reference) {
                        let mut frame = [0u8; TCP_FRAME_MAX];
                        let len = encoder
                            .encode(&answer, &mut frame)
                            .expect("answers fit a frame");
                        assert_eq!(
                            usize::from(u16::from_le_bytes([frame[0], frame[1]])),
                            len - 4
                        );
                    }
                    event(&mut bench, 0);
                    event(&mut bench, 1);
                }
                Some(Err(_)) => return, // the connection would be closed
                None => break,
            }
        }
    }
});
