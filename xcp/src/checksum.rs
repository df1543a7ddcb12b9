//! BUILD_CHECKSUM's algorithm: XCP_CRC_16_CITT (type 0x08), the CRC-16 CCITT variant pyxcp
//! computes for that type (polynomial 0x1021, initial value 0xFFFF, no reflection, no final
//! XOR; "123456789" gives 0x29B1), so `Master.verify` can compare it with what it uploads.

/// A running CRC-16 CCITT over bytes fed in pieces.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Crc16Ccitt {
    value: u16,
}

impl Crc16Ccitt {
    /// Starts a checksum (initial value 0xFFFF).
    pub const fn new() -> Self {
        Crc16Ccitt { value: 0xFFFF }
    }

    /// Feeds bytes.
    pub fn update(&mut self, bytes: &[u8]) {
        for &byte in bytes {
            self.value ^= u16::from(byte) << 8;
            for _ in 0..8 {
                self.value = if self.value & 0x8000 != 0 {
                    (self.value << 1) ^ 0x1021
                } else {
                    self.value << 1
                };
            }
        }
    }

    /// The checksum of the bytes fed so far.
    pub const fn value(&self) -> u16 {
        self.value
    }
}

impl Default for Crc16Ccitt {
    fn default() -> Self {
        Self::new()
    }
}

/// The CRC-16 CCITT of `bytes` in one call.
pub fn crc16_ccitt(bytes: &[u8]) -> u16 {
    let mut crc = Crc16Ccitt::new();
    crc.update(bytes);
    crc.value()
}
