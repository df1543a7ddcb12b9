//! Every command against the fake ECU: positive responses byte for byte as the standard lays
//! them out, and each error path with the code a master reacts to.

mod common;

use aer_xcp::crc16_ccitt;
use common::*;

// ---------------------------------------------------------------------------------------------
// Session
// ---------------------------------------------------------------------------------------------

#[test]
fn connect_announces_resources_and_sizes() {
    let mut bench = Bench::new();
    // RESOURCE: CAL/PAG + DAQ; COMM_MODE_BASIC: Intel, byte granularity, OPTIONAL; MAX_CTO 8;
    // MAX_DTO 8 (u16, Intel); protocol and transport layer version 1.
    assert_eq!(
        bench.ask(&[0xFF, 0x00]),
        [0xFF, 0x05, 0x80, 0x08, 0x08, 0x00, 0x01, 0x01]
    );
    assert!(bench.slave.is_connected());
    assert!(bench.slave.is_calibration_locked());
}

#[test]
fn connect_with_bad_mode_or_too_short_is_refused() {
    let mut bench = Bench::new();
    assert_eq!(bench.ask(&[0xFF, 0x07]), [0xFE, 0x22]);
    assert_eq!(bench.ask(&[0xFF]), [0xFE, 0x21]);
    assert!(!bench.slave.is_connected());
    // User-defined mode 1 connects like normal mode.
    assert_eq!(bench.ask(&[0xFF, 0x01])[0], 0xFF);
}

#[test]
fn commands_before_connect_and_after_disconnect_are_ignored() {
    let mut bench = Bench::new();
    assert_eq!(bench.cmd(&[0xFD]), None);
    assert_eq!(bench.cmd(&[0xF5, 4]), None);
    assert_eq!(bench.cmd(&[]), None);
    assert_eq!(
        bench.slave.counters().commands,
        0,
        "ignored packets are not counted"
    );
    bench.ask(&[0xFF, 0]);
    assert_eq!(bench.ask(&[0xFE]), [0xFF]);
    assert!(!bench.slave.is_connected());
    assert_eq!(bench.cmd(&[0xFD]), None);
}

#[test]
fn get_status_reports_protection_daq_and_store_request() {
    let mut bench = Bench::connected();
    // SESSION_STATUS, RESOURCE_PROTECTION (CAL/PAG locked), STATE_NUMBER, SESSION_CONFIG_ID.
    assert_eq!(bench.ask(&[0xFD]), [0xFF, 0x00, 0x01, 0x00, 0x00, 0x00]);
    bench.unlock();
    assert_eq!(bench.ask(&[0xFD]), [0xFF, 0x00, 0x00, 0x00, 0x00, 0x00]);
    bench.target.store_pending = true;
    start_two_odt_list(&mut bench, false);
    assert_eq!(bench.ask(&[0xFD]), [0xFF, 0x41, 0x00, 0x00, 0x00, 0x00]);
}

#[test]
fn synch_answers_err_cmd_synch() {
    let mut bench = Bench::connected();
    assert_eq!(bench.ask(&[0xFC]), [0xFE, 0x00]);
}

#[test]
fn get_comm_mode_info_offers_master_block_mode() {
    let mut bench = Bench::connected();
    // reserved, COMM_MODE_OPTIONAL (master block mode), reserved, MAX_BS 8, MIN_ST 0,
    // QUEUE_SIZE 0, driver version.
    assert_eq!(
        bench.ask(&[0xFB]),
        [0xFF, 0x00, 0x01, 0x00, 0x08, 0x00, 0x00, 0x10]
    );
}

#[test]
fn unknown_and_unsupported_commands_answer_err_cmd_unknown() {
    let mut bench = Bench::connected();
    for code in [0xC0, 0xEC, 0xEE, 0xF2, 0xF1, 0xDB, 0xD8, 0xC7, 0x00, 0x42] {
        assert_eq!(
            bench.ask(&[code, 0, 0, 0]),
            [0xFE, 0x20],
            "command {code:02X}"
        );
    }
    assert!(bench.slave.is_connected(), "the slave keeps running");
}

#[test]
fn short_long_and_empty_packets_answer_err_cmd_syntax() {
    let mut bench = Bench::connected();
    assert_eq!(bench.ask(&[]), [0xFE, 0x21]);
    assert_eq!(
        bench.ask(&[0xF6, 0, 0, 0, 1]),
        [0xFE, 0x21],
        "SET_MTA without its address"
    );
    assert_eq!(bench.ask(&[0xF5]), [0xFE, 0x21], "UPLOAD without its count");
    assert_eq!(
        bench.ask(&[0xE1, 0xFF, 2, 0]),
        [0xFE, 0x21],
        "WRITE_DAQ without its address"
    );
    assert_eq!(
        bench.ask(&[0xFA, 0, 0, 0, 0, 0, 0, 0, 0]),
        [0xFE, 0x21],
        "nine bytes"
    );
    assert_eq!(bench.slave.counters().errors, 5);
}

#[test]
fn get_id_answers_lengths_and_texts_are_uploaded() {
    let mut bench = Bench::connected();
    let text = |bench: &mut Bench, kind: u8| -> Vec<u8> {
        let answer = bench.ask(&[0xFA, kind]);
        assert_eq!(
            answer[..4],
            [0xFF, 0x00, 0x00, 0x00],
            "mode 0: upload from the MTA"
        );
        let len = u32::from_le_bytes(answer[4..8].try_into().unwrap()) as usize;
        let mut out = Vec::new();
        while out.len() < len {
            let chunk = (len - out.len()).min(7) as u8;
            let data = bench.ask(&[0xF5, chunk]);
            assert_eq!(data[0], 0xFF);
            out.extend_from_slice(&data[1..]);
        }
        out
    };
    assert_eq!(text(&mut bench, 0), b"AER CCM");
    assert_eq!(text(&mut bench, 1), b"aer_ccm");
    assert_eq!(text(&mut bench, 5), EPK);
    assert_eq!(text(&mut bench, 4), b"", "no A2L to upload: length 0");
    // Reading past the text's end is out of range.
    bench.ask(&[0xFA, 0]);
    assert_eq!(bench.ask(&[0xF5, 6]), [&[0xFF][..], b"AER CC"].concat());
    assert_eq!(bench.ask(&[0xF5, 2]), [0xFE, 0x22]);
}

// ---------------------------------------------------------------------------------------------
// Reading
// ---------------------------------------------------------------------------------------------

#[test]
fn upload_reads_the_working_page_and_advances_the_mta() {
    let mut bench = Bench::connected();
    bench.set_mta(CAL);
    let first = bench.ask(&[0xF5, 7]);
    assert_eq!(first[0], 0xFF);
    assert_eq!(first[1..], bench.target.working[..7]);
    let second = bench.ask(&[0xF5, 3]);
    assert_eq!(second[1..], bench.target.working[7..10]);
}

