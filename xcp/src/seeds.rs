//! Seeds no observer can predict: HMAC_DRBG with SHA-256 (NIST SP 800-90A rev. 1, 10.1.2),
//! instantiated from the ECU's true random number generator. A seed reveals nothing of the
//! generator's state, so no number of seeds seen lets anyone compute the next one (the
//! xorshift generator before it gave its whole state away in two seeds).
//!
//! The ECU instantiates it once at start-up from at least 256 bits of entropy (the i.MX RT's
//! TRNG) with its own identity as personalization, and mixes the time of each request in as
//! additional input. The host tests instantiate it from fixed bytes.

use hmac::{Hmac, Mac};
use sha2::Sha256;

/// Bytes of the state's key and value (SHA-256's output).
const LEN: usize = 32;

/// Bytes of entropy [`SeedGenerator::new`] wants at least (the security strength, 256 bits).
pub const ENTROPY_MIN: usize = 32;

/// The generator (see the module's description).
#[derive(Clone)]
pub struct SeedGenerator {
    key: [u8; LEN],
    value: [u8; LEN],
}

/// HMAC-SHA256 of the concatenated `parts` under `key`.
fn hmac(key: &[u8; LEN], parts: &[&[u8]]) -> [u8; LEN] {
    let mut out = [0u8; LEN];
    // HMAC takes a key of any length: this cannot fail.
    if let Ok(mut mac) = Hmac::<Sha256>::new_from_slice(key) {
        for part in parts {
            mac.update(part);
        }
        out.copy_from_slice(&mac.finalize().into_bytes());
    }
    out
}

impl SeedGenerator {
    /// Instantiated from `entropy` (at least [`ENTROPY_MIN`] bytes from a true random source)
    /// and `personalization` (what makes this ECU's generator its own: its chip id).
    pub fn new(entropy: &[u8], personalization: &[u8]) -> Self {
        let mut generator = Self {
            key: [0; LEN],
            value: [1; LEN],
        };
        generator.update(&[entropy, personalization]);
        generator
    }

    /// Mixes fresh entropy in (reseed).
    pub fn reseed(&mut self, entropy: &[u8]) {
        self.update(&[entropy]);
    }

    /// Fills `out` with the next bytes, with `additional` (the request's time, say) mixed in
    /// before and after.
    pub fn fill(&mut self, out: &mut [u8], additional: &[u8]) {
        if !additional.is_empty() {
            self.update(&[additional]);
        }
        for chunk in out.chunks_mut(LEN) {
            self.value = hmac(&self.key, &[&self.value]);
            for (slot, byte) in chunk.iter_mut().zip(self.value) {
                *slot = byte;
            }
        }
        self.update(&[additional]);
    }

    /// HMAC_DRBG's update function over the concatenated `provided` parts.
    fn update(&mut self, provided: &[&[u8]]) {
        let empty = provided.iter().all(|part| part.is_empty());
        self.step(0x00, provided);
        if !empty {
            self.step(0x01, provided);
        }
    }

    fn step(&mut self, separator: u8, provided: &[&[u8]]) {
        let mut parts: [&[u8]; 4] = [&self.value, &[separator], &[], &[]];
        for (slot, part) in parts.iter_mut().skip(2).zip(provided) {
            *slot = part;
        }
        let key = hmac(&self.key, &parts);
        self.key = key;
        self.value = hmac(&self.key, &[&self.value]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_same_entropy_gives_the_same_seeds_and_other_entropy_others() {
        let mut a = SeedGenerator::new(&[7; ENTROPY_MIN], b"ccm");
        let mut b = SeedGenerator::new(&[7; ENTROPY_MIN], b"ccm");
        let mut c = SeedGenerator::new(&[8; ENTROPY_MIN], b"ccm");
        let (mut x, mut y, mut z) = ([0u8; 6], [0u8; 6], [0u8; 6]);
        for time in 0..100u32 {
            a.fill(&mut x, &time.to_le_bytes());
            b.fill(&mut y, &time.to_le_bytes());
            c.fill(&mut z, &time.to_le_bytes());
            assert_eq!(x, y);
            assert_ne!(x, z);
        }
    }
}
