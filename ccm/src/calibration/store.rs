//! The working page saved to flash, and loaded back at start-up.
//!
//! Two slots (two erase units), each holding at most one record: a header (magic, generation,
//! the EPK of the schema that wrote it), the page, and a CRC-32 over all of it, programmed
//! last. A save erases and programs the slot that does not hold the newest good copy, so a power
//! cut at any point leaves that copy loadable: the half-written record fails its CRC. At
//! start-up the newest record with a good CRC, this firmware's EPK and values the CCM accepts
//! is loaded; otherwise the schema's defaults, and [`Startup`] says why.
//!
//! The flash itself sits behind [`CalibrationFlash`]: the firmware's driver on the Teensy, a
//! [`RamFlash`] on the host and in the car model.

use super::{Calibration, SensorCalibration};
use aer::calibration::{PAGE_LEN, VehicleState};

/// First bytes of every record; a slot without them is empty or torn.
pub const RECORD_MAGIC: [u8; 4] = *b"AERC";

/// Bytes the record keeps for the EPK (zero-padded); a longer EPK does not build.
pub const EPK_FIELD_LEN: usize = 48;

const MAGIC_AT: usize = 0;
const GENERATION_AT: usize = 4;
const EPK_AT: usize = 8;
const PAGE_LEN_AT: usize = EPK_AT + EPK_FIELD_LEN;
const PAGE_AT: usize = PAGE_LEN_AT + 2;
const CRC_AT: usize = PAGE_AT + PAGE_LEN;

/// Bytes of one record, CRC included.
pub const RECORD_LEN: usize = CRC_AT + 4;

/// One of the two erase units the records live in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Slot {
    /// The first.
    A,
    /// The second.
    B,
}

impl Slot {
    /// The other slot.
    pub const fn other(self) -> Self {
        match self {
            Self::A => Self::B,
            Self::B => Self::A,
        }
    }

    /// `A` or `B`, for console lines.
    pub const fn name(self) -> &'static str {
        match self {
            Self::A => "A",
            Self::B => "B",
        }
    }
}

/// The flash the records live in: NOR semantics, erase sets every byte of a slot to 0xFF and
/// programming only clears bits.
pub trait CalibrationFlash {
    /// Reads `out.len()` bytes of `slot` from `offset`.
    fn read(&mut self, slot: Slot, offset: usize, out: &mut [u8]) -> Result<(), FlashError>;
    /// Erases `slot`.
    fn erase(&mut self, slot: Slot) -> Result<(), FlashError>;
    /// Programs `data` into `slot` at `offset` (which must be erased).
    fn program(&mut self, slot: Slot, offset: usize, data: &[u8]) -> Result<(), FlashError>;
}

/// What the flash driver reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FlashError {
    /// The access lies outside the slot.
    OutOfBounds,
    /// The controller reported a failure (timeout, protection, verify error).
    Device,
    /// The slot lies outside the chip's flash, or in the top its bootloader reserves: this
    /// image is on a board it was not built for.
    Reserved,
}

/// What start-up loaded, as `CCM_Calibration.CCM_CalStartup` reports it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Startup {
    /// No record in either slot: the defaults.
    NoneSaved,
    /// The newest good copy.
    Saved {
        /// Where it was.
        slot: Slot,
        /// Its generation (each save counts one up).
        generation: u32,
    },
    /// A record was there but failed its CRC (a torn write, a worn cell): the defaults.
    Corrupt,
    /// Good records, but written by firmware of another schema (EPK): the defaults.
    OtherSchema,
    /// A good record of this schema whose values the CCM refuses (limits, sensor checks): the
    /// defaults.
    OutOfLimits,
}

impl Startup {
    /// The raw value of `CCM_CalStartup`.
    pub const fn raw(self) -> u8 {
        match self {
            Self::NoneSaved => 0,
            Self::Saved { .. } => 1,
            Self::Corrupt => 2,
            Self::OtherSchema => 3,
            Self::OutOfLimits => 4,
        }
    }