#[test]
fn upload_sizes_outside_one_packet_are_out_of_range() {
    let mut bench = Bench::connected();
    bench.set_mta(CAL);
    assert_eq!(bench.ask(&[0xF5, 0]), [0xFE, 0x22]);
    assert_eq!(bench.ask(&[0xF5, 8]), [0xFE, 0x22]);
    assert_eq!(bench.ask(&[0xF5, 255]), [0xFE, 0x22]);
}

#[test]
fn unmapped_reads_are_access_denied() {
    let mut bench = Bench::connected();
    bench.set_mta(0x0004_0000);
    assert_eq!(bench.ask(&[0xF5, 4]), [0xFE, 0x24]);
    // Straddling the end of the page is not mapped either.
    bench.set_mta(CAL + CAL_LEN as u32 - 2);
    assert_eq!(bench.ask(&[0xF5, 4]), [0xFE, 0x24]);
    // Another address extension.
    let a = le32(CAL);
    assert_eq!(
        bench.ask(&[0xF4, 1, 0, 7, a[0], a[1], a[2], a[3]]),
        [0xFE, 0x24]
    );
    // The end of the address space does not wrap.
    let a = le32(u32::MAX - 1);
    assert_eq!(
        bench.ask(&[0xF4, 4, 0, 0, a[0], a[1], a[2], a[3]]),
        [0xFE, 0x22]
    );
}

#[test]
fn short_upload_reads_measurements_and_the_epk_by_address() {
    let mut bench = Bench::connected();
    let a = le32(MEAS + 3);
    let answer = bench.ask(&[0xF4, 4, 0, 0, a[0], a[1], a[2], a[3]]);
    assert_eq!(answer[1..], bench.target.measurement[3..7]);
    // The MTA now follows the uploaded bytes.
    assert_eq!(bench.ask(&[0xF5, 2])[1..], bench.target.measurement[7..9]);
    let a = le32(EPK_ADDR);
    assert_eq!(
        bench.ask(&[0xF4, 7, 0, 0, a[0], a[1], a[2], a[3]])[1..],
        EPK[..7]
    );
}

#[test]
fn the_reference_page_is_read_when_xcp_accesses_page_1() {
    let mut bench = Bench::unlocked();
    bench.set_mta(CAL);
    assert_eq!(bench.ask(&[0xF0, 1, 77]), [0xFF]);
    assert_eq!(bench.target.working[0], 77);
    assert_eq!(
        bench.ask(&[0xEB, 0x02, 0, 1]),
        [0xFF],
        "XCP page := reference"
    );
    bench.set_mta(CAL);
    assert_eq!(
        bench.ask(&[0xF5, 1]),
        [0xFF, 50],
        "reference keeps the default"
    );
    assert!(
        bench
            .target
            .reads
            .borrow()
            .iter()
            .any(|read| read.page == 1 && read.accepted)
    );
    assert_eq!(bench.ask(&[0xEB, 0x02, 0, 0]), [0xFF]);
    bench.set_mta(CAL);
    assert_eq!(bench.ask(&[0xF5, 1]), [0xFF, 77]);
}

#[test]
fn build_checksum_is_crc16_ccitt_over_the_block_and_advances_the_mta() {
    assert_eq!(
        crc16_ccitt(b"123456789"),
        0x29B1,
        "CRC-16/CCITT-FALSE check value"
    );
    let mut bench = Bench::connected();
    bench.set_mta(CAL);
    let answer = bench.ask(&[0xF3, 0, 0, 0, 20, 0, 0, 0]);
    let crc = crc16_ccitt(&bench.target.working[..20]);
    let c = (crc as u32).to_le_bytes();
    assert_eq!(answer, [0xFF, 0x08, 0x00, 0x00, c[0], c[1], c[2], c[3]]);
    assert_eq!(bench.ask(&[0xF5, 2])[1..], bench.target.working[20..22]);
}

#[test]
fn build_checksum_refuses_big_blocks_with_the_limit_and_unmapped_ones() {
    let mut bench = Bench::connected();
    bench.set_mta(CAL);
    assert_eq!(
        bench.ask(&[0xF3, 0, 0, 0, 0x01, 0x01, 0, 0]),
        [0xFE, 0x22, 0, 0, 0x00, 0x01, 0x00, 0x00]
    );
    assert_eq!(
        bench.ask(&[0xF3, 0, 0, 0, 33, 0, 0, 0]),
        [0xFE, 0x24],
        "past the page"
    );
}

// ---------------------------------------------------------------------------------------------
// Seed and key
// ---------------------------------------------------------------------------------------------

#[test]
fn unlock_with_the_right_key_over_two_packets() {
    let mut bench = Bench::connected();
    bench.unlock();
    assert!(!bench.slave.is_calibration_locked());
    // Unlocked: another seed request answers length 0.
    assert_eq!(bench.ask(&[0xF8, 0x00, 0x01]), [0xFF, 0x00]);
}

#[test]
fn a_wrong_key_answers_access_locked_and_ends_the_session() {
    let mut bench = Bench::connected();
    let seed = bench.ask(&[0xF8, 0x00, 0x01]);
    let mut key = FakeTarget::key_for(&seed[2..]);
    key[7] ^= 1;
    assert_eq!(
        bench.ask(&[&[0xF7, 8][..], &key[..6]].concat()),
        [0xFF, 0x01]
    );
    assert_eq!(
        bench.ask(&[&[0xF7, 2][..], &key[6..]].concat()),
        [0xFE, 0x25]
    );
    assert!(!bench.slave.is_connected());
    assert_eq!(bench.cmd(&[0xFD]), None);
    bench.ask(&[0xFF, 0]);
    assert!(
        bench.slave.is_calibration_locked(),
        "a new session starts locked"
    );
}

#[test]
fn unlock_sequence_errors() {
    let mut bench = Bench::connected();
    assert_eq!(bench.ask(&[0xF7, 2, 1, 2]), [0xFE, 0x29], "no seed yet");
    assert_eq!(
        bench.ask(&[0xF8, 0x01, 0x01]),
        [0xFE, 0x29],
        "remaining part without a first"
    );
    let seed = bench.ask(&[0xF8, 0x00, 0x01]);
    assert_eq!(
        bench.ask(&[0xF8, 0x01, 0x01]),
        [0xFF, 0x00],
        "the whole seed fit the first part"
    );
    let key = FakeTarget::key_for(&seed[2..]);
    assert_eq!(
        bench.ask(&[&[0xF7, 8][..], &key[..6]].concat()),
        [0xFF, 0x01]
    );
    // The second part announces the wrong remaining length.
    assert_eq!(
        bench.ask(&[&[0xF7, 3][..], &key[6..], &[0][..]].concat()),
        [0xFE, 0x29]
    );
    assert!(
        bench.slave.is_connected(),
        "a sequence error does not end the session"
    );
    assert_eq!(
        bench.ask(&[&[0xF7, 2][..], &key[6..]].concat()),
        [0xFE, 0x29],
        "seed consumed"
    );
    assert_eq!(bench.ask(&[0xF8, 0x00, 0x01])[0], 0xFF);
    assert_eq!(
        bench.ask(&[0xF7, 33, 0, 0, 0, 0, 0, 0]),
        [0xFE, 0x22],
        "key longer than 32"
    );
}

