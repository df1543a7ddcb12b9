//! The team's seed-and-key function, shared by the CCM's slave (which checks a key) and the
//! masters that compute one (the dashboard's Tune page; pyxcp's `tools/xcp_scenarios.py`
//! implements the same): the key is the first [`KEY_LEN`] bytes of HMAC-SHA256 over the seed,
//! keyed with the team's [`SECRET_LEN`]-byte secret.

use hmac::{Hmac, Mac};
use sha2::Sha256;

/// Bytes of the key UNLOCK takes (sent in three UNLOCK commands on CAN).
pub const KEY_LEN: usize = 16;
/// Bytes of the team's secret.
pub const SECRET_LEN: usize = 32;

/// The key for `seed` under `secret`.
pub fn key_for(secret: &[u8; SECRET_LEN], seed: &[u8]) -> [u8; KEY_LEN] {
    let mut key = [0u8; KEY_LEN];
    // HMAC takes a key of any length: this cannot fail.
    if let Ok(mut mac) = Hmac::<Sha256>::new_from_slice(secret) {
        mac.update(seed);
        let digest = mac.finalize().into_bytes();
        for (out, byte) in key.iter_mut().zip(digest.iter()) {
            *out = *byte;
        }
    }
    key
}

/// The secret as the team keeps it: 64 hex digits (whitespace around them ignored).
pub fn parse_secret(text: &str) -> Option<[u8; SECRET_LEN]> {
    let hex = text.trim().as_bytes();
    if hex.len() != 2 * SECRET_LEN {
        return None;
    }
    let mut secret = [0u8; SECRET_LEN];
    for (byte, pair) in secret.iter_mut().zip(hex.chunks(2)) {
        let digit = |c: u8| char::from(c).to_digit(16);
        let (high, low) = (digit(*pair.first()?)?, digit(*pair.get(1)?)?);
        *byte = u8::try_from(high * 16 + low).ok()?;
    }
    Some(secret)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_key_is_hmac_sha256_of_the_seed_cut_to_sixteen_bytes() {
        // RFC 4231 test case 2's key and data give 5bdcc146bf60754e6a042426089575c7...
        let mut secret = [0u8; SECRET_LEN];
        secret[..4].copy_from_slice(b"Jefe");
        // A 32-byte key padded with zeros is the same HMAC key as the 4-byte one.
        let key = key_for(&secret, b"what do ya want for nothing?");
        assert_eq!(
            key,
            [
                0x5b, 0xdc, 0xc1, 0x46, 0xbf, 0x60, 0x75, 0x4e, 0x6a, 0x04, 0x24, 0x26, 0x08, 0x95,
                0x75, 0xc7
            ]
        );
    }

    #[test]
    fn a_secret_is_64_hex_digits() {
        // " 0f0f...0f\n": the digits, with whitespace around them.
        let mut text = [b'0'; 2 * SECRET_LEN + 2];
        text[0] = b' ';
        text[2 * SECRET_LEN + 1] = b'\n';
        for pair in text[1..=2 * SECRET_LEN].chunks_mut(2) {
            pair[1] = b'f';
        }
        let text = core::str::from_utf8(&text).expect("ascii");
        assert_eq!(parse_secret(text), Some([0x0f; SECRET_LEN]));
        assert_eq!(parse_secret(&text[..2 * SECRET_LEN - 1]), None);
        let mut odd = [b'0'; 2 * SECRET_LEN];
        odd[7] = b'z';
        assert_eq!(
            parse_secret(core::str::from_utf8(&odd).expect("ascii")),
            None
        );
    }
}