    /// Whether the saved copy is running (not the defaults).
    pub const fn is_saved(self) -> bool {
        matches!(self, Self::Saved { .. })
    }
}

impl core::fmt::Display for Startup {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::NoneSaved => f.write_str("calibration: the schema's defaults (none saved)"),
            Self::Saved { slot, generation } => write!(
                f,
                "calibration: saved copy {} (generation {generation})",
                slot.name()
            ),
            Self::Corrupt => f.write_str("calibration: the schema's defaults (saved copy corrupt)"),
            Self::OtherSchema => {
                f.write_str("calibration: the schema's defaults (saved copy is of another schema)")
            }
            Self::OutOfLimits => {
                f.write_str("calibration: the schema's defaults (saved copy outside the limits)")
            }
        }
    }
}

/// Why a save did not happen.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SaveError {
    /// Only at standstill with the tractive system off (writing the flash stalls the code
    /// running from it).
    NotAllowedNow,
    /// The EPK is longer than the record keeps.
    EpkTooLong,
    /// The flash failed; the previous copy is still there.
    Flash(FlashError),
}

impl core::fmt::Display for SaveError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::NotAllowedNow => {
                f.write_str("not saved: only at standstill with the tractive system off")
            }
            Self::EpkTooLong => f.write_str("not saved: the EPK does not fit the record"),
            Self::Flash(FlashError::OutOfBounds) => {
                f.write_str("not saved: the record does not fit the flash slot")
            }
            Self::Flash(FlashError::Device) => {
                f.write_str("not saved: the flash failed (the previous copy stays)")
            }
            Self::Flash(FlashError::Reserved) => f.write_str(
                "not saved: the slot is not this chip's to write (outside its flash or in the top its bootloader reserves)",
            ),
        }
    }
}

/// What start-up found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Loaded {
    /// The calibration to run: the saved copy's or the defaults.
    pub calibration: Calibration,
    /// Where it came from.
    pub startup: Startup,
}

impl Loaded {
    /// The one rule for what a firmware image runs: the saved copy start-up found, if it found
    /// a good one; else the schema's defaults with `measured`, the sensors
    /// `ccm/calibration.toml` records.
    pub fn or_measured(self, measured: SensorCalibration) -> Self {
        if self.startup.is_saved() {
            self
        } else {
            Self {
                calibration: measured.applied_to(Calibration::DEFAULT),
                startup: self.startup,
            }
        }
    }
}

/// Which slot holds the newest good copy, so a save never touches it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct CalibrationStore {
    newest: Option<(Slot, u32)>,
}

/// One slot's record as read.
enum Record {
    Empty,
    Corrupt,
    OtherSchema {
        generation: u32,
    },
    Good {
        generation: u32,
        page: [u8; PAGE_LEN],
    },
}

impl CalibrationStore {
    /// Reads both slots and picks the newest good copy of `epk` (see the module's
    /// description).
    pub fn load(flash: &mut impl CalibrationFlash, epk: &[u8]) -> (Self, Loaded) {
        let mut store = Self::default();
        let mut best: Option<(Slot, u32, Calibration)> = None;
        let mut worst = Startup::NoneSaved;
        for slot in [Slot::A, Slot::B] {
            match read_record(flash, slot, epk) {
                Record::Empty => {}
                Record::Corrupt => worst = more_telling(worst, Startup::Corrupt),
                Record::OtherSchema { generation } => {
                    worst = more_telling(worst, Startup::OtherSchema);
                    // Its generation still counts: a save must not go to the slot holding the
                    // newest record, whoever wrote it.
                    note_newest(&mut store, slot, generation);
                }
                Record::Good { generation, page } => {
                    note_newest(&mut store, slot, generation);
                    match accepted(&page) {
                        Some(calibration) if best.is_none_or(|(_, g, _)| newer(generation, g)) => {
                            best = Some((slot, generation, calibration));
                        }
                        Some(_) => {}
                        None => worst = more_telling(worst, Startup::OutOfLimits),
                    }
                }
            }
        }
        let loaded = match best {
            Some((slot, generation, calibration)) => Loaded {
                calibration,
                startup: Startup::Saved { slot, generation },
            },
            None => Loaded {
                calibration: Calibration::DEFAULT,
                startup: worst,
            },
        };
        (store, loaded)
    }

