//! The i.MX RT1062 boot ROM's FlexSPI NOR driver, which both images use on the Teensy's QSPI
//! flash: the CCM's calibration store erases and programs through it, and every image reads
//! through it to tell a Teensy 4.0 from a 4.1 ([`identify`], decided by
//! [`Teensy::from_probe`](crate::board_check::Teensy::from_probe)).
//!
//! The ROM API tree's layout is NXP's (`fsl_romapi.h` for the MIMXRT1062): the tree's fifth
//! word points at the FlexSPI NOR driver interface, whose words 2, 4, 5 and 6 are program,
//! erase, read and clear_cache. Assumed until the bench day: the bring-up images print what
//! [`identify`] found at start-up (docs/bench-day.md, step 1).
//!
//! The flash cannot be read through the AHB while it erases or programs. The images run from
//! RAM (imxrt-rt copies code to ITCM and data to DTCM/OCRAM at boot), but to be safe
//! interrupts are off for each ROM operation, so nothing can reach the flash meanwhile.

use crate::board_check::{IVT_OFFSET, Probe, Teensy, WRAP_OFFSET};

/// Where the FlexSPI maps the flash for reads.
pub const FLASH_BASE: usize = 0x6000_0000;
/// The ROM's pointer to its API tree.
const ROM_API_TREE: usize = 0x0020_001C;
/// The FlexSPI instance the boot flash hangs on (the ROM counts from 0).
const INSTANCE: u32 = 0;
/// `kStatus_Success`.
const SUCCESS: i32 = 0;
/// The word of the configuration block that holds serial flash A1's size
/// (`flexspi_mem_config_t.sflashA1Size`, offset 0x50).
const A1_SIZE_WORD: usize = 0x50 / 4;

/// The ROM driver's copy of the flash's configuration block (`flexspi_nor_config_t`, 512
/// bytes), word-aligned as the ROM reads it.
#[repr(C, align(4))]
pub struct NorConfig(pub [u32; 128]);

impl NorConfig {
    /// The boot configuration block the running image started with (the first 512 bytes of
    /// flash).
    pub fn from_flash() -> Self {
        let mut config = Self([0; 128]);
        for (index, word) in config.0.iter_mut().enumerate() {
            // SAFETY: the boot configuration block is the first 512 bytes of the mapped flash,
            // always readable.
            *word = unsafe { core::ptr::read_volatile((FLASH_BASE + 4 * index) as *const u32) };
        }
        config
    }
}

type ProgramFn = unsafe extern "C" fn(u32, *mut NorConfig, u32, *const u32) -> i32;
type EraseFn = unsafe extern "C" fn(u32, *mut NorConfig, u32, u32) -> i32;
type ReadFn = unsafe extern "C" fn(u32, *mut NorConfig, *mut u32, u32, u32) -> i32;
type ClearCacheFn = unsafe extern "C" fn(u32);

/// The ROM's FlexSPI NOR functions the images call.
pub struct RomDriver {
    program: ProgramFn,
    erase: EraseFn,
    read: ReadFn,
    clear_cache: ClearCacheFn,
}

/// A ROM operation did not succeed (its status code).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RomError(pub i32);

impl RomDriver {
    /// Reads the function pointers from the ROM API tree.
    pub fn locate() -> Self {
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
                read: core::mem::transmute::<usize, ReadFn>(word(5)),
                clear_cache: core::mem::transmute::<usize, ClearCacheFn>(word(6)),
            }
        }
    }

    /// Runs `operation` with interrupts off, then resets the FlexSPI's read buffers.
    fn run(&self, operation: impl FnOnce() -> i32) -> Result<(), RomError> {
        let status = cortex_m::interrupt::free(|_| {
            let status = operation();
            // SAFETY: the ROM function resets the FlexSPI's AHB read buffers; interrupts are off.
            unsafe { (self.clear_cache)(INSTANCE) };
            status
        });
        if status == SUCCESS {
            Ok(())
        } else {
            Err(RomError(status))
        }
    }

    /// Erases `len` bytes from flash offset `offset` (whole sectors).
    pub fn erase(&self, config: &mut NorConfig, offset: u32, len: u32) -> Result<(), RomError> {
        // SAFETY: the ROM's erase of the given sectors, interrupts off (`run`); the caller has
        // checked the range against the chip ([`Teensy::writable`]).
        self.run(|| unsafe { (self.erase)(INSTANCE, config, offset, len) })
    }

    /// Programs one 256-byte page at flash offset `offset` from `page`.
    pub fn program(
        &self,
        config: &mut NorConfig,
        offset: u32,
        page: &[u32; 64],
    ) -> Result<(), RomError> {
        // SAFETY: the ROM programs one page from `page`, interrupts off (`run`); the caller
        // has checked the range against the chip.
        self.run(|| unsafe { (self.program)(INSTANCE, config, offset, page.as_ptr()) })
    }

    /// Reads `out.len()` words from flash offset `offset` with IP commands (not the AHB).
    pub fn read(
        &self,
        config: &mut NorConfig,
        offset: u32,
        out: &mut [u32],
    ) -> Result<(), RomError> {
        let len = u32::try_from(out.len() * 4).map_err(|_| RomError(-1))?;
        // SAFETY: the ROM reads `len` bytes into `out`, which holds them; interrupts off.
        self.run(|| unsafe { (self.read)(INSTANCE, config, out.as_mut_ptr(), offset, len) })
    }
}

/// Which Teensy this is: the flash's boot configuration block and its IVT (16 bytes each)
/// beside the same places 2 MiB further, read with a copy of the boot block that declares
/// 8 MiB (so the ROM lets the read through); `None` if any read failed. Reads only: nothing is
/// written.
pub fn identify() -> Option<Teensy> {
    let rom = RomDriver::locate();
    let mut config = NorConfig::from_flash();
    if let Some(size) = config.0.get_mut(A1_SIZE_WORD) {
        *size = Teensy::T41.flash_bytes();
    }
    let mut probe = Probe {
        origin: [0; 4],
        origin_at_wrap: [0; 4],
        ivt: [0; 4],
        ivt_at_wrap: [0; 4],
    };
    rom.read(&mut config, 0, &mut probe.origin).ok()?;
    rom.read(&mut config, WRAP_OFFSET, &mut probe.origin_at_wrap)
        .ok()?;
    rom.read(&mut config, IVT_OFFSET, &mut probe.ivt).ok()?;
    rom.read(
        &mut config,
        WRAP_OFFSET + IVT_OFFSET,
        &mut probe.ivt_at_wrap,
    )
    .ok()?;
    Teensy::from_probe(&probe)
}
