//! Which Teensy an image runs on, and whether it is the one it was built for.
//!
//! The Teensy 4.0 and 4.1 carry the same i.MX RT1062; what tells them apart is the QSPI flash
//! beside it: 2 MiB on the 4.0 (a W25Q16JV), 8 MiB on the 4.1 (a W25Q64JV), per PJRC's boards.
//! The images' own boot configuration block cannot say which: the Rust BSP's block declares
//! 2 MiB on both boards. The chip can: a 2 MiB part ignores the address bits above its size, so
//! reading 2 MiB past the start of flash (with a configuration that lets the read through)
//! returns the start again on a 4.0 and other bytes on a 4.1. The firmware reads both places
//! (`chip`); this module decides from what it read, and is tested on the host.
//!
//! An image on the wrong board (or on one it cannot identify) drives no output, never writes
//! flash, and names itself and the board it found on the console and in its USB product
//! string, so the port's name says it before anyone types.

use core::fmt;

/// The boards the images are built for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Teensy {
    /// Teensy 4.0: the PCC's board.
    T40,
    /// Teensy 4.1: the CCM's board.
    T41,
}

/// The tag the boot configuration block starts with ("FCFB", little-endian).
pub const FCB_TAG: u32 = 0x4246_4346;

/// Where a 2 MiB flash wraps to its start.
pub const WRAP_OFFSET: u32 = 2 * 1024 * 1024;

/// Where the image vector table (IVT) sits in flash for FlexSPI NOR boot (i.MX RT1060 RM,
/// "Image Vector Table and Boot Data"): the second place compared, so that two copies of
/// the boot configuration block alone never make a 4.1 look like a 4.0.
pub const IVT_OFFSET: u32 = 0x1000;

/// The IVT header's tag byte (its lowest byte, little-endian).
pub const IVT_TAG: u8 = 0xD1;

/// Reads 2 MiB on that differ from the start in this many bits or fewer are a garbled copy,
/// not other data.
const GARBLED_BITS: u32 = 8;

/// What the board check read: 16 bytes at the flash's start and at its IVT, and the same two
/// [`WRAP_OFFSET`] further on, all with 8 MiB addressing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Probe {
    /// The boot configuration block's first words (offset 0).
    pub origin: [u32; 4],
    /// The words at [`WRAP_OFFSET`].
    pub origin_at_wrap: [u32; 4],
    /// The IVT's first words ([`IVT_OFFSET`]).
    pub ivt: [u32; 4],
    /// The words at [`WRAP_OFFSET`] + [`IVT_OFFSET`].
    pub ivt_at_wrap: [u32; 4],
}

impl Teensy {
    /// The board's name.
    pub const fn name(self) -> &'static str {
        match self {
            Self::T40 => "Teensy 4.0",
            Self::T41 => "Teensy 4.1",
        }
    }

    /// Its flash (bytes).
    pub const fn flash_bytes(self) -> u32 {
        match self {
            Self::T40 => 2 * 1024 * 1024,
            Self::T41 => 8 * 1024 * 1024,
        }
    }

    /// The top of its flash that PJRC reserves for the restore program and EEPROM emulation
    /// (bytes): 64 KiB of the 4.0's, 256 KiB of the 4.1's (PJRC's Teensy 4.0 and 4.1 pages).
    /// Erasing there can take the 15-second restore away.
    pub const fn reserved_bytes(self) -> u32 {
        match self {
            Self::T40 => 64 * 1024,
            Self::T41 => 256 * 1024,
        }
    }

    /// Whether an image may erase or program `len` bytes at flash offset `offset`: inside the
    /// chip's flash and below its reserved top.
    pub const fn writable(self, offset: u32, len: u32) -> bool {
        let limit = self.flash_bytes() - self.reserved_bytes();
        match offset.checked_add(len) {
            Some(end) => end <= limit,
            None => false,
        }
    }

    /// The board from what the check read: a 4.0 when both the boot configuration block and
    /// the IVT repeat [`WRAP_OFFSET`] further on, a 4.1 otherwise; `None` when either is not
    /// where the boot ROM needs it (the read did not work, so nothing can be concluded).
    ///
    /// A 4.1 needs the reads 2 MiB on to be other data, not a failed read: all zeros, or a
    /// copy of the start with a few bits wrong, proves nothing and is `None` too. (An erased
    /// 4.1 reads all ones there, which a failing read could also return: that case stays
    /// the bench day's, step 1.2.)
    pub fn from_probe(probe: &Probe) -> Option<Self> {
        let [ivt_header, ..] = probe.ivt;
        if probe.origin[0] != FCB_TAG || ivt_header.to_le_bytes()[0] != IVT_TAG {
            return None;
        }
        let at_wrap = || probe.origin_at_wrap.iter().chain(&probe.ivt_at_wrap);
        let start = probe.origin.iter().chain(&probe.ivt);
        let differing: u32 = start
            .zip(at_wrap())
            .map(|(a, b)| (a ^ b).count_ones())
            .sum();
        if differing == 0 {
            return Some(Self::T40);
        }
        if differing <= GARBLED_BITS || at_wrap().all(|word| *word == 0) {
            return None;
        }
        Some(Self::T41)
    }
}

