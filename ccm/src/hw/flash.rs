//! The calibration's two flash slots on the Teensy's QSPI flash, written through the i.MX RT1062
//! boot ROM's FlexSPI NOR driver (`aer_console::chip`, shared with the board check).
//!
//! Every erase and program is checked against the chip the image found at start-up: never
//! outside its flash or in the top PJRC reserves for the restore program and EEPROM emulation
//! ([`Teensy::writable`]). The data cache is invalidated before the slots are read again
//! after a write. An erase takes up to 400 ms (W25Q64JV sector erase, worst case), within the
//! 1 s hardware watchdog, and stalls
//! every task: this is why the store saves only at standstill with the tractive system off
//! (a stale-sensor fault for that moment is expected and clears).
//!
//! Assumed (the bring-up image's `cal save` / `cal load` check them on the bench):
//! - the slot offsets below: the last two 4 KiB sectors of the first 2 MiB, the flash size the
//!   Teensy's boot configuration block (teensy4-fcb 0.5) declares; the CCM's image ends far
//!   below (about 200 KiB), and on the Teensy 4.1's 8 MiB part nothing else lives there (on a
//!   Teensy 4.0 they would be its restore program's sectors: [`Teensy::writable`] refuses);
//! - the boot configuration block at the start of flash carries the sector-erase and
//!   page-program sequences the ROM driver uses (teensy4-fcb defines them);
//! - whether loading a new image with the Teensy loader keeps these sectors.

use crate::calibration::store::{CalibrationFlash, FlashError, Slot};
use aer_console::board_check::Teensy;
use aer_console::chip::{FLASH_BASE, NorConfig, RomDriver};

/// Each slot's offset in the flash (assumed, see the module's description).
pub const SLOT_OFFSETS: [u32; 2] = [0x001F_E000, 0x001F_F000];
/// One erase sector.
pub const SLOT_LEN: usize = 4096;
/// The flash's program page.
const PAGE_LEN: usize = 256;

/// The calibration slots on the Teensy's flash.
pub struct TeensyFlash {
    config: NorConfig,
    rom: RomDriver,
    chip: Teensy,
}

impl TeensyFlash {
    /// Takes the flash's configuration from the boot block the image starts with; every write
    /// is checked against `chip`, the board the image found.
    pub fn new(chip: Teensy) -> Self {
        Self {
            config: NorConfig::from_flash(),
            rom: RomDriver::locate(),
            chip,
        }
    }

    /// The slot's offset, if the chip lets an image write `len` bytes from `at` in it.
    fn writable(&self, slot: Slot, at: usize, len: usize) -> Result<u32, FlashError> {
        let offset = slot_offset(slot);
        let start = u32::try_from(at).map_err(|_| FlashError::OutOfBounds)?;
        let len = u32::try_from(len).map_err(|_| FlashError::OutOfBounds)?;
        if !self.chip.writable(offset.saturating_add(start), len) {
            return Err(FlashError::Reserved);
        }
        Ok(offset)
    }

    /// Drops every cached copy of the slot, so it is read from the flash again.
    fn invalidate(slot: Slot) {
        // SAFETY: invalidating (not cleaning) the slot's lines is right: nothing writes the
        // flash through the cache. The SCB is only used here for cache maintenance.
        unsafe {
            let mut peripherals = cortex_m::Peripherals::steal();
            peripherals
                .SCB
                .invalidate_dcache_by_address(slot_address(slot), SLOT_LEN);
        }
    }
}

fn slot_offset(slot: Slot) -> u32 {
    match slot {
        Slot::A => SLOT_OFFSETS[0],
        Slot::B => SLOT_OFFSETS[1],
    }
}

fn slot_address(slot: Slot) -> usize {
    FLASH_BASE + slot_offset(slot) as usize
}

impl CalibrationFlash for TeensyFlash {
    fn read(&mut self, slot: Slot, offset: usize, out: &mut [u8]) -> Result<(), FlashError> {
        if offset.saturating_add(out.len()) > SLOT_LEN {
            return Err(FlashError::OutOfBounds);
        }
        let start = slot_address(slot) + offset;
        for (index, byte) in out.iter_mut().enumerate() {
            // SAFETY: inside the slot, which is mapped flash.
            *byte = unsafe { core::ptr::read_volatile((start + index) as *const u8) };
        }
        Ok(())
    }

    fn erase(&mut self, slot: Slot) -> Result<(), FlashError> {
        let start = self.writable(slot, 0, SLOT_LEN)?;
        let result = self.rom.erase(&mut self.config, start, SLOT_LEN as u32);
        Self::invalidate(slot);
        result.map_err(|_| FlashError::Device)
    }

    fn program(&mut self, slot: Slot, offset: usize, data: &[u8]) -> Result<(), FlashError> {
        if offset.saturating_add(data.len()) > SLOT_LEN {
            return Err(FlashError::OutOfBounds);
        }
        let slot_start = self.writable(slot, offset, data.len())?;
        // Page by page: bytes outside `data` stay 0xFF, which programming leaves as they are.
        let mut at = offset;
        let end = offset + data.len();
        while at < end {
            let page_start = at - at % PAGE_LEN;
            let page_end = (page_start + PAGE_LEN).min(end);
            let mut page = [u32::MAX; PAGE_LEN / 4];
            for address in at..page_end {
                let byte = data.get(address - offset).copied().unwrap_or(0xFF);
                let (word, shift) = ((address - page_start) / 4, 8 * ((address - page_start) % 4));
                if let Some(word) = page.get_mut(word) {
                    *word &= !(0xFF << shift) | (u32::from(byte) << shift);
                }
            }
            let destination = slot_start + page_start as u32;
            let result = self.rom.program(&mut self.config, destination, &page);
            Self::invalidate(slot);
            result.map_err(|_| FlashError::Device)?;
            at = page_end;
        }
        Ok(())
    }
}
