//! Sender and receiver against each other: every length, block size and STmin; lost,
//! repeated and corrupted frames; timeouts.

use aer_isotp::{Config, Received, Receiver, RxError, SendError, Sender, StMin};
use proptest::prelude::*;

const BIG: usize = aer_isotp::MAX_PAYLOAD;

/// What happened to one transfer.
#[derive(Debug, PartialEq)]
enum Outcome {
    Delivered(Vec<u8>),
    SenderFailed(SendError),
    ReceiverFailed(RxError),
}

/// Frame faults to inject on the data path, by frame index.
#[derive(Debug, Clone, Default)]
struct Faults {
    drop: Option<usize>,
    repeat: Option<usize>,
}

/// Moves one message from a sender to a receiver over a lossless (or faulty) link, with a
/// clock that advances 50 us per frame and whatever STmin asks.
fn transfer(config: Config, payload: &[u8], faults: &Faults) -> Outcome {
    let mut sender: Sender<BIG> = Sender::new(config);
    let mut receiver: Receiver<BIG> = Receiver::new(config);
    if let Err(error) = sender.start(payload) {
        return Outcome::SenderFailed(error);
    }
    let mut now: u32 = 0xFFFF_0000; // crosses the u32 wrap during long transfers
    let mut index = 0usize;
    for _ in 0..100_000 {
        let frame = match sender.poll(now) {
            Ok(Some(frame)) => frame,
            Ok(None) if sender.is_idle() => break,
            Ok(None) => {
                now = now.wrapping_add(100);
                if let Err(error) = receiver.poll(now) {
                    return Outcome::ReceiverFailed(error);
                }
                continue;
            }
            Err(error) => return Outcome::SenderFailed(error),
        };
        sender.sent(now);
        let copies = if faults.drop == Some(index) {
            0
        } else if faults.repeat == Some(index) {
            2
        } else {
            1
        };
        index += 1;
        for _ in 0..copies {
            match receiver.on_frame(frame.as_slice(), now) {
                Ok(Received::Message(message)) => return Outcome::Delivered(message.to_vec()),
                Ok(Received::FlowControl(reply)) => {
                    if let Err(error) = sender.on_flow_control(reply.as_slice(), now) {
                        return Outcome::SenderFailed(error);
                    }
                }
                Ok(Received::Nothing) => {}
                Err(error) => return Outcome::ReceiverFailed(error),
            }
        }
        now = now.wrapping_add(50);
    }
    // The sender finished (or stalled) without the receiver completing: run the clock out.
    now = now.wrapping_add(config.timeout_us + 1);
    match (receiver.poll(now), sender.poll(now)) {
        (Err(error), _) => Outcome::ReceiverFailed(error),
        (_, Err(error)) => Outcome::SenderFailed(error),
        _ => Outcome::ReceiverFailed(RxError::Timeout),
    }
}

fn config(block_size: u8, st_min: u8, padded: bool) -> Config {
    Config {
        padding: padded.then_some(0xCC),
        block_size,
        st_min: StMin::from_raw(st_min),
        ..Config::CAR
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(600))]

    #[test]
    fn every_message_arrives_intact(
        payload in prop::collection::vec(any::<u8>(), 1..=BIG),
        block_size in prop_oneof![Just(0u8), 1u8..=16],
        st_min in prop_oneof![Just(0u8), 0u8..=3, 0xF1u8..=0xF9],
        padded in any::<bool>(),
    ) {
        let outcome = transfer(config(block_size, st_min, padded), &payload, &Faults::default());
        prop_assert_eq!(outcome, Outcome::Delivered(payload));
    }

    /// A lost or repeated consecutive frame is detected; a wrong message is never delivered.
    #[test]
    fn lost_or_repeated_frames_never_deliver_a_wrong_message(
        payload in prop::collection::vec(any::<u8>(), 8..=600),
        block_size in prop_oneof![Just(0u8), 1u8..=8],
        lose in any::<bool>(),
        at in any::<prop::sample::Index>(),
    ) {
        let frames = 1 + (payload.len() - 6).div_ceil(7);
        let index = 1 + at.index(frames - 1); // a consecutive frame, never the first
        let faults = if lose {
            Faults { drop: Some(index), ..Faults::default() }
        } else {
            Faults { repeat: Some(index), ..Faults::default() }
        };
        match transfer(config(block_size, 0, true), &payload, &faults) {
            // Only a repeat of the very last frame can leave a complete message behind it,
            // and then the message is the right one.
            Outcome::Delivered(message) => {
                prop_assert!(!lose && index == frames - 1, "delivered despite {:?}", faults);
                prop_assert_eq!(message, payload);
            }
            Outcome::ReceiverFailed(RxError::Sequence { .. } | RxError::Timeout) => {}
            // Losing the frame just before a flow control stalls the sender instead.
            Outcome::SenderFailed(SendError::Timeout) => {}
            other => prop_assert!(false, "unexpected {other:?}"),
        }
    }

    #[test]
    fn arbitrary_frames_never_panic_the_receiver(frames in prop::collection::vec(prop::collection::vec(any::<u8>(), 0..=8), 1..50)) {
        let mut receiver: Receiver<64> = Receiver::new(Config::CAR);
        for (i, frame) in frames.iter().enumerate() {
            if let Ok(Received::Message(message)) = receiver.on_frame(frame, i as u32 * 100) {
                prop_assert!(!message.is_empty() && message.len() <= 64);
            }
        }
    }
}