/// An image's check of the board it runs on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BoardCheck {
    /// The image: `AER CCM`, `AER PCC bring-up`.
    pub image: &'static str,
    /// The board it was built for.
    pub built_for: Teensy,
    /// The board it found; `None`: it could not tell.
    pub found: Option<Teensy>,
}

impl BoardCheck {
    /// The check as it reads on the right board (the simulations' and the documentation's).
    pub const fn passed(image: &'static str, board: Teensy) -> Self {
        Self {
            image,
            built_for: board,
            found: Some(board),
        }
    }

    /// True when it runs on the board it was built for.
    pub fn right(&self) -> bool {
        self.found == Some(self.built_for)
    }

    /// The USB product string on a board that is not the right one (the port's
    /// `/dev/serial/by-id` name carries it).
    pub fn wrong_board_product(&self) -> &'static str {
        match (self.built_for, self.found) {
            (Teensy::T40, Some(Teensy::T41)) => "AER PCC image on a Teensy 4.1 WRONG BOARD",
            (Teensy::T41, Some(Teensy::T40)) => "AER CCM image on a Teensy 4.0 WRONG BOARD",
            (Teensy::T40, _) => "AER PCC image on an unknown board",
            (Teensy::T41, _) => "AER CCM image on an unknown board",
        }
    }
}

impl fmt::Display for BoardCheck {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.found {
            Some(found) if found == self.built_for => write!(
                f,
                "board: {} ({} MiB of flash, checked)",
                found.name(),
                found.flash_bytes() / (1024 * 1024)
            ),
            Some(found) => write!(
                f,
                "WRONG BOARD: this is the {} image, built for a {}, and it runs on a {} ({} MiB of flash). It drives no output and writes no flash: type `bootloader` (or set 134 baud) and flash the {} image (docs/bench-day.md, step 1)",
                self.image,
                self.built_for.name(),
                found.name(),
                found.flash_bytes() / (1024 * 1024),
                match found {
                    Teensy::T40 => "PCC's",
                    Teensy::T41 => "CCM's",
                }
            ),
            None => write!(
                f,
                "UNKNOWN BOARD: this is the {} image, built for a {}, and the flash did not answer the board check. It drives no output and writes no flash: type `bootloader` (or set 134 baud), flash the bring-up image and report its start-up lines (docs/bench-day.md, step 1)",
                self.image,
                self.built_for.name()
            ),
        }
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::string::ToString;

    const FCB: [u32; 4] = [FCB_TAG, 0x5601_0000, 0, 0x0003_0301];

    /// An IVT as imxrt-rt writes it: header (tag 0xD1, length 0x20, version 0x41), entry
    /// point, reserved, DCD.
    const IVT: [u32; 4] = [0x4120_00D1, 0x6000_2000, 0, 0];

