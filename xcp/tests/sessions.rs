//! Sessions as a careless or hostile master meets them: a session ends with its transport
//! and after the idle time-out, a wrong key slows every next try, DAQ says what it lost, and
//! the slave publishes why it refused.

mod common;

use aer_xcp::protocol::{ev, pid};
use aer_xcp::{SessionEnd, reason};
use common::*;

const IDLE_US: u32 = IDLE_TIMEOUT_MS * 1_000;

/// The packets `poll` sent at `now_us`, and what it reported.
fn poll(bench: &mut Bench) -> (Option<SessionEnd>, Vec<Vec<u8>>) {
    let mut sent = Vec::new();
    let ended = bench.slave.poll(bench.now_us, &mut |packet: &[u8]| {
        sent.push(packet.to_vec());
        true
    });
    (ended, sent)
}

#[test]
fn a_lost_transport_ends_the_session_and_its_half_done_block() {
    let mut bench = Bench::unlocked();
    let before = bench.target.working;
    bench.set_mta(CAL);
    // The first packet of a 12-byte block: the rest never comes.
    assert_eq!(bench.cmd(&[0xF0, 12, 1, 2, 3, 4, 5, 6]), None);
    assert_eq!(
        bench.slave.transport_lost(),
        Some(SessionEnd::TransportLost)
    );
    assert!(!bench.slave.is_connected());
    // A stranger on the next connection: no session to continue, nothing unlocked.
    assert_eq!(
        bench.cmd(&[0xEF, 6, 7, 8, 9, 10, 11, 12]),
        None,
        "not connected"
    );
    bench.ask(&[0xFF, 0x00]);
    assert!(bench.slave.is_calibration_locked());
    assert_eq!(bench.ask(&[0xEF, 6, 7, 8, 9, 10, 11, 12])[0], 0xFE);
    assert_eq!(bench.target.working, before);
    assert!(bench.target.writes.is_empty());
    assert_eq!(bench.slave.counters().transport_ends, 1);
    // Nothing to end without a session.
    bench.ask(&[0xFE]);
    assert_eq!(bench.slave.transport_lost(), None);
}

#[test]
fn an_idle_session_ends_at_the_time_out_and_says_so() {
    let mut bench = Bench::unlocked();
    let last = bench.now_us;
    bench.now_us = last + IDLE_US - 1;
    assert_eq!(poll(&mut bench), (None, Vec::new()), "1 us before");
    bench.now_us = last + IDLE_US;
    assert_eq!(
        poll(&mut bench),
        (
            Some(SessionEnd::Idle),
            vec![vec![pid::EV, ev::SESSION_TERMINATED]]
        )
    );
    assert!(!bench.slave.is_connected());
    assert!(bench.slave.is_calibration_locked());
    assert_eq!(bench.cmd(&[0xFD]), None, "commands need a new CONNECT");
    assert_eq!(poll(&mut bench), (None, Vec::new()), "once");
    assert_eq!(bench.slave.counters().idle_ends, 1);
}

#[test]
fn every_command_restarts_the_idle_time_out() {
    let mut bench = Bench::unlocked();
    for _ in 0..5 {
        bench.now_us += IDLE_US - 1;
        assert_eq!(poll(&mut bench).0, None);
        bench.ask(&[0xFD]);
    }
    assert!(!bench.slave.is_calibration_locked());
}

#[test]
fn an_idle_session_with_daq_running_keeps_measuring_but_is_locked_again() {
    let mut bench = Bench::unlocked();
    start_two_odt_list(&mut bench, false);
    bench.now_us += IDLE_US;
    assert_eq!(
        poll(&mut bench),
        (Some(SessionEnd::IdleRelocked), Vec::new())
    );
    assert!(bench.slave.is_connected());
    assert!(bench.slave.is_calibration_locked());
    assert_eq!(bench.event(0).len(), 2, "both ODTs still sent");
    bench.set_mta(CAL);
    assert_eq!(bench.ask(&[0xF0, 1, 5]), [0xFE, 0x25], "unlock first");
    bench.unlock();
    assert_eq!(bench.ask(&[0xF0, 1, 5]), [0xFF]);
}

/// Every wrong key doubles the time GET_SEED stays refused: a master trying keys as fast as
/// the slave answers gets 6 tries in a minute, not the 375,000 it had before.
#[test]
fn wrong_keys_are_slowed_by_a_doubling_delay() {
    let mut bench = Bench::new();
    let start = bench.now_us;
    let mut tries = 0;
    let mut refused = 0;
    // One command per millisecond for a minute.
    while bench.now_us - start < 60_000_000 {
        bench.now_us += 1_000;
        if !bench.slave.is_connected() {
            bench.ask(&[0xFF, 0x00]);
            continue;
        }
        let seed = bench.ask(&[0xF8, 0x00, 0x01]);
        if seed == [0xFE, 0x33] {
            refused += 1;
            continue;
        }
        assert_eq!(seed[0], 0xFF);
        tries += 1;
        let wrong = [0u8; KEY_LEN];
        bench.ask(&[&[0xF7, KEY_LEN as u8][..], &wrong[..6]].concat());
        let answer = bench.ask(&[&[0xF7, (KEY_LEN - 6) as u8][..], &wrong[6..]].concat());
        assert_eq!(answer, [0xFE, 0x25], "a wrong key");
    }
    // 1 + 2 + 4 + 8 + 16 s of delays fit a minute, the next 32 s do not.
    assert_eq!(tries, 6);
    assert!(refused > 1_000);
    assert_eq!(bench.slave.counters().wrong_keys, 6);
    // What the slave publishes: too soon, and how long is left (s).
    let last = bench.slave.last_refusal();
    assert_eq!(last.detail.reason, reason::TOO_SOON);
    assert!(last.detail.value > 0.0 && last.detail.value <= 32.0);
    // Once the delay has passed, the right key unlocks and clears it.
    bench.now_us += 300_000_000;
    bench.unlock();
    bench.ask(&[0xFF, 0x00]);
    bench.unlock();
}