#[test]
fn get_seed_for_unprotected_and_unknown_resources() {
    let mut bench = Bench::connected();
    assert_eq!(
        bench.ask(&[0xF8, 0x00, 0x04]),
        [0xFF, 0x00],
        "DAQ is not protected"
    );
    assert_eq!(bench.ask(&[0xF8, 0x00, 0x10]), [0xFE, 0x22], "no PGM");
    assert_eq!(
        bench.ask(&[0xF8, 0x00, 0x05]),
        [0xFE, 0x22],
        "one resource at a time"
    );
    assert_eq!(bench.ask(&[0xF8, 0x02, 0x01]), [0xFE, 0x22], "no such mode");
}

#[test]
fn locked_calibration_refuses_every_change() {
    let mut bench = Bench::connected();
    let before = bench.target.working;
    bench.set_mta(CAL);
    let a = le32(CAL);
    assert_eq!(bench.ask(&[0xF0, 1, 5]), [0xFE, 0x25]);
    assert_eq!(bench.ask(&[0xF0, 12, 1, 2, 3, 4, 5, 6]), [0xFE, 0x25]);
    // SHORT_DOWNLOAD is not offered at all (MAX_CTO 8 leaves it no room for data).
    assert_eq!(
        bench.ask(&[0xED, 1, 0, 0, a[0], a[1], a[2], a[3]]),
        [0xFE, 0x20]
    );
    assert_eq!(bench.ask(&[0xEB, 0x03, 0, 1]), [0xFE, 0x25]);
    assert_eq!(bench.ask(&[0xE4, 0, 1, 0, 0]), [0xFE, 0x25]);
    assert_eq!(bench.ask(&[0xF9, 0x01, 0, 0]), [0xFE, 0x25]);
    assert!(bench.target.writes.is_empty());
    assert_eq!(bench.target.page_calls, 0);
    assert_eq!(bench.target.working, before);
    // Reading stays open.
    assert_eq!(bench.ask(&[0xF5, 1]), [0xFF, 50]);
}

// ---------------------------------------------------------------------------------------------
// Writing
// ---------------------------------------------------------------------------------------------

#[test]
fn download_writes_and_advances_the_mta() {
    let mut bench = Bench::unlocked();
    bench.set_mta(CAL + 8);
    assert_eq!(bench.ask(&[0xF0, 2, 0x11, 0x22]), [0xFF]);
    assert_eq!(bench.ask(&[0xF0, 3, 0x33, 0x44, 0x55]), [0xFF]);
    assert_eq!(bench.target.working[8..13], [0x11, 0x22, 0x33, 0x44, 0x55]);
    assert_eq!(bench.target.writes.len(), 2);
}

#[test]
fn download_of_nothing_or_into_an_unmapped_address_is_refused() {
    let mut bench = Bench::unlocked();
    bench.set_mta(CAL);
    assert_eq!(bench.ask(&[0xF0, 0]), [0xFE, 0x22]);
    assert_eq!(
        bench.ask(&[0xF0, 4, 1, 2]),
        [0xFE, 0x21],
        "fewer bytes than announced"
    );
    bench.set_mta(MEAS);
    assert_eq!(
        bench.ask(&[0xF0, 1, 9]),
        [0xFE, 0x24],
        "measurements are read-only"
    );
    bench.ask(&[0xFA, 0]);
    assert_eq!(
        bench.ask(&[0xF0, 1, 9]),
        [0xFE, 0x24],
        "the MTA points at a text"
    );
}

#[test]
fn an_out_of_range_write_leaves_the_value() {
    let mut bench = Bench::unlocked();
    bench.set_mta(CAL + LIMITED as u32);
    assert_eq!(bench.ask(&[0xF0, 1, 150]), [0xFE, 0x22]);
    assert_eq!(bench.target.working[LIMITED], 50);
    // The MTA did not move: the retry with a good value lands on the same byte.
    assert_eq!(bench.ask(&[0xF0, 1, 99]), [0xFF]);
    assert_eq!(bench.target.working[LIMITED], 99);
}

#[test]
fn a_write_while_moving_is_write_protected_and_leaves_the_value() {
    let mut bench = Bench::unlocked();
    bench.target.moving = true;
    bench.set_mta(CAL + 1);
    assert_eq!(bench.ask(&[0xF0, 1, 9]), [0xFE, 0x23]);
    assert_eq!(bench.target.working[1], 1);
}

#[test]
fn writes_to_the_reference_page_are_write_protected() {
    let mut bench = Bench::unlocked();
    assert_eq!(bench.ask(&[0xEB, 0x02, 0, 1]), [0xFF]);
    bench.set_mta(CAL + 1);
    assert_eq!(bench.ask(&[0xF0, 1, 9]), [0xFE, 0x23]);
    assert!(bench.target.writes.is_empty());
    assert_eq!(bench.target.reference[1], 1);
}

#[test]
fn short_download_is_not_offered_at_max_cto_8() {
    // It would leave no room for data: the slave does not offer it (the A2L's OPTIONAL_CMD
    // list leaves it out), so a master learns so at once.
    let mut bench = Bench::unlocked();
    let a = le32(CAL + 1);
    assert_eq!(
        bench.ask(&[0xED, 1, 0, 0, a[0], a[1], a[2], a[3]]),
        [0xFE, 0x20]
    );
    assert!(bench.target.writes.is_empty());
}

/// The pedal pair moves from (100, 200) to (300, 400): valid together, invalid one by one.
fn pedal_block() -> Vec<u8> {
    let mut block = FakeTarget::new().working[..12].to_vec();
    block[PEDAL_REST..PEDAL_REST + 2].copy_from_slice(&300u16.to_le_bytes());
    block[PEDAL_FULL..PEDAL_FULL + 2].copy_from_slice(&400u16.to_le_bytes());
    block
}

#[test]
fn a_block_download_is_written_once_and_atomically() {
    let mut bench = Bench::unlocked();
    let block = pedal_block();
    bench.set_mta(CAL);
    assert_eq!(
        bench.cmd(&[&[0xF0, 12][..], &block[..6]].concat()),
        None,
        "no answer mid-block"
    );
    assert!(
        bench.target.writes.is_empty(),
        "nothing written before the block is complete"
    );
    assert_eq!(bench.ask(&[&[0xEF, 6][..], &block[6..]].concat()), [0xFF]);
    assert_eq!(bench.target.writes.len(), 1);
    assert_eq!(bench.target.writes[0], (0, CAL, block.clone(), true));
    assert_eq!(bench.target.working[..12], block[..]);
    // The halves alone would have been refused by the cross-check.
    let mut target = FakeTarget::new();
    assert_eq!(
        aer_xcp::Target::write(&mut target, 0, CAL, &block[..6]),
        Err(aer_xcp::Refusal::OutOfRange)
    );
}