    /// Saves `page` as the newest copy, in the slot that does not hold the newest record.
    /// Refused unless the car stands with the tractive system off.
    pub fn save(
        &mut self,
        flash: &mut impl CalibrationFlash,
        page: &[u8; PAGE_LEN],
        epk: &[u8],
        state: VehicleState,
    ) -> Result<Startup, SaveError> {
        if state.moving || state.tractive_live {
            return Err(SaveError::NotAllowedNow);
        }
        if epk.len() > EPK_FIELD_LEN {
            return Err(SaveError::EpkTooLong);
        }
        let (slot, generation) = match self.newest {
            Some((slot, generation)) => (slot.other(), generation.wrapping_add(1)),
            None => (Slot::A, 1),
        };
        let mut record = [0u8; RECORD_LEN];
        record[MAGIC_AT..GENERATION_AT].copy_from_slice(&RECORD_MAGIC);
        record[GENERATION_AT..EPK_AT].copy_from_slice(&generation.to_le_bytes());
        record[EPK_AT..EPK_AT + epk.len()].copy_from_slice(epk);
        record[PAGE_LEN_AT..PAGE_AT].copy_from_slice(&(PAGE_LEN as u16).to_le_bytes());
        record[PAGE_AT..CRC_AT].copy_from_slice(page);
        let crc = crc32(&record[..CRC_AT]);
        flash.erase(slot).map_err(SaveError::Flash)?;
        flash
            .program(slot, 0, &record[..CRC_AT])
            .map_err(SaveError::Flash)?;
        // The CRC last: until it is in, the record does not count.
        flash
            .program(slot, CRC_AT, &crc.to_le_bytes())
            .map_err(SaveError::Flash)?;
        self.newest = Some((slot, generation));
        Ok(Startup::Saved { slot, generation })
    }
}

impl CalibrationStore {
    /// Erases both slots, so start-up runs the defaults with `ccm/calibration.toml`'s
    /// sensors again. Refused unless the car stands with the tractive system off, as a save.
    pub fn erase(
        &mut self,
        flash: &mut impl CalibrationFlash,
        state: VehicleState,
    ) -> Result<(), SaveError> {
        if state.moving || state.tractive_live {
            return Err(SaveError::NotAllowedNow);
        }
        for slot in [Slot::A, Slot::B] {
            flash.erase(slot).map_err(SaveError::Flash)?;
        }
        self.newest = None;
        Ok(())
    }
}

fn note_newest(store: &mut CalibrationStore, slot: Slot, generation: u32) {
    if store.newest.is_none_or(|(_, g)| newer(generation, g)) {
        store.newest = Some((slot, generation));
    }
}

/// Generations wrap; the newer of two is the one less than half the range ahead.
fn newer(a: u32, b: u32) -> bool {
    (a.wrapping_sub(b) as i32) > 0
}

/// Of two reasons for running the defaults, the one a tuner must hear about first.
fn more_telling(a: Startup, b: Startup) -> Startup {
    if b.raw() > a.raw() { b } else { a }
}

