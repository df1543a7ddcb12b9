//! Reads a firmware ELF: what goes into flash (for the HEX file) and how much flash and RAM
//! it uses, by i.MX RT1062 memory region.

use anyhow::{Context, Result, bail};
use object::LittleEndian;
use object::elf::{FileHeader32, PT_LOAD, SHF_ALLOC};
use object::read::elf::{FileHeader, ProgramHeader, SectionHeader};

/// A memory region of the i.MX RT1062 as the Teensy 4.x uses it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Region {
    /// Name in the report.
    pub name: &'static str,
    /// First address.
    pub start: u32,
    /// Size in bytes.
    pub size: u32,
}

/// External QSPI flash (Teensy 4.0: 2 MiB; PJRC reserves the top 64 KiB for the restore
/// program and EEPROM emulation: `aer_console::board_check::Teensy::reserved_bytes`).
pub const FLASH_T40: Region = Region {
    name: "flash",
    start: 0x6000_0000,
    size: 2 * 1024 * 1024 - 64 * 1024,
};
/// External QSPI flash (Teensy 4.1: 8 MiB; PJRC reserves the top 256 KiB).
pub const FLASH_T41: Region = Region {
    name: "flash",
    start: 0x6000_0000,
    size: 8 * 1024 * 1024 - 256 * 1024,
};

/// On-chip RAM regions: FlexRAM (512 KiB shared by ITCM and DTCM in 32 KiB banks) and OCRAM2.
pub const RAM: [Region; 3] = [
    Region {
        name: "ITCM (code)",
        start: 0x0000_0000,
        size: 512 * 1024,
    },
    Region {
        name: "DTCM (data, stack)",
        start: 0x2000_0000,
        size: 512 * 1024,
    },
    Region {
        name: "OCRAM (rodata, heap)",
        start: 0x2020_0000,
        size: 512 * 1024,
    },
];
/// FlexRAM shared by ITCM and DTCM.
pub const FLEXRAM_BYTES: u32 = 512 * 1024;

/// What the ELF puts where.
pub struct Image {
    /// Loadable bytes by physical (load) address, as flashed.
    pub load: Vec<(u32, Vec<u8>)>,
    /// Bytes per RAM region, in the order of [`RAM`].
    pub ram: [u32; 3],
}

impl Image {
    /// Reads an ELF file's program and section headers.
    pub fn read(elf_bytes: &[u8]) -> Result<Self> {
        let elf = FileHeader32::<LittleEndian>::parse(elf_bytes).context("not a 32-bit ELF")?;
        let endian = elf.endian().context("ELF byte order")?;
        let mut load = Vec::new();
        for segment in elf
            .program_headers(endian, elf_bytes)
            .context("program headers")?
        {
            if segment.p_type(endian) != PT_LOAD || segment.p_filesz(endian) == 0 {
                continue;
            }
            let data = segment
                .data(endian, elf_bytes)
                .map_err(|()| anyhow::anyhow!("segment data outside the file"))?;
            load.push((segment.p_paddr(endian), data.to_vec()));
        }
        load.sort_by_key(|(address, _)| *address);
        let mut ram = [0u32; 3];
        let sections = elf.sections(endian, elf_bytes).context("section headers")?;
        for section in sections.iter() {
            if section.sh_flags(endian) & SHF_ALLOC == 0 {
                continue;
            }
            let address = section.sh_addr(endian);
            for (used, region) in ram.iter_mut().zip(RAM) {
                if address >= region.start && address - region.start < region.size {
                    *used += section.sh_size(endian);
                }
            }
        }
        if load.is_empty() {
            bail!("the ELF has nothing to load");
        }
        Ok(Self { load, ram })
    }

    /// Bytes written to `flash`.
    pub fn flash_bytes(&self, flash: Region) -> u32 {
        self.load
            .iter()
            .filter(|(address, _)| *address >= flash.start && address - flash.start < flash.size)
            .map(|(_, bytes)| bytes.len() as u32)
            .sum()
    }

    /// Loadable bytes outside `flash` (a linker-script mistake: they would never be flashed).
    pub fn outside(&self, flash: Region) -> u32 {
        self.load
            .iter()
            .filter(|(address, _)| !(*address >= flash.start && address - flash.start < flash.size))
            .map(|(_, bytes)| bytes.len() as u32)
            .sum()
    }
}