#[test]
fn a_block_of_three_packets_and_the_mta_after_it() {
    let mut bench = Bench::unlocked();
    bench.set_mta(CAL + 16);
    let data: Vec<u8> = (0..14).map(|i| 0x60 + i).collect();
    assert_eq!(bench.cmd(&[&[0xF0, 14][..], &data[..6]].concat()), None);
    assert_eq!(bench.cmd(&[&[0xEF, 8][..], &data[6..12]].concat()), None);
    assert_eq!(bench.ask(&[&[0xEF, 2][..], &data[12..]].concat()), [0xFF]);
    assert_eq!(bench.target.working[16..30], data[..]);
    assert_eq!(bench.target.writes.len(), 1);
    assert_eq!(bench.ask(&[0xF5, 2])[1..], bench.target.working[30..32]);
}

#[test]
fn pyxcp_ends_a_7_to_11_byte_block_with_a_download() {
    // pyxcp's block downloader sends DOWNLOAD(8, six bytes) then DOWNLOAD(2, two bytes).
    let mut bench = Bench::unlocked();
    bench.set_mta(CAL);
    let block = &pedal_block()[..8];
    assert_eq!(bench.cmd(&[&[0xF0, 8][..], &block[..6]].concat()), None);
    assert_eq!(bench.ask(&[&[0xF0, 2][..], &block[6..]].concat()), [0xFF]);
    assert_eq!(bench.target.writes.len(), 1);
    assert_eq!(bench.target.working[..8], block[..]);
}

#[test]
fn a_refused_block_leaves_the_page() {
    let mut bench = Bench::unlocked();
    let mut block = pedal_block();
    block[LIMITED] = 200;
    bench.set_mta(CAL);
    assert_eq!(bench.cmd(&[&[0xF0, 12][..], &block[..6]].concat()), None);
    assert_eq!(
        bench.ask(&[&[0xEF, 6][..], &block[6..]].concat()),
        [0xFE, 0x22]
    );
    assert_eq!(bench.target.working, FakeTarget::new().working);
}

#[test]
fn block_sequence_errors_write_nothing() {
    let mut bench = Bench::unlocked();
    bench.set_mta(CAL);
    assert_eq!(
        bench.ask(&[0xEF, 6, 1, 2, 3, 4, 5, 6]),
        [0xFE, 0x29, 0],
        "no block open"
    );
    // Wrong remaining count: ERR_SEQUENCE with the expected count, the block is dropped.
    assert_eq!(bench.cmd(&[0xF0, 12, 1, 2, 3, 4, 5, 6]), None);
    assert_eq!(bench.ask(&[0xEF, 5, 1, 2, 3, 4, 5]), [0xFE, 0x29, 6]);
    assert_eq!(bench.ask(&[0xEF, 6, 1, 2, 3, 4, 5, 6]), [0xFE, 0x29, 0]);
    // A DOWNLOAD that does not complete the open block.
    assert_eq!(bench.cmd(&[0xF0, 12, 1, 2, 3, 4, 5, 6]), None);
    assert_eq!(bench.ask(&[0xF0, 3, 1, 2, 3]), [0xFE, 0x29, 6]);
    // Another command abandons the block.
    assert_eq!(bench.cmd(&[0xF0, 12, 1, 2, 3, 4, 5, 6]), None);
    bench.ask(&[0xFD]);
    assert_eq!(bench.ask(&[0xEF, 6, 1, 2, 3, 4, 5, 6]), [0xFE, 0x29, 0]);
    // A block packet shorter than its count.
    assert_eq!(bench.cmd(&[0xF0, 12, 1, 2, 3, 4, 5, 6]), None);
    assert_eq!(bench.ask(&[0xEF, 6, 1, 2]), [0xFE, 0x21]);
    assert!(bench.target.writes.is_empty());
    assert_eq!(bench.target.working, FakeTarget::new().working);
}

#[test]
fn a_failed_block_gets_one_answer_and_its_other_packets_none() {
    // Refused at its first packet (locked): the rest of the block is dropped silently, so a
    // master streaming the block finds exactly one answer, the error.
    let mut bench = Bench::connected();
    bench.set_mta(CAL);
    let data: Vec<u8> = (0..20).collect();
    assert_eq!(
        bench.ask(&[&[0xF0, 20][..], &data[..6]].concat()),
        [0xFE, 0x25]
    );
    assert_eq!(bench.cmd(&[&[0xEF, 14][..], &data[6..12]].concat()), None);
    assert_eq!(bench.cmd(&[&[0xEF, 8][..], &data[12..18]].concat()), None);
    assert_eq!(bench.cmd(&[&[0xEF, 2][..], &data[18..]].concat()), None);
    assert_eq!(
        bench.ask(&[0xEF, 2, 0, 0]),
        [0xFE, 0x29, 0],
        "the block is over"
    );
    // A wrong count mid-block: one ERR_SEQUENCE, then the master's remaining packets are dropped.
    bench.unlock();
    bench.set_mta(CAL + 16);
    assert_eq!(bench.cmd(&[&[0xF0, 14][..], &data[..6]].concat()), None);
    assert_eq!(
        bench.ask(&[&[0xEF, 9][..], &data[6..12]].concat()),
        [0xFE, 0x29, 8]
    );
    assert_eq!(bench.cmd(&[&[0xEF, 3][..], &data[12..15]].concat()), None);
    assert!(bench.target.writes.is_empty());
    // Too large a block: refused at once, its continuation dropped, the next one works.
    assert_eq!(
        bench.ask(&[&[0xF0, 60][..], &data[..6]].concat()),
        [0xFE, 0x22]
    );
    assert_eq!(bench.cmd(&[&[0xEF, 54][..], &data[..6]].concat()), None);
    bench.set_mta(CAL + 16);
    assert_eq!(bench.ask(&[&[0xF0, 2][..], &data[..2]].concat()), [0xFF]);
    assert_eq!(bench.target.working[16..18], data[..2]);
}

#[test]
fn blocks_beyond_max_bs_are_out_of_range() {
    let mut bench = Bench::unlocked();
    bench.set_mta(CAL);
    assert_eq!(
        bench.ask(&[0xF0, 49, 1, 2, 3, 4, 5, 6]),
        [0xFE, 0x22],
        "MAX_BS 8 x 6 = 48 bytes"
    );
    assert_eq!(bench.cmd(&[0xF0, 48, 1, 2, 3, 4, 5, 6]), None);
}

// ---------------------------------------------------------------------------------------------
// Pages
// ---------------------------------------------------------------------------------------------