fn read_record(flash: &mut impl CalibrationFlash, slot: Slot, epk: &[u8]) -> Record {
    let mut record = [0u8; RECORD_LEN];
    if flash.read(slot, 0, &mut record).is_err() {
        return Record::Corrupt;
    }
    if record.iter().all(|&b| b == 0xFF) {
        return Record::Empty;
    }
    let (body, crc) = record.split_at(CRC_AT);
    let stored_crc = u32::from_le_bytes([crc[0], crc[1], crc[2], crc[3]]);
    if body.get(MAGIC_AT..GENERATION_AT) != Some(&RECORD_MAGIC[..]) || crc32(body) != stored_crc {
        return Record::Corrupt;
    }
    let generation = u32::from_le_bytes([
        record[GENERATION_AT],
        record[GENERATION_AT + 1],
        record[GENERATION_AT + 2],
        record[GENERATION_AT + 3],
    ]);
    let mut expected_epk = [0u8; EPK_FIELD_LEN];
    let Some(prefix) = expected_epk.get_mut(..epk.len()) else {
        return Record::OtherSchema { generation };
    };
    prefix.copy_from_slice(epk);
    let page_len = u16::from_le_bytes([record[PAGE_LEN_AT], record[PAGE_LEN_AT + 1]]);
    if record[EPK_AT..PAGE_LEN_AT] != expected_epk || usize::from(page_len) != PAGE_LEN {
        return Record::OtherSchema { generation };
    }
    let mut page = [0u8; PAGE_LEN];
    page.copy_from_slice(&record[PAGE_AT..CRC_AT]);
    Record::Good { generation, page }
}

/// The page as a calibration the CCM runs with, or `None`.
fn accepted(page: &[u8; PAGE_LEN]) -> Option<Calibration> {
    let calibration = Calibration::from_page(page).ok()?;
    SensorCalibration::of(&calibration).check().ok()?;
    Some(calibration)
}

/// CRC-32 (IEEE 802.3: reflected, polynomial 0xEDB88320, initial and final 0xFFFFFFFF), the
/// records' check and `CCM_CalChecksum`. Check value: `crc32(b"123456789") == 0xCBF43926`.
pub fn crc32(data: &[u8]) -> u32 {
    let mut crc = u32::MAX;
    for &byte in data {
        crc ^= u32::from(byte);
        for _ in 0..8 {
            let mask = (crc & 1).wrapping_neg();
            crc = (crc >> 1) ^ (0xEDB8_8320 & mask);
        }
    }
    !crc
}

/// Bytes of a [`RamFlash`] slot: one 4 KiB erase sector, as on the Teensy's flash.
pub const RAM_SLOT_LEN: usize = 4096;

/// A flash in RAM with NOR semantics, for the host, the car model and tests.
#[derive(Clone)]
pub struct RamFlash {
    slots: [[u8; RAM_SLOT_LEN]; 2],
}

impl Default for RamFlash {
    fn default() -> Self {
        Self {
            slots: [[0xFF; RAM_SLOT_LEN]; 2],
        }
    }
}

impl RamFlash {
    /// The bytes of `slot`, for tests that corrupt or inspect them.
    pub fn slot_mut(&mut self, slot: Slot) -> &mut [u8; RAM_SLOT_LEN] {
        match slot {
            Slot::A => &mut self.slots[0],
            Slot::B => &mut self.slots[1],
        }
    }
}

impl CalibrationFlash for RamFlash {
    fn read(&mut self, slot: Slot, offset: usize, out: &mut [u8]) -> Result<(), FlashError> {
        let bytes = self
            .slot_mut(slot)
            .get(offset..offset.saturating_add(out.len()))
            .ok_or(FlashError::OutOfBounds)?;
        out.copy_from_slice(bytes);
        Ok(())
    }

    fn erase(&mut self, slot: Slot) -> Result<(), FlashError> {
        self.slot_mut(slot).fill(0xFF);
        Ok(())
    }

    fn program(&mut self, slot: Slot, offset: usize, data: &[u8]) -> Result<(), FlashError> {
        let bytes = self
            .slot_mut(slot)
            .get_mut(offset..offset.saturating_add(data.len()))
            .ok_or(FlashError::OutOfBounds)?;
        for (cell, &value) in bytes.iter_mut().zip(data) {
            *cell &= value;
        }
        Ok(())
    }
}

const _: () = assert!(RECORD_LEN <= RAM_SLOT_LEN);
