//! The Pi's Deku telemetry decoder on untrusted bytes. Half the inputs get the right fingerprint
//! so the fuzzer reaches the field decoding. Decoding must never panic, must agree with the
//! firmware's own reader, and whatever decodes must re-pack to the same packet.
#![no_main]

use aer::telemetry::{TELEMETRY_FINGERPRINT, Telemetry};
use aer::telemetry_deku::TelemetryFrame;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|input: &[u8]| {
    let Some((&mode, rest)) = input.split_first() else {
        return;
    };
    let mut bytes = rest.to_vec();
    if mode & 1 == 1 && bytes.len() >= 4 {
        bytes[..4].copy_from_slice(&TELEMETRY_FINGERPRINT.to_le_bytes());
    }
    let deku = TelemetryFrame::decode(&bytes);
    let firmware = Telemetry::unpack(&bytes);
    assert_eq!(deku.is_ok(), firmware.is_ok());
    if let (Ok(frame), Ok((header, snapshot))) = (deku, firmware) {
        assert_eq!(frame.to_telemetry(), (header, snapshot));
        let mut packed = [0u8; Telemetry::LEN];
        assert_eq!(snapshot.pack(header, &mut packed), 0);
        let (_, again) = Telemetry::unpack(&packed).expect("own packet decodes");
        assert_eq!(again, snapshot);
    }
});