/// The longest delay caps the doubling.
#[test]
fn the_delay_stops_growing_at_its_maximum() {
    let config = &CONFIG;
    let mut delay = 0;
    for wrong in 1..=30 {
        delay = config.unlock_delay_us(wrong);
    }
    assert_eq!(
        u64::from(delay),
        u64::from(config.unlock_delay_max_ms) * 1_000
    );
}

/// A DTO the bus queue refuses is counted, and the master hears of it once per episode:
/// one EV_DAQ_OVERLOAD ahead of the next DTO that goes out.
#[test]
fn lost_daq_packets_are_counted_and_announced_once_per_episode() {
    let mut bench = Bench::unlocked();
    start_two_odt_list(&mut bench, false);
    let refuse = |bench: &mut Bench| {
        bench
            .slave
            .event(&bench.target, 0, bench.now_us, &mut |_: &[u8]| false)
    };
    assert_eq!(refuse(&mut bench).dropped, 2);
    assert_eq!(refuse(&mut bench).dropped, 2);
    let mut sent = Vec::new();
    let report = bench
        .slave
        .event(&bench.target, 0, bench.now_us, &mut |packet: &[u8]| {
            sent.push(packet.to_vec());
            true
        });
    assert_eq!(sent[0], [pid::EV, ev::DAQ_OVERLOAD]);
    assert_eq!(sent.len(), 3, "the event, then both ODTs");
    assert_eq!(report.sent, 2, "DAQ packets: the event is not one");
    assert_eq!(bench.event(0).len(), 2, "no event without a new loss");
    let counters = bench.slave.counters();
    assert_eq!(counters.dtos_dropped, 4);
    assert_eq!(counters.overloads, 1);
    // The counters as the ECU publishes them (aer_xcp::status).
    let status = bench.slave.status_bytes();
    let counter = |name: &str| {
        let field = aer_xcp::status::FIELDS
            .iter()
            .find(|f| f.name == name)
            .expect(name);
        let at = field.offset as usize;
        u32::from_le_bytes(status[at..at + 4].try_into().unwrap())
    };
    assert_eq!(counter("dtos_dropped"), 4);
    assert_eq!(counter("overloads"), 1);
    assert_eq!(counter("dtos_sent"), counters.dtos_sent);
}

/// The status block's fields tile it exactly, each where [`aer_xcp::LastRefusal::to_bytes`]
/// and the counters put it.
#[test]
fn the_status_fields_tile_the_block() {
    use aer_xcp::status::{FIELDS, Kind, STATUS_LEN};
    let mut end = 0;
    for field in FIELDS {
        let size = match field.kind {
            Kind::U8 => 1,
            Kind::U16 => 2,
            Kind::U32 | Kind::F32 => 4,
        };
        assert_eq!(field.offset % size, 0, "{}: aligned", field.name);
        assert!(field.offset as usize >= end, "{} overlaps", field.name);
        end = field.offset as usize + size as usize;
    }
    assert_eq!(end, STATUS_LEN);
    let refusal = aer_xcp::LastRefusal {
        count: 0x0102_0304,
        command: 0xF0,
        error: 0x22,
        detail: aer_xcp::Detail {
            reason: reason::ABOVE_MAX,
            item: 0x0605,
            element: 7,
            value: 1.5,
            limit: -2.5,
        },
    };
    let bytes = refusal.to_bytes();
    let at = |name: &str| FIELDS.iter().find(|f| f.name == name).expect(name).offset as usize;
    assert_eq!(
        bytes[at("refusals")..at("refusals") + 4],
        0x0102_0304u32.to_le_bytes()
    );
    assert_eq!(bytes[at("refused_command")], 0xF0);
    assert_eq!(bytes[at("refused_error")], 0x22);
    assert_eq!(bytes[at("refused_reason")], reason::ABOVE_MAX);
    assert_eq!(bytes[at("refused_element")], 7);
    assert_eq!(bytes[at("refused_item")..at("refused_item") + 2], [5, 6]);
    assert_eq!(
        bytes[at("refused_value")..at("refused_value") + 4],
        1.5f32.to_le_bytes()
    );
    assert_eq!(
        bytes[at("refused_limit")..at("refused_limit") + 4],
        (-2.5f32).to_le_bytes()
    );
}

/// A refusal's command and code, and the reason the slave itself knows, are published.
#[test]
fn the_last_refusal_names_the_command_and_why() {
    let mut bench = Bench::connected();
    bench.set_mta(CAL);
    assert_eq!(bench.ask(&[0xF0, 1, 5]), [0xFE, 0x25]);
    let last = bench.slave.last_refusal();
    assert_eq!((last.command, last.error), (0xF0, 0x25));
    assert_eq!(last.detail.reason, reason::LOCKED);
    assert_eq!(last.count, 1);
}
