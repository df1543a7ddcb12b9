//! FNV-1a (32-bit) over everything written to it.

/// Hashes text written through `core::fmt::Write` and raw bytes.
#[derive(Debug, Clone, Copy)]
pub struct Digest(u32);

impl Default for Digest {
    fn default() -> Self {
        Self(0x811C_9DC5)
    }
}

impl Digest {
    /// Adds bytes.
    pub fn bytes(&mut self, bytes: &[u8]) {
        for byte in bytes {
            self.0 = (self.0 ^ u32::from(*byte)).wrapping_mul(0x0100_0193);
        }
    }

    /// The digest so far.
    pub fn value(&self) -> u32 {
        self.0
    }
}

impl core::fmt::Write for Digest {
    fn write_str(&mut self, text: &str) -> core::fmt::Result {
        self.bytes(text.as_bytes());
        Ok(())
    }
}