    fn probe(origin_at_wrap: [u32; 4], ivt_at_wrap: [u32; 4]) -> Probe {
        Probe {
            origin: FCB,
            origin_at_wrap,
            ivt: IVT,
            ivt_at_wrap,
        }
    }

    #[test]
    fn a_wrapped_read_is_a_teensy_4_0_and_other_bytes_a_4_1() {
        assert_eq!(Teensy::from_probe(&probe(FCB, IVT)), Some(Teensy::T40));
        let erased = [u32::MAX; 4];
        assert_eq!(
            Teensy::from_probe(&probe(erased, erased)),
            Some(Teensy::T41)
        );
        assert_eq!(
            Teensy::from_probe(&probe([FCB_TAG, 0, 0, 0], IVT)),
            Some(Teensy::T41),
            "only the whole block repeated is a wrap"
        );
        assert_eq!(
            Teensy::from_probe(&probe(FCB, erased)),
            Some(Teensy::T41),
            "a copy of the configuration block 2 MiB on, without the IVT, is no wrap"
        );
        let unread = Probe {
            origin: [0; 4],
            origin_at_wrap: [0; 4],
            ivt: [0; 4],
            ivt_at_wrap: [0; 4],
        };
        assert_eq!(
            Teensy::from_probe(&unread),
            None,
            "no block read: no conclusion"
        );
        let mut garbled = FCB;
        garbled[1] ^= 1;
        assert_eq!(
            Teensy::from_probe(&probe(garbled, IVT)),
            None,
            "a copy with a bit wrong is a bad read, not a 4.1"
        );
        assert_eq!(
            Teensy::from_probe(&probe([0; 4], [0; 4])),
            None,
            "zeros are a read that returned nothing"
        );
        let no_ivt = Probe {
            ivt: [0; 4],
            ivt_at_wrap: [0; 4],
            ..probe(FCB, IVT)
        };
        assert_eq!(
            Teensy::from_probe(&no_ivt),
            None,
            "no IVT where the ROM boots from"
        );
    }

    #[test]
    fn each_image_runs_only_on_its_own_board() {
        for (image, built_for) in [
            ("AER CCM", Teensy::T41),
            ("AER CCM bring-up", Teensy::T41),
            ("AER PCC", Teensy::T40),
            ("AER PCC bring-up", Teensy::T40),
        ] {
            for found in [Some(Teensy::T40), Some(Teensy::T41), None] {
                let check = BoardCheck {
                    image,
                    built_for,
                    found,
                };
                assert_eq!(check.right(), found == Some(built_for), "{check}");
                let line = check.to_string();
                if check.right() {
                    assert!(line.starts_with("board: "), "{line}");
                } else {
                    assert!(line.contains(image), "{line}");
                    assert!(
                        line.contains("drives no output and writes no flash"),
                        "{line}"
                    );
                    let product = check.wrong_board_product();
                    assert!(product.contains(if built_for == Teensy::T41 {
                        "CCM"
                    } else {
                        "PCC"
                    }));
                    // USB string descriptors hold at most 126 UTF-16 characters.
                    assert!(product.len() <= 126);
                }
            }
        }
    }

    #[test]
    fn the_reserved_top_of_each_flash_is_never_writable() {
        // The CCM's calibration slots (the last two sectors of the first 2 MiB).
        let slots = [0x001F_E000, 0x001F_F000];
        for slot in slots {
            assert!(Teensy::T41.writable(slot, 4096), "{slot:#x} on a 4.1");
            assert!(
                !Teensy::T40.writable(slot, 4096),
                "{slot:#x} on a 4.0 is its restore program's"
            );
        }
        assert!(Teensy::T40.writable(0x001E_F000, 4096));
        assert!(!Teensy::T41.writable(0x007C_0000, 1));
        assert!(Teensy::T41.writable(0x007B_F000, 4096));
        assert!(!Teensy::T41.writable(u32::MAX, 2), "no overflow");
    }
}
