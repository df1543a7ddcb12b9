//! The calibration's two flash slots on the Teensy's QSPI flash, written through the i.MX RT1062
//! boot ROM's FlexSPI NOR driver (the ROM API tree; NXP's `fsl_romapi.c` for the MIMXRT1062
//! gives its layout).
//!
//! The flash cannot be read while it erases or programs. The images run from RAM (imxrt-rt
//! copies code to ITCM and data to DTCM/OCRAM at boot), but to be safe interrupts are off for
//! each ROM operation, so nothing can reach the flash meanwhile, and the data cache and the
//! FlexSPI's read buffers are invalidated before the slots are read again. An erase takes up
//! to 400 ms (W25Q64JV sector erase, worst case), within the 1 s hardware watchdog, and stalls
//! every task: this is why the store saves only at standstill with the tractive system off
//! (a stale-sensor fault for that moment is expected and clears).
//!
//! Assumed (the bring-up image's `cal save` / `cal load` check them on the bench):
//! - the slot offsets below: the last two 4 KiB sectors of the first 2 MiB, the flash size the
//!   Teensy's boot configuration block (teensy4-fcb 0.5) declares; the CCM's image ends far
//!   below (about 200 KiB), and on the Teensy 4.1's 8 MiB part nothing else lives there;
//! - the boot configuration block at the start of flash carries the sector-erase and
//!   page-program sequences the ROM driver uses (teensy4-fcb defines them);
//! - whether loading a new image with the Teensy loader keeps these sectors.

use crate::calibration::store::{CalibrationFlash, FlashError, Slot};

/// Where the FlexSPI maps the flash for reads.
const FLASH_BASE: usize = 0x6000_0000;
/// Each slot's offset in the flash (assumed, see the module's description).
pub const SLOT_OFFSETS: [u32; 2] = [0x001F_E000, 0x001F_F000];
/// One erase sector.
pub const SLOT_LEN: usize = 4096;
/// The flash's program page.
const PAGE_LEN: usize = 256;
/// The ROM's pointer to its API tree.
const ROM_API_TREE: usize = 0x0020_001C;
/// The FlexSPI instance the boot flash hangs on (the ROM counts from 0).
const INSTANCE: u32 = 0;
/// `kStatus_Success`.
const SUCCESS: i32 = 0;

/// The ROM driver's copy of the flash's configuration block (`flexspi_nor_config_t`, 512
/// bytes), word-aligned as the ROM reads it.
#[repr(C, align(4))]
struct NorConfig([u32; 128]);

type EraseFn = unsafe extern "C" fn(u32, *mut NorConfig, u32, u32) -> i32;
type ProgramFn = unsafe extern "C" fn(u32, *mut NorConfig, u32, *const u32) -> i32;
type ClearCacheFn = unsafe extern "C" fn(u32);

/// The ROM's FlexSPI NOR functions this driver calls.
struct RomDriver {
    program: ProgramFn,
    erase: EraseFn,
    clear_cache: ClearCacheFn,
}

impl RomDriver {
    /// Reads the function pointers from the ROM API tree: the tree's fifth word points at the
    /// driver interface, whose words 2, 4 and 6 are program, erase and clear_cache.
    fn locate() -> Self {
        // SAFETY: the boot ROM is always mapped and these words are its read-only API tree;
        // the transmutes give the functions the signatures NXP documents for them.
        unsafe {
            let tree = core::ptr::read_volatile(ROM_API_TREE as *const usize);
            let driver = core::ptr::read_volatile((tree + 16) as *const usize);
            let word =
                |index: usize| core::ptr::read_volatile((driver + 4 * index) as *const usize);
            Self {
                program: core::mem::transmute::<usize, ProgramFn>(word(2)),
                erase: core::mem::transmute::<usize, EraseFn>(word(4)),
                clear_cache: core::mem::transmute::<usize, ClearCacheFn>(word(6)),
            }
        }
    }
}

/// The calibration slots on the Teensy's flash.
pub struct TeensyFlash {
    config: NorConfig,
    rom: RomDriver,
}

impl TeensyFlash {
    /// Takes the flash's configuration from the boot block the image starts with.
    pub fn new() -> Self {
        let mut config = NorConfig([0; 128]);
        for (index, word) in config.0.iter_mut().enumerate() {
            // SAFETY: the boot configuration block is the first 512 bytes of the mapped flash.
            *word = unsafe { core::ptr::read_volatile((FLASH_BASE + 4 * index) as *const u32) };
        }
        Self {
            config,
            rom: RomDriver::locate(),
        }
    }

    /// Runs one ROM operation with interrupts off, then drops every cached copy of the slot.
    fn operate(
        &mut self,
        slot: Slot,
        operation: impl FnOnce(&mut Self) -> i32,
    ) -> Result<(), FlashError> {
        let status = cortex_m::interrupt::free(|_| {
            let status = operation(self);
            // SAFETY: the ROM function resets the FlexSPI's AHB read buffers; interrupts are off.
            unsafe { (self.rom.clear_cache)(INSTANCE) };
            status
        });
        // SAFETY: invalidating (not cleaning) the slot's lines is right: nothing writes the
        // flash through the cache. The SCB is only used here for cache maintenance.
        unsafe {
            let mut peripherals = cortex_m::Peripherals::steal();
            peripherals
                .SCB
                .invalidate_dcache_by_address(slot_address(slot), SLOT_LEN);
        }
        if status == SUCCESS {
            Ok(())
        } else {
            Err(FlashError::Device)
        }
    }
}

impl Default for TeensyFlash {
    fn default() -> Self {
        Self::new()
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
        let start = slot_offset(slot);
        self.operate(slot, |flash| {
            // SAFETY: the ROM's erase of one sector of the slot, interrupts off (`operate`).
            unsafe { (flash.rom.erase)(INSTANCE, &mut flash.config, start, SLOT_LEN as u32) }
        })
    }

    fn program(&mut self, slot: Slot, offset: usize, data: &[u8]) -> Result<(), FlashError> {
        if offset.saturating_add(data.len()) > SLOT_LEN {
            return Err(FlashError::OutOfBounds);
        }
        // Page by page: bytes outside `data` stay 0xFF, which programming leaves as they are.
        let mut at = offset;
        let end = offset + data.len();
        while at < end {
            let page_start = at - at % PAGE_LEN;
            let page_end = (page_start + PAGE_LEN).min(end);
            let mut page = [u32::MAX; PAGE_LEN / 4];
            for address in at..page_end {
                let byte = data[address - offset];
                let (word, shift) = ((address - page_start) / 4, 8 * ((address - page_start) % 4));
                page[word] &= !(0xFF << shift) | (u32::from(byte) << shift);
            }
            let destination = slot_offset(slot) + page_start as u32;
            self.operate(slot, |flash| {
                // SAFETY: the ROM programs one 256-byte page of the slot from `page`,
                // interrupts off (`operate`).
                unsafe {
                    (flash.rom.program)(INSTANCE, &mut flash.config, destination, page.as_ptr())
                }
            })?;
            at = page_end;
        }
        Ok(())
    }
}
