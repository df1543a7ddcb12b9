//! Intel HEX output, what teensy_loader_cli flashes.
//!
//! Records: 02-free form, 16 data bytes per line (type 00), an extended linear address record
//! (type 04) whenever the upper 16 address bits change, end of file (type 01).

use std::fmt::Write as _;

/// Writes `chunks` (load address, bytes) as Intel HEX text.
pub fn write(chunks: &[(u32, &[u8])]) -> String {
    let mut out = String::new();
    let mut upper: Option<u16> = None;
    for &(address, bytes) in chunks {
        let mut offset = 0usize;
        while offset < bytes.len() {
            let at = address.wrapping_add(offset as u32);
            let [hi_a, hi_b, lo_a, lo_b] = at.to_be_bytes();
            let high = u16::from_be_bytes([hi_a, hi_b]);
            if upper != Some(high) {
                record(&mut out, 0, 0x04, &[hi_a, hi_b]);
                upper = Some(high);
            }
            // A line never crosses a 64 KiB boundary, so the 04 record above stays valid.
            let to_boundary = 0x1_0000 - usize::from(u16::from_be_bytes([lo_a, lo_b]));
            let len = (bytes.len() - offset).min(16).min(to_boundary);
            record(
                &mut out,
                u16::from_be_bytes([lo_a, lo_b]),
                0x00,
                &bytes[offset..offset + len],
            );
            offset += len;
        }
    }
    record(&mut out, 0, 0x01, &[]);
    out
}

fn record(out: &mut String, address: u16, kind: u8, data: &[u8]) {
    let [a_hi, a_lo] = address.to_be_bytes();
    let len = data.len() as u8;
    let sum = [len, a_hi, a_lo, kind]
        .iter()
        .chain(data)
        .fold(0u8, |sum, byte| sum.wrapping_add(*byte));
    let _ = write!(out, ":{len:02X}{address:04X}{kind:02X}");
    for byte in data {
        let _ = write!(out, "{byte:02X}");
    }
    let _ = writeln!(out, "{:02X}", sum.wrapping_neg());
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Parses Intel HEX back into (address, byte) pairs.
    fn parse(text: &str) -> Result<Vec<(u32, u8)>, String> {
        let mut bytes = Vec::new();
        let mut upper = 0u32;
        for (number, line) in text.lines().enumerate() {
            let line = line.trim();
            let fields = line
                .strip_prefix(':')
                .ok_or_else(|| format!("line {}: no ':'", number + 1))?;
            let raw = (0..fields.len())
                .step_by(2)
                .map(|i| {
                    fields
                        .get(i..i + 2)
                        .and_then(|pair| u8::from_str_radix(pair, 16).ok())
                        .ok_or_else(|| format!("line {}: bad hex", number + 1))
                })
                .collect::<Result<Vec<u8>, String>>()?;
            if raw.iter().fold(0u8, |sum, byte| sum.wrapping_add(*byte)) != 0 {
                return Err(format!("line {}: bad checksum", number + 1));
            }
            let [len, a_hi, a_lo, kind, ref rest @ ..] = raw[..] else {
                return Err(format!("line {}: too short", number + 1));
            };
            let data = rest
                .get(..usize::from(len))
                .ok_or_else(|| format!("line {}: length", number + 1))?;
            match kind {
                0x00 => {
                    let base = upper | u32::from(u16::from_be_bytes([a_hi, a_lo]));
                    bytes.extend(data.iter().enumerate().map(|(i, b)| (base + i as u32, *b)));
                }
                0x01 => break,
                0x04 => {
                    let [high, low] = data[..] else {
                        return Err(format!("line {}: 04 record length", number + 1));
                    };
                    upper = u32::from(u16::from_be_bytes([high, low])) << 16;
                }
                // 05 (start linear address) carries no image bytes.
                0x05 => {}
                other => return Err(format!("line {}: record type {other:02X}", number + 1)),
            }
        }
        Ok(bytes)
    }

    #[test]
    fn records_have_the_intel_checksum() {
        // The classic example record from the Intel HEX specification.
        let text = write(&[(0x0000_0030, &[0x02, 0x33, 0x7A])]);
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(
            lines,
            [":020000040000FA", ":0300300002337A1E", ":00000001FF"]
        );
    }

    #[test]
    fn the_upper_address_changes_at_64_kib_boundaries() {
        let bytes: Vec<u8> = (0..40u8).collect();
        let text = write(&[(0x6000_FFF0, &bytes)]);
        assert!(text.contains(":020000046000"));
        assert!(text.contains(":020000046001"));
        let parsed = parse(&text).unwrap();
        let expected: Vec<(u32, u8)> = (0..40u32).map(|i| (0x6000_FFF0 + i, i as u8)).collect();
        assert_eq!(parsed, expected);
    }

    #[test]
    fn corrupt_hex_is_refused() {
        assert!(parse(":0300300002337A1F\n").is_err());
        assert!(parse("0300300002337A1E\n").is_err());
    }
}