#[test]
fn the_telemetry_packet_takes_one_first_frame_and_eight_consecutive_frames() {
    let payload: Vec<u8> = (0..62).collect();
    let mut sender: Sender<64> = Sender::new(Config::CAR);
    sender.start(&payload).unwrap();
    let first = sender.poll(0).unwrap().unwrap();
    assert_eq!(&first.as_slice()[..2], &[0x10, 62]);
    sender.sent(0);
    assert_eq!(sender.poll(10).unwrap(), None, "waits for flow control");
    sender
        .on_flow_control(&[0x30, 0, 0, 0xCC, 0xCC, 0xCC, 0xCC, 0xCC], 20)
        .unwrap();
    let mut sequence = Vec::new();
    while let Some(frame) = sender.poll(30).unwrap() {
        sequence.push(frame.as_slice()[0]);
        assert_eq!(frame.as_slice().len(), 8, "padded");
        sender.sent(30);
    }
    assert_eq!(sequence, [0x21, 0x22, 0x23, 0x24, 0x25, 0x26, 0x27, 0x28]);
    assert!(sender.is_idle());
}

#[test]
fn sequence_numbers_wrap_from_15_to_0() {
    let payload = vec![0xAB; 6 + 7 * 17];
    let mut sender: Sender<256> = Sender::new(Config::CAR);
    sender.start(&payload).unwrap();
    sender.poll(0).unwrap();
    sender.sent(0);
    sender.on_flow_control(&[0x30, 0, 0], 0).unwrap();
    let mut sequence = Vec::new();
    while let Some(frame) = sender.poll(0).unwrap() {
        sequence.push(frame.as_slice()[0] & 0x0F);
        sender.sent(0);
    }
    assert_eq!(&sequence[13..], &[14, 15, 0, 1]);
}

#[test]
fn st_min_spaces_consecutive_frames() {
    let mut sender: Sender<64> = Sender::new(Config::CAR);
    sender.start(&[1; 30]).unwrap();
    sender.poll(0).unwrap();
    sender.sent(0);
    sender.on_flow_control(&[0x30, 0, 0xF5], 1_000).unwrap(); // 500 us
    assert!(sender.poll(1_000).unwrap().is_some());
    sender.sent(1_000);
    assert!(sender.poll(1_499).unwrap().is_none(), "1 us before STmin");
    assert!(sender.poll(1_500).unwrap().is_some(), "at STmin");
}

#[test]
fn block_size_makes_the_sender_wait_for_the_next_flow_control() {
    let mut sender: Sender<64> = Sender::new(Config::CAR);
    sender.start(&[1; 40]).unwrap();
    sender.poll(0).unwrap();
    sender.sent(0);
    sender.on_flow_control(&[0x30, 2, 0], 0).unwrap();
    for _ in 0..2 {
        assert!(sender.poll(0).unwrap().is_some());
        sender.sent(0);
    }
    assert_eq!(sender.poll(0).unwrap(), None, "block of 2 done");
    sender.on_flow_control(&[0x30, 2, 0], 5).unwrap();
    assert!(sender.poll(5).unwrap().is_some());
}

#[test]
fn no_flow_control_times_out_just_after_n_bs() {
    let mut sender: Sender<64> = Sender::new(Config::CAR);
    sender.start(&[1; 20]).unwrap();
    sender.poll(0).unwrap();
    sender.sent(0);
    assert_eq!(sender.poll(1_000_000), Ok(None), "at N_Bs");
    assert_eq!(sender.poll(1_000_001), Err(SendError::Timeout));
    assert!(sender.is_idle());
}

