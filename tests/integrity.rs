//! Rolling counters and checksums as the schema declares them (`CounterStep`,
//! `ChecksumAlgorithm`): the generated metadata places them where the signals are, `seal`
//! fills them as a sender must, and `verify` refuses a wrong checksum, a repeated counter and
//! a skipped one.

use aer::can::{CcmStatus, ImdInfoGeneral, Mcu1, Mcu2, Vcu1};
use aer::runtime::{ChecksumAlgorithm, CounterCheck, CounterSender, IntegrityError};
use proptest::prelude::*;

#[test]
fn the_schema_declares_the_cars_counters_and_vcu1s_checksum() {
    let counter = |meta: &aer::runtime::MessageMeta| meta.counter.map(|c| (c.signal, c.step));
    assert_eq!(counter(Vcu1::META), Some(("VCU_RollingCounter", 1)));
    assert_eq!(counter(Mcu1::META), Some(("MCU1_RollingCounter", 1)));
    assert_eq!(counter(Mcu2::META), Some(("MCU2_RollingCounter", 1)));
    assert_eq!(counter(CcmStatus::META), Some(("CCM_RollingCounter", 1)));
    let checksum = Vcu1::META.checksum.expect("VCU1 has a checksum");
    assert_eq!(
        (checksum.signal, checksum.byte, checksum.algorithm),
        ("VCU_CheckSum", 7, ChecksumAlgorithm::SumXorFf)
    );
    // A message without them is sealed and verified as it is.
    assert_eq!(ImdInfoGeneral::META.counter, None);
    assert_eq!(ImdInfoGeneral::META.checksum, None);
}

#[test]
fn the_algorithms_match_their_definitions() {
    // CRC-8/SAE-J1850's catalogued check value.
    assert_eq!(
        ChecksumAlgorithm::Crc8SaeJ1850.compute(b"123456789".iter()),
        0x4B
    );
    // 0x01 + 0x02 + 0xFF = 0x102: 0x02 mod 256, XOR 0xFF.
    assert_eq!(
        ChecksumAlgorithm::SumXorFf.compute([0x01, 0x02, 0xFF].iter()),
        0xFD
    );
    assert_eq!(ChecksumAlgorithm::SumXorFf.compute([].iter()), 0xFF);
}

#[test]
fn the_counter_lands_in_the_signal_the_decoder_reads() {
    // MCU1's counter is a 4-bit Motorola signal: what seal writes, decode reads back.
    let mut sender = CounterSender::default();
    for expected in (0..16u8).chain(0..3) {
        let mut data = [0u8; 8];
        Mcu1::META.seal(&mut sender, &mut data);
        assert_eq!(Mcu1::decode(&data).unwrap().mcu1_rolling_counter, expected);
        assert_eq!(Mcu1::META.counter.unwrap().read(&data), expected);
    }
    // CCM_Status's is Intel, 4 bits at 48.
    let mut sender = CounterSender::default();
    let mut data = [0xFFu8; 8];
    CcmStatus::META.seal(&mut sender, &mut data);
    assert_eq!(CcmStatus::decode(&data).unwrap().ccm_rolling_counter, 0);
    assert_eq!(data[6], 0xF0, "only the counter's bits change");
}

#[test]
fn verify_refuses_a_repeat_a_skip_and_a_bad_checksum() {
    let mut sender = CounterSender::default();
    let mut check = CounterCheck::default();
    let frames: Vec<[u8; 8]> = (0..4)
        .map(|i| {
            let mut data = [i as u8 * 10, 0, 0, 0, 0, 0, 0, 0];
            Vcu1::META.seal(&mut sender, &mut data);
            data
        })
        .collect();
    assert_eq!(Vcu1::META.verify(&mut check, &frames[0]), Ok(()));
    assert_eq!(Vcu1::META.verify(&mut check, &frames[1]), Ok(()));
    assert_eq!(
        Vcu1::META.verify(&mut check, &frames[1]),
        Err(IntegrityError::CounterRepeated {
            message: "VCU1",
            value: 1
        })
    );
    // Frame 2 lost: 3 is refused, and the one after it is in sequence again.
    assert_eq!(
        Vcu1::META.verify(&mut check, &frames[3]),
        Err(IntegrityError::CounterJumped {
            message: "VCU1",
            expected: 2,
            found: 3
        })
    );
    let mut next = [40u8, 0, 0, 0, 0, 0, 0, 0];
    Vcu1::META.seal(&mut sender, &mut next);
    assert_eq!(Vcu1::META.verify(&mut check, &next), Ok(()));
    let mut corrupted = next;
    corrupted[0] ^= 0x04;
    assert!(matches!(
        Vcu1::META.verify(&mut CounterCheck::default(), &corrupted),
        Err(IntegrityError::Checksum { .. })
    ));
    check.reset();
    assert_eq!(
        Vcu1::META.verify(&mut check, &frames[0]),
        Ok(()),
        "after a reset"
    );
}

proptest! {
    #[test]
    fn a_sealed_stream_verifies_and_any_single_bit_error_is_caught(
        payloads in prop::collection::vec(any::<[u8; 8]>(), 1..40),
        flip in 0usize..64,
    ) {
        let mut sender = CounterSender::default();
        let mut check = CounterCheck::default();
        for payload in &payloads {
            let mut data = *payload;
            Vcu1::META.seal(&mut sender, &mut data);
            prop_assert_eq!(Vcu1::META.verify(&mut check, &data), Ok(()));
            // One flipped bit anywhere fails the checksum (a sum changes with any one bit).
            let mut flipped = data;
            flipped[flip / 8] ^= 1 << (flip % 8);
            prop_assert!(Vcu1::META.verify(&mut CounterCheck::default(), &flipped).is_err());
        }
    }
}

#[test]
fn every_periodic_message_has_one_freshness_limit_from_the_schema() {
    use aer::can::{ImdRequest, MESSAGES, OrionLimits, PccStatus};
    // Declared (AerTimeoutMs): the PCC's status, 10 frames of 10 ms.
    assert_eq!(PccStatus::TIMEOUT_MS, 100);
    // Otherwise five cycle times.
    assert_eq!(Mcu1::TIMEOUT_MS, 5 * Mcu1::CYCLE_TIME_MS);
    assert_eq!(OrionLimits::TIMEOUT_MS, 500);
    for meta in MESSAGES {
        match (meta.cycle_time_ms, meta.timeout_ms) {
            (Some(cycle), Some(limit)) => assert!(limit >= 2 * cycle, "{}", meta.name),
            (None, None) => {}
            other => panic!("{}: cycle and limit {other:?}", meta.name),
        }
    }
    // Sent on demand: no limit.
    assert_eq!(ImdRequest::META.timeout_ms, None);
}