#[test]
fn set_and_get_cal_page() {
    let mut bench = Bench::unlocked();
    assert_eq!(bench.ask(&[0xEA, 0x01, 0]), [0xFF, 0, 0, 0]);
    assert_eq!(bench.ask(&[0xEB, 0x01, 0, 1]), [0xFF]);
    assert_eq!(bench.target.ecu_page, 1);
    assert_eq!(bench.ask(&[0xEA, 0x01, 0]), [0xFF, 0, 0, 1]);
    assert_eq!(bench.ask(&[0xEA, 0x02, 0]), [0xFF, 0, 0, 0]);
    assert_eq!(
        bench.ask(&[0xEB, 0x83, 9, 0]),
        [0xFF],
        "ALL ignores the segment"
    );
    assert_eq!(bench.target.ecu_page, 0);
}

#[test]
fn set_cal_page_errors() {
    let mut bench = Bench::unlocked();
    assert_eq!(
        bench.ask(&[0xEB, 0x00, 0, 0]),
        [0xFE, 0x27],
        "neither ECU nor XCP"
    );
    assert_eq!(
        bench.ask(&[0xEB, 0x11, 0, 0]),
        [0xFE, 0x27],
        "unknown mode bit"
    );
    assert_eq!(bench.ask(&[0xEB, 0x01, 1, 0]), [0xFE, 0x28]);
    assert_eq!(bench.ask(&[0xEB, 0x01, 0, 2]), [0xFE, 0x26]);
    assert_eq!(bench.ask(&[0xEA, 0x03, 0]), [0xFE, 0x27]);
    assert_eq!(bench.ask(&[0xEA, 0x01, 1]), [0xFE, 0x28]);
    // The target refuses the ECU's switch while moving; the XCP page does not change either.
    bench.target.moving = true;
    assert_eq!(bench.ask(&[0xEB, 0x03, 0, 1]), [0xFE, 0x23]);
    assert_eq!(bench.target.ecu_page, 0);
    assert_eq!(bench.ask(&[0xEA, 0x02, 0]), [0xFF, 0, 0, 0]);
}

#[test]
fn copy_cal_page_restores_the_reference() {
    let mut bench = Bench::unlocked();
    bench.set_mta(CAL + 10);
    bench.ask(&[0xF0, 2, 0xEE, 0xEE]);
    assert_ne!(bench.target.working, bench.target.reference);
    assert_eq!(bench.ask(&[0xE4, 0, 1, 0, 0]), [0xFF]);
    assert_eq!(bench.target.working, bench.target.reference);
    assert_eq!(
        bench.ask(&[0xE4, 0, 0, 0, 1]),
        [0xFE, 0x23],
        "the reference is read-only"
    );
    assert_eq!(bench.ask(&[0xE4, 0, 3, 0, 0]), [0xFE, 0x26]);
    assert_eq!(bench.ask(&[0xE4, 1, 1, 0, 0]), [0xFE, 0x28]);
    bench.target.moving = true;
    assert_eq!(bench.ask(&[0xE4, 0, 1, 0, 0]), [0xFE, 0x23]);
}

#[test]
fn pag_processor_segment_and_page_info() {
    let mut bench = Bench::connected();
    assert_eq!(bench.ask(&[0xE9]), [0xFF, 1, 0], "one segment, no freeze");
    let a = le32(CAL);
    assert_eq!(
        bench.ask(&[0xE8, 0, 0, 0, 0]),
        [0xFF, 0, 0, 0, a[0], a[1], a[2], a[3]]
    );
    assert_eq!(bench.ask(&[0xE8, 0, 0, 1, 0]), [0xFF, 0, 0, 0, 32, 0, 0, 0]);
    assert_eq!(
        bench.ask(&[0xE8, 1, 0, 0, 0]),
        [0xFF, 2, 0, 0, 0, 0],
        "2 pages, ext 0, no mapping"
    );
    assert_eq!(bench.ask(&[0xE8, 2, 0, 0, 0]), [0xFE, 0x22]);
    assert_eq!(bench.ask(&[0xE8, 0, 0, 2, 0]), [0xFE, 0x22]);
    assert_eq!(bench.ask(&[0xE8, 1, 1, 0, 0]), [0xFE, 0x28]);
    assert_eq!(bench.ask(&[0xE7, 0, 0, 0]), [0xFF, 0x3F, 0]);
    assert_eq!(
        bench.ask(&[0xE7, 0, 0, 1]),
        [0xFF, 0x0F, 0],
        "reference: no XCP write"
    );
    assert_eq!(bench.ask(&[0xE7, 0, 0, 2]), [0xFE, 0x26]);
}

#[test]
fn set_request_store_goes_to_the_target() {
    let mut bench = Bench::unlocked();
    assert_eq!(
        bench.ask(&[0xF9, 0x02, 0, 0]),
        [0xFE, 0x22],
        "no DAQ storing"
    );
    assert_eq!(bench.ask(&[0xF9, 0x01, 0, 0]), [0xFF]);
    assert!(bench.target.store_pending);
    assert_eq!(
        bench.ask(&[0xFD])[1],
        0x01,
        "STORE_CAL_REQ until the target is done"
    );
}

// ---------------------------------------------------------------------------------------------
// DAQ
// ---------------------------------------------------------------------------------------------

#[test]
fn daq_processor_resolution_and_clock() {
    let mut bench = Bench::connected();
    // Dynamic, prescaler, timestamps, overload indicated by an event (0x80); MAX_DAQ 4;
    // 2 events; MIN_DAQ 0; key byte: absolute ODT.
    assert_eq!(bench.ask(&[0xDA]), [0xFF, 0x93, 4, 0, 2, 0, 0, 0x00]);
    // Granularity 1, max entry 7, no STIM, timestamp 4 bytes / 1 us / not fixed, 1 tick.
    assert_eq!(bench.ask(&[0xD9]), [0xFF, 1, 7, 1, 0, 0x34, 1, 0]);
    bench.now_us = 0x1234_5678;
    assert_eq!(bench.ask(&[0xDC]), [0xFF, 0, 0, 0, 0x78, 0x56, 0x34, 0x12]);
}

#[test]
fn daq_event_info_and_its_name() {
    let mut bench = Bench::connected();
    // DAQ, consistency per event channel; as many lists as the slave has (4, as the A2L
    // says); name length; 100 x 100 us.
    assert_eq!(bench.ask(&[0xD7, 0, 0, 0]), [0xFF, 0x84, 4, 7, 100, 5, 1]);
    assert_eq!(bench.ask(&[0xF5, 7]), [&[0xFF][..], b"control"].concat());
    assert_eq!(
        bench.ask(&[0xD7, 0, 1, 0]),
        [0xFF, 0x84, 4, 7, 100, 4, 2],
        "1 ms = 100 x 10 us"
    );
    assert_eq!(bench.ask(&[0xF5, 7]), [&[0xFF][..], b"sensors"].concat());
    assert_eq!(bench.ask(&[0xD7, 0, 2, 0]), [0xFE, 0x22]);
}