#[test]
fn wait_overflow_and_too_many_waits_end_the_message() {
    let mut sender: Sender<64> = Sender::new(Config {
        max_waits: 1,
        ..Config::CAR
    });
    sender.start(&[1; 20]).unwrap();
    sender.poll(0).unwrap();
    sender.sent(0);
    sender.on_flow_control(&[0x31, 0, 0], 900_000).unwrap();
    assert_eq!(sender.poll(1_800_000), Ok(None), "WAIT restarted N_Bs");
    assert_eq!(
        sender.on_flow_control(&[0x31, 0, 0], 1_800_000),
        Err(SendError::TooManyWaits)
    );

    sender.start(&[1; 20]).unwrap();
    sender.poll(0).unwrap();
    sender.sent(0);
    assert_eq!(
        sender.on_flow_control(&[0x32, 0, 0], 1),
        Err(SendError::Overflow)
    );
}

#[test]
fn the_sender_refuses_empty_oversized_and_overlapping_messages() {
    let mut sender: Sender<64> = Sender::new(Config::CAR);
    assert_eq!(sender.start(&[]), Err(SendError::Length(0)));
    assert_eq!(sender.start(&[0; 65]), Err(SendError::Length(65)));
    let mut big: Sender<5000> = Sender::new(Config::CAR);
    assert_eq!(big.start(&[0; 4096]), Err(SendError::Length(4096)));
    sender.start(&[1; 20]).unwrap();
    assert_eq!(sender.start(&[1; 20]), Err(SendError::Busy));
}

#[test]
fn the_receiver_answers_overflow_to_a_message_it_cannot_hold() {
    let mut receiver: Receiver<64> = Receiver::new(Config::CAR);
    let Err(RxError::TooLong {
        length: 100,
        reply: Some(reply),
    }) = receiver.on_frame(&[0x10, 100, 1, 2, 3, 4, 5, 6], 0)
    else {
        panic!("expected TooLong");
    };
    assert_eq!(&reply.as_slice()[..3], &[0x32, 0, 0]);
}

#[test]
fn the_receiver_times_out_one_us_after_n_cr_and_counts_interruptions() {
    let mut receiver: Receiver<64> = Receiver::new(Config::CAR);
    receiver.on_frame(&[0x10, 20, 1, 2, 3, 4, 5, 6], 0).unwrap();
    assert_eq!(receiver.poll(1_000_000), Ok(()));
    assert_eq!(receiver.poll(1_000_001), Err(RxError::Timeout));
    assert_eq!(
        receiver.on_frame(&[0x21, 7, 8, 9, 10, 11, 12, 13], 1_000_002),
        Err(RxError::UnexpectedConsecutive)
    );

    receiver.on_frame(&[0x10, 20, 1, 2, 3, 4, 5, 6], 0).unwrap();
    assert!(!receiver.take_interrupted());
    let single = receiver.on_frame(&[0x02, 9, 9], 10).unwrap();
    assert_eq!(single, Received::Message(&[9, 9]));
    assert!(
        receiver.take_interrupted(),
        "the partial message was dropped and counted"
    );
    assert!(!receiver.take_interrupted());
}

#[test]
fn a_message_that_timed_out_is_counted_when_the_next_one_starts() {
    // What a CCM that stopped mid-packet and resumed sends: the partial packet times out with
    // no consecutive frame to report it, then a first frame starts the next one.
    let mut receiver: Receiver<64> = Receiver::new(Config::CAR);
    receiver.on_frame(&[0x10, 20, 1, 2, 3, 4, 5, 6], 0).unwrap();
    let next = receiver.on_frame(&[0x10, 20, 1, 2, 3, 4, 5, 6], 2_000_000);
    assert!(
        matches!(next, Ok(Received::FlowControl(_))),
        "the new one is taken"
    );
    assert!(receiver.take_interrupted(), "the timed-out one is counted");
    assert!(!receiver.take_interrupted());
    // A timed-out message is counted once: reported by `poll`, the next first frame adds
    // nothing.
    assert_eq!(receiver.poll(4_000_000), Err(RxError::Timeout));
    receiver
        .on_frame(&[0x10, 20, 1, 2, 3, 4, 5, 6], 4_000_001)
        .unwrap();
    assert!(!receiver.take_interrupted());
}
