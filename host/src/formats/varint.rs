//! LEB128 varints and zigzag signs: the compact integers of the raw log and of the Pi
//! store's compacted blocks.

/// Appends `value` as LEB128 (7 bits a byte, low first).
pub fn put_varint(out: &mut Vec<u8>, mut value: u64) {
    while value >= 0x80 {
        out.push((value as u8 & 0x7F) | 0x80);
        value >>= 7;
    }
    out.push(value as u8);
}

/// Reads a LEB128 value from `next_byte`; `None` if a byte is missing or it runs past 64 bits.
pub fn read_varint(mut next_byte: impl FnMut() -> Option<u8>) -> Option<u64> {
    let mut value = 0u64;
    for shift in (0..64).step_by(7) {
        let byte = next_byte()?;
        value |= u64::from(byte & 0x7F) << shift;
        if byte & 0x80 == 0 {
            return Some(value);
        }
    }
    None
}

/// A signed value as unsigned, small magnitudes small (0, -1, 1, -2 -> 0, 1, 2, 3).
pub fn zigzag(value: i64) -> u64 {
    ((value << 1) ^ (value >> 63)) as u64
}

/// The inverse of [`zigzag`].
pub fn unzigzag(value: u64) -> i64 {
    ((value >> 1) as i64) ^ -((value & 1) as i64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn any_value_reads_back(value in any::<i64>()) {
            let mut out = Vec::new();
            put_varint(&mut out, zigzag(value));
            let mut bytes = out.iter().copied();
            prop_assert_eq!(read_varint(|| bytes.next()).map(unzigzag), Some(value));
            prop_assert_eq!(bytes.next(), None);
        }
    }
}
