//! The generated CAN codec and telemetry packer over pseudo-random payloads.

use crate::Digest;
use aer::can::{AnyMessage, MESSAGES};
use aer::telemetry::{TELEMETRY_FINGERPRINT, Telemetry, TelemetryHeader};
use aer_car_model::rng::Rng;
use core::fmt::Write;

/// Payloads per message.
const FRAMES: u32 = 500;

/// Decodes random payloads of every message, re-encodes them, and digests both.
pub fn can_messages(out: &mut impl Write) -> core::fmt::Result {
    let mut rng = Rng::new(0x00C0_FFEE);
    for meta in MESSAGES {
        let mut digest = Digest::default();
        let mut refused = 0u32;
        for _ in 0..FRAMES {
            let mut payload = [0u8; 64];
            let len = meta.len.min(payload.len());
            let payload = payload.get_mut(..len).unwrap_or_default();
            rng.fill(payload);
            match AnyMessage::decode(meta.id, meta.extended, payload) {
                Ok(message) => {
                    write!(digest, "{message:?}")?;
                    let mut again = [0u8; 64];
                    match message.encode(&mut again) {
                        Ok(written) => digest.bytes(again.get(..written).unwrap_or_default()),
                        Err(error) => {
                            refused += 1;
                            write!(digest, "{error:?}")?;
                        }
                    }
                }
                Err(error) => write!(digest, "{error:?}")?,
            }
        }
        writeln!(
            out,
            "can {} frames={FRAMES} re-encode-refused={refused} digest={:08x}",
            meta.name,
            digest.value()
        )?;
    }
    Ok(())
}

/// Unpacks random telemetry packets (with the right fingerprint), packs them again, digests.
pub fn telemetry(out: &mut impl Write) -> core::fmt::Result {
    let mut rng = Rng::new(0x7E1E_3E7A);
    let mut digest = Digest::default();
    let mut saturated = 0u32;
    for _ in 0..FRAMES {
        let mut packet = [0u8; Telemetry::LEN];
        rng.fill(&mut packet);
        if let Some(head) = packet.get_mut(..4) {
            head.copy_from_slice(&TELEMETRY_FINGERPRINT.to_le_bytes());
        }
        match Telemetry::unpack(&packet) {
            Ok((header, telemetry)) => {
                write!(digest, "{header:?}{telemetry:?}")?;
                let mut again = [0u8; Telemetry::LEN];
                let next = TelemetryHeader {
                    sequence: header.sequence.wrapping_add(1),
                    ..header
                };
                saturated += u32::from(telemetry.pack(next, &mut again));
                digest.bytes(&again);
            }
            Err(error) => write!(digest, "{error:?}")?,
        }
    }
    writeln!(
        out,
        "telemetry packets={FRAMES} saturated-fields={saturated} digest={:08x}",
        digest.value()
    )
}