#[test]
fn a_running_list_sends_its_odts_with_pid_timestamp_and_current_data() {
    let mut bench = Bench::connected();
    start_two_odt_list(&mut bench, true);
    // RUNNING + TIMESTAMP, event 0, prescaler 1, priority 0.
    assert_eq!(bench.ask(&[0xDF, 0, 0, 0]), [0xFF, 0x50, 0, 0, 0, 0, 1, 0]);
    bench.now_us = 0x0A0B_0C0D;
    let m = bench.target.measurement;
    let dtos = bench.event(0);
    assert_eq!(
        dtos,
        vec![
            vec![0x00, 0x0D, 0x0C, 0x0B, 0x0A, m[0], m[1], m[5]],
            vec![0x01, m[8], m[9], m[10], m[11]]
        ]
    );
    // The next event samples the data as they are then.
    bench.target.measurement[9] = 0x99;
    bench.now_us += 10_000;
    let dtos = bench.event(0);
    assert_eq!(dtos[1], vec![0x01, m[8], 0x99, m[10], m[11]]);
    assert_eq!(dtos[0][1..5], (0x0A0B_0C0Du32 + 10_000).to_le_bytes());
    assert!(
        bench.event(1).is_empty(),
        "nothing runs on the sensors channel"
    );
    assert_eq!(bench.slave.counters().dtos_sent, 4);
    // Stop all.
    assert_eq!(bench.ask(&[0xDD, 0x00]), [0xFF]);
    assert!(bench.event(0).is_empty());
    assert_eq!(bench.ask(&[0xDF, 0, 0, 0]), [0xFF, 0x10, 0, 0, 0, 0, 1, 0]);
}

#[test]
fn daq_reads_stay_inside_the_map() {
    let mut bench = Bench::connected();
    start_two_odt_list(&mut bench, false);
    bench.target.reads.borrow_mut().clear();
    bench.event(0);
    let reads = bench.target.reads.borrow();
    assert_eq!(reads.len(), 3, "one read per entry");
    assert!(
        reads
            .iter()
            .all(|read| read.accepted && FakeTarget::in_map(read.ext, read.address, read.len))
    );
}

#[test]
fn the_prescaler_skips_events() {
    let mut bench = Bench::connected();
    configure_two_odt_list(&mut bench);
    assert_eq!(bench.ask(&[0xE0, 0x00, 0, 0, 0, 0, 3, 0]), [0xFF]);
    assert_eq!(
        bench.ask(&[0xDE, 0x01, 0, 0]),
        [0xFF, 0x00],
        "started directly"
    );
    let sampled: Vec<bool> = (0..7).map(|_| !bench.event(0).is_empty()).collect();
    assert_eq!(sampled, [true, false, false, true, false, false, true]);
    assert_eq!(bench.ask(&[0xDE, 0x00, 0, 0]), [0xFF, 0x00], "stopped");
    assert!(bench.event(0).is_empty());
}

#[test]
fn lists_after_the_first_report_their_first_pid() {
    let mut bench = Bench::connected();
    for packet in [
        &[0xD5, 0, 2, 0][..],
        &[0xD4, 0, 1, 0, 3],
        &[0xD4, 0, 0, 0, 2],
    ] {
        assert_eq!(bench.ask(packet), [0xFF]);
    }
    for (list, odt) in [(0u8, 0u8), (0, 1), (1, 0), (1, 1), (1, 2)] {
        assert_eq!(bench.ask(&[0xD3, 0, list, 0, odt, 1]), [0xFF]);
    }
    let a = le32(MEAS);
    for (list, odts) in [(0u8, 2u8), (1, 3)] {
        for odt in 0..odts {
            bench.ask(&[0xE2, 0, list, 0, odt, 0]);
            assert_eq!(
                bench.ask(&[0xE1, 0xFF, 1, 0, a[0], a[1], a[2], a[3]]),
                [0xFF]
            );
        }
        assert_eq!(
            bench.ask(&[0xE0, 0, list, 0, 0, 0, 4, 0]),
            [0xFF],
            "prescaler 4: 125 frames/s"
        );
    }
    // List 1 was allocated first: PIDs 0..=2; list 0 then has PIDs 3 and 4.
    assert_eq!(bench.ask(&[0xDE, 0x02, 1, 0]), [0xFF, 0]);
    assert_eq!(bench.ask(&[0xDE, 0x02, 0, 0]), [0xFF, 3]);
    assert_eq!(bench.ask(&[0xDD, 0x01]), [0xFF]);
    let pids: Vec<u8> = bench.event(0).iter().map(|dto| dto[0]).collect();
    assert_eq!(pids, [3, 4, 0, 1, 2]);
    // Stop the selected ones: none selected any more after the start.
    assert_eq!(bench.ask(&[0xDD, 0x02]), [0xFF]);
    assert!(bench.slave.is_daq_running());
}

#[test]
fn an_empty_first_odt_is_allowed() {
    // pyxcp allocates 0 entries for a first ODT that has no room next to the timestamp.
    let mut bench = Bench::connected();
    for packet in [
        &[0xD5, 0, 1, 0][..],
        &[0xD4, 0, 0, 0, 2],
        &[0xD3, 0, 0, 0, 0, 0],
        &[0xD3, 0, 0, 0, 1, 1],
    ] {
        assert_eq!(bench.ask(packet), [0xFF]);
    }
    assert_eq!(
        bench.ask(&[0xE2, 0, 0, 0, 0, 0]),
        [0xFE, 0x22],
        "no entry to point at"
    );
    assert_eq!(bench.ask(&[0xE2, 0, 0, 0, 1, 0]), [0xFF]);
    let a = le32(MEAS);
    assert_eq!(
        bench.ask(&[0xE1, 0xFF, 4, 0, a[0], a[1], a[2], a[3]]),
        [0xFF]
    );
    assert_eq!(bench.ask(&[0xE0, 0x10, 0, 0, 0, 0, 1, 0]), [0xFF]);
    assert_eq!(bench.ask(&[0xDE, 0x01, 0, 0]), [0xFF, 0]);
    bench.now_us = 7;
    let m = bench.target.measurement;
    assert_eq!(
        bench.event(0),
        vec![vec![0, 7, 0, 0, 0], vec![1, m[0], m[1], m[2], m[3]]]
    );
}

#[test]
fn allocation_order_violations_are_sequence_errors() {
    let mut bench = Bench::connected();
    assert_eq!(
        bench.ask(&[0xD4, 0, 0, 0, 1]),
        [0xFE, 0x29],
        "ALLOC_ODT before ALLOC_DAQ"
    );
    assert_eq!(
        bench.ask(&[0xD3, 0, 0, 0, 0, 1]),
        [0xFE, 0x29],
        "ALLOC_ODT_ENTRY before ALLOC_DAQ"
    );
    assert_eq!(bench.ask(&[0xD5, 0, 2, 0]), [0xFF]);
    assert_eq!(
        bench.ask(&[0xD3, 0, 0, 0, 0, 1]),
        [0xFE, 0x29],
        "ALLOC_ODT_ENTRY before ALLOC_ODT"
    );
    assert_eq!(
        bench.ask(&[0xD5, 0, 3, 0]),
        [0xFF],
        "ALLOC_DAQ again before any ODT"
    );
    assert_eq!(bench.ask(&[0xD4, 0, 0, 0, 2]), [0xFF]);
    assert_eq!(
        bench.ask(&[0xD4, 0, 0, 0, 2]),
        [0xFE, 0x29],
        "the same list twice"
    );
    assert_eq!(
        bench.ask(&[0xD5, 0, 1, 0]),
        [0xFE, 0x29],
        "ALLOC_DAQ after ALLOC_ODT"
    );
    assert_eq!(bench.ask(&[0xD3, 0, 0, 0, 0, 1]), [0xFF]);
    assert_eq!(
        bench.ask(&[0xD3, 0, 0, 0, 0, 1]),
        [0xFE, 0x29],
        "the same ODT twice"
    );
    assert_eq!(
        bench.ask(&[0xD4, 0, 1, 0, 1]),
        [0xFE, 0x29],
        "ALLOC_ODT after ALLOC_ODT_ENTRY"
    );
    let a = le32(MEAS);
    assert_eq!(
        bench.ask(&[0xE1, 0xFF, 1, 0, a[0], a[1], a[2], a[3]]),
        [0xFE, 0x29],
        "WRITE_DAQ without SET_DAQ_PTR"
    );
    // FREE_DAQ starts over.
    assert_eq!(bench.ask(&[0xD6]), [0xFF]);
    assert_eq!(bench.ask(&[0xD4, 0, 0, 0, 1]), [0xFE, 0x29]);
    assert_eq!(bench.ask(&[0xD5, 0, 1, 0]), [0xFF]);
}

#[test]
fn allocation_beyond_the_storage_is_a_memory_overflow() {
    let mut bench = Bench::connected();
    assert_eq!(bench.ask(&[0xD5, 0, 5, 0]), [0xFE, 0x30], "4 lists");
    assert_eq!(bench.ask(&[0xD5, 0, 0, 0]), [0xFE, 0x22]);
    assert_eq!(bench.ask(&[0xD5, 0, 4, 0]), [0xFF]);
    assert_eq!(bench.ask(&[0xD4, 0, 0, 0, 10]), [0xFF]);
    assert_eq!(bench.ask(&[0xD4, 0, 1, 0, 7]), [0xFE, 0x30], "16 ODTs");
    assert_eq!(bench.ask(&[0xD4, 0, 1, 0, 0]), [0xFE, 0x22]);
    assert_eq!(bench.ask(&[0xD4, 0, 9, 0, 1]), [0xFE, 0x22], "no list 9");
    assert_eq!(bench.ask(&[0xD4, 0, 1, 0, 6]), [0xFF]);
    for odt in 0..9 {
        assert_eq!(bench.ask(&[0xD3, 0, 0, 0, odt, 7]), [0xFF]);
    }
    assert_eq!(
        bench.ask(&[0xD3, 0, 0, 0, 9, 2]),
        [0xFE, 0x30],
        "64 entries"
    );
    assert_eq!(
        bench.ask(&[0xD3, 0, 0, 0, 9, 8]),
        [0xFE, 0x22],
        "8 entries cannot fit a DTO"
    );
    assert_eq!(
        bench.ask(&[0xD3, 0, 0, 0, 10, 1]),
        [0xFE, 0x22],
        "no ODT 10 in list 0"
    );
}

#[test]
fn write_daq_errors() {
    let mut bench = Bench::connected();
    for packet in [
        &[0xD5, 0, 1, 0][..],
        &[0xD4, 0, 0, 0, 1],
        &[0xD3, 0, 0, 0, 0, 3],
        &[0xE2, 0, 0, 0, 0, 0],
    ] {
        assert_eq!(bench.ask(packet), [0xFF]);
    }
    let write = |bench: &mut Bench, bit: u8, size: u8, ext: u8, address: u32| {
        let a = le32(address);
        bench.ask(&[0xE1, bit, size, ext, a[0], a[1], a[2], a[3]])
    };
    assert_eq!(
        write(&mut bench, 0xFF, 2, 0, 0x0005_0000),
        [0xFE, 0x24],
        "not mapped"
    );
    assert_eq!(
        write(&mut bench, 0xFF, 2, 1, MEAS),
        [0xFE, 0x24],
        "other extension"
    );
    assert_eq!(write(&mut bench, 0xFF, 0, 0, MEAS), [0xFE, 0x22]);
    assert_eq!(write(&mut bench, 0xFF, 8, 0, MEAS), [0xFE, 0x22]);
    assert_eq!(
        write(&mut bench, 3, 1, 0, MEAS),
        [0xFE, 0x22],
        "no bit entries"
    );
    assert_eq!(write(&mut bench, 0xFF, 4, 0, MEAS), [0xFF]);
    assert_eq!(
        write(&mut bench, 0xFF, 4, 0, MEAS),
        [0xFE, 0x2A],
        "8 bytes do not fit a DTO"
    );
    assert_eq!(write(&mut bench, 0xFF, 2, 0, MEAS), [0xFF]);
    assert_eq!(write(&mut bench, 0xFF, 1, 0, MEAS), [0xFF]);
    assert_eq!(
        write(&mut bench, 0xFF, 1, 0, MEAS),
        [0xFE, 0x29],
        "past the ODT's last entry"
    );
    // With a timestamp the first ODT has 3 bytes of room, not 7.
    assert_eq!(bench.ask(&[0xE0, 0x10, 0, 0, 0, 0, 1, 0]), [0xFE, 0x2A]);
    assert_eq!(bench.ask(&[0xE0, 0x00, 0, 0, 0, 0, 1, 0]), [0xFF]);
    // No SET_DAQ_PTR / WRITE_DAQ on a running list.
    assert_eq!(bench.ask(&[0xDE, 0x01, 0, 0]), [0xFF, 0]);
    assert_eq!(bench.ask(&[0xE2, 0, 0, 0, 0, 0]), [0xFE, 0x11]);
    assert_eq!(bench.ask(&[0xE0, 0x00, 0, 0, 0, 0, 1, 0]), [0xFE, 0x11]);
    assert_eq!(bench.ask(&[0xE2, 0, 1, 0, 0, 0]), [0xFE, 0x22], "no list 1");
}

#[test]
fn daq_list_mode_errors() {
    let mut bench = Bench::connected();
    configure_two_odt_list(&mut bench);
    assert_eq!(
        bench.ask(&[0xE0, 0x02, 0, 0, 0, 0, 1, 0]),
        [0xFE, 0x27],
        "STIM"
    );
    assert_eq!(
        bench.ask(&[0xE0, 0x20, 0, 0, 0, 0, 1, 0]),
        [0xFE, 0x27],
        "PID_OFF"
    );
    assert_eq!(
        bench.ask(&[0xE0, 0x00, 0, 0, 0, 0, 0, 0]),
        [0xFE, 0x22],
        "prescaler 0"
    );
    assert_eq!(
        bench.ask(&[0xE0, 0x00, 0, 0, 2, 0, 1, 0]),
        [0xFE, 0x22],
        "no event 2"
    );
    assert_eq!(
        bench.ask(&[0xE0, 0x00, 1, 0, 0, 0, 1, 0]),
        [0xFE, 0x22],
        "no list 1"
    );
    assert_eq!(bench.ask(&[0xDF, 0, 1, 0]), [0xFE, 0x22]);
    // Starting without an event channel is not a valid configuration.
    assert_eq!(bench.ask(&[0xDE, 0x01, 0, 0]), [0xFE, 0x2A]);
    assert_eq!(bench.ask(&[0xDE, 0x02, 0, 0]), [0xFE, 0x2A]);
    assert_eq!(bench.ask(&[0xDE, 0x03, 0, 0]), [0xFE, 0x27]);
    assert_eq!(bench.ask(&[0xDD, 0x03]), [0xFE, 0x27]);
    assert!(!bench.slave.is_daq_running());
}

/// ALLOC_ODT for one list.
fn list_with(bench: &mut Bench, list: u8, odts: u8) {
    assert_eq!(bench.ask(&[0xD4, 0, list, 0, odts]), [0xFF]);
}

/// One one-byte entry per ODT, then the list's event and prescaler.
fn fill_and_mode(bench: &mut Bench, list: u8, odts: u8, event: u8, prescaler: u8) {
    let a = le32(MEAS);
    for odt in 0..odts {
        assert_eq!(bench.ask(&[0xD3, 0, list, 0, odt, 1]), [0xFF]);
        assert_eq!(bench.ask(&[0xE2, 0, list, 0, odt, 0]), [0xFF]);
        assert_eq!(
            bench.ask(&[0xE1, 0xFF, 1, 0, a[0], a[1], a[2], a[3]]),
            [0xFF]
        );
    }
    assert_eq!(
        bench.ask(&[0xE0, 0, list, 0, event, 0, prescaler, 0]),
        [0xFF]
    );
}

#[test]
fn lists_beyond_the_frame_budget_are_refused() {
    // Budget 250/s, 50 kept for responses: DAQ may send 200 frames/s.
    let mut bench = Bench::connected();
    assert_eq!(bench.ask(&[0xD5, 0, 3, 0]), [0xFF]);
    list_with(&mut bench, 0, 2);
    list_with(&mut bench, 1, 3);
    list_with(&mut bench, 2, 1);
    fill_and_mode(&mut bench, 0, 2, 0, 1); // 2 x 100 Hz = 200/s
    fill_and_mode(&mut bench, 1, 3, 0, 1); // 3 x 100 Hz = 300/s
    fill_and_mode(&mut bench, 2, 1, 1, 1); // 1 x 1 kHz = 1000/s
    assert_eq!(bench.ask(&[0xDE, 0x01, 1, 0]), [0xFE, 0x2A], "300/s alone");
    assert_eq!(bench.ask(&[0xDE, 0x01, 2, 0]), [0xFE, 0x2A], "1000/s alone");
    assert_eq!(bench.ask(&[0xDE, 0x01, 0, 0]), [0xFF, 0], "200/s fits");
    assert!(bench.slave.is_daq_running());
    // With list 0 running, a prescaled sensors list no longer fits either.
    assert_eq!(
        bench.ask(&[0xE0, 0, 2, 0, 1, 0, 5, 0]),
        [0xFF],
        "1000 / 5 = 200/s"
    );
    assert_eq!(bench.ask(&[0xDE, 0x01, 2, 0]), [0xFE, 0x2A]);
    assert_eq!(bench.ask(&[0xDE, 0x00, 0, 0]), [0xFF, 0]);
    assert_eq!(bench.ask(&[0xDE, 0x01, 2, 0]), [0xFF, 5], "alone it fits");
    assert_eq!(bench.ask(&[0xDD, 0x00]), [0xFF]);
    // Selected together they exceed the budget: START_STOP_SYNCH starts none of them.
    assert_eq!(bench.ask(&[0xDE, 0x02, 0, 0]), [0xFF, 0]);
    assert_eq!(bench.ask(&[0xDE, 0x02, 2, 0]), [0xFF, 5]);
    assert_eq!(bench.ask(&[0xDD, 0x01]), [0xFE, 0x2A]);
    assert!(!bench.slave.is_daq_running());
}

#[test]
fn a_full_bus_queue_counts_dropped_dtos() {
    let mut bench = Bench::connected();
    start_two_odt_list(&mut bench, false);
    let mut taken = 0;
    let report = bench
        .slave
        .event(&bench.target, 0, 0, &mut |_packet: &[u8]| {
            taken += 1;
            taken == 1
        });
    assert_eq!((report.sent, report.dropped), (1, 1));
    assert_eq!(taken, 2);
    let mut offered = 0;
    let report = bench
        .slave
        .event(&bench.target, 0, 0, &mut |_packet: &[u8]| {
            offered += 1;
            false
        });
    assert_eq!((report.sent, report.dropped), (0, 2));
    assert_eq!(
        offered, 1,
        "after the first refusal the rest is not offered"
    );
    let counters = bench.slave.counters();
    assert_eq!((counters.dtos_sent, counters.dtos_dropped), (1, 3));
}

#[test]
fn clear_daq_list_empties_the_entries() {
    let mut bench = Bench::connected();
    configure_two_odt_list(&mut bench);
    assert_eq!(bench.ask(&[0xE3, 0, 0, 0]), [0xFF]);
    assert_eq!(bench.ask(&[0xE3, 0, 1, 0]), [0xFE, 0x22]);
    assert_eq!(bench.ask(&[0xE0, 0, 0, 0, 0, 0, 1, 0]), [0xFF]);
    assert_eq!(bench.ask(&[0xDE, 0x01, 0, 0]), [0xFF, 0]);
    assert_eq!(bench.event(0), vec![vec![0x00], vec![0x01]]);
}

#[test]
fn disconnect_and_reconnect_stop_daq() {
    let mut bench = Bench::connected();
    start_two_odt_list(&mut bench, false);
    assert_eq!(bench.ask(&[0xFE]), [0xFF]);
    assert!(!bench.slave.is_daq_running());
    assert!(bench.event(0).is_empty());
    let mut bench = Bench::connected();
    start_two_odt_list(&mut bench, false);
    bench.ask(&[0xFF, 0]);
    assert!(bench.event(0).is_empty(), "CONNECT starts a clean session");
    assert_eq!(
        bench.ask(&[0xE2, 0, 0, 0, 0, 0]),
        [0xFE, 0x22],
        "lists were freed"
    );
}
