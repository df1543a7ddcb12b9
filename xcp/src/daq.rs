//! Dynamic DAQ storage: DAQ lists, ODTs and ODT entries in fixed arrays, the allocation order
//! the standard prescribes (FREE_DAQ, ALLOC_DAQ, ALLOC_ODT, ALLOC_ODT_ENTRY), the frame budget,
//! and the sampling of running lists when an event channel fires.

use crate::config::Config;
use crate::protocol::{MAX_DTO, err, pid};

/// Bytes of the DTO's timestamp (first ODT of a list with the TIMESTAMP mode).
pub(crate) const TIMESTAMP_LEN: usize = 4;

/// Data bytes one DTO carries after its PID.
pub(crate) const ODT_CAPACITY: usize = MAX_DTO - 1;

/// One ODT entry: what to sample (size 0: allocated but not written).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Entry {
    pub(crate) ext: u8,
    pub(crate) address: u32,
    pub(crate) size: u8,
}

/// One ODT: a run of entries, sent as one DTO.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Odt {
    pub(crate) first_entry: usize,
    pub(crate) entries: usize,
    /// ALLOC_ODT_ENTRY has been done for this ODT.
    pub(crate) allocated: bool,
}

/// One DAQ list: a run of ODTs, its event channel and mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct List {
    /// Absolute number of its first ODT: the PID of its first DTO (FIRST_PID).
    pub(crate) first_odt: usize,
    pub(crate) odts: usize,
    /// ALLOC_ODT has been done for this list.
    pub(crate) allocated: bool,
    /// Event channel set by SET_DAQ_LIST_MODE.
    pub(crate) event: Option<u16>,
    pub(crate) prescaler: u8,
    pub(crate) priority: u8,
    pub(crate) timestamp: bool,
    pub(crate) running: bool,
    pub(crate) selected: bool,
    /// Events to skip before the next sample.
    pub(crate) skip: u8,
}

impl List {
    const EMPTY: Self = List {
        first_odt: 0,
        odts: 0,
        allocated: false,
        event: None,
        prescaler: 1,
        priority: 0,
        timestamp: false,
        running: false,
        selected: false,
        skip: 0,
    };

    /// DTO frames per second this list sends when running: ODTs x event rate / prescaler,
    /// rounded up; unbounded (u64::MAX) without an event or on a sporadic channel.
    pub(crate) fn rate_per_s(&self, config: &Config) -> u64 {
        let Some(event) = self
            .event
            .and_then(|event| config.events.get(usize::from(event)))
        else {
            return u64::MAX;
        };
        let interval = u64::from(event.period_us).saturating_mul(u64::from(self.prescaler));
        if interval == 0 {
            return u64::MAX;
        }
        u64::try_from(self.odts)
            .unwrap_or(u64::MAX)
            .saturating_mul(1_000_000)
            .div_ceil(interval)
    }
}

/// Where allocation stands; each stage allows the next allocation command only.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Stage {
    /// After FREE_DAQ (or at start): ALLOC_DAQ next.
    Free,
    /// After ALLOC_DAQ: ALLOC_DAQ again or ALLOC_ODT.
    Lists,
    /// After ALLOC_ODT: more ALLOC_ODT or ALLOC_ODT_ENTRY.
    Odts,
    /// After ALLOC_ODT_ENTRY: more ALLOC_ODT_ENTRY; configuration may proceed.
    Entries,
}

/// The DAQ pointer of SET_DAQ_PTR / WRITE_DAQ.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Pointer {
    pub(crate) list: usize,
    /// Relative ODT number within the list.
    pub(crate) odt: usize,
    /// Absolute ODT index.
    pub(crate) odt_index: usize,
    /// Absolute entry index.
    pub(crate) entry: usize,
}

/// All DAQ storage of one slave.
pub(crate) struct Daq<const LISTS: usize, const ODTS: usize, const ENTRIES: usize> {
    pub(crate) lists: [List; LISTS],
    pub(crate) odts: [Odt; ODTS],
    pub(crate) entries: [Entry; ENTRIES],
    pub(crate) list_count: usize,
    odt_count: usize,
    entry_count: usize,
    stage: Stage,
    pub(crate) pointer: Option<Pointer>,
}

impl<const LISTS: usize, const ODTS: usize, const ENTRIES: usize> Daq<LISTS, ODTS, ENTRIES> {
    /// ODTs not allocated yet.
    pub(crate) fn free_odts(&self) -> usize {
        ODTS.saturating_sub(self.odt_count)
    }

    /// ODT entries not allocated yet.
    pub(crate) fn free_entries(&self) -> usize {
        ENTRIES.saturating_sub(self.entry_count)
    }

    /// Bytes the first ODT of `list` has left beside its entries (for a timestamp).
    pub(crate) fn first_odt_room(&self, list: &List) -> usize {
        ODT_CAPACITY.saturating_sub(self.odt_bytes(list.first_odt, None))
    }

    /// Nothing allocated.
    pub(crate) const fn new() -> Self {
        Daq {
            lists: [List::EMPTY; LISTS],
            odts: [Odt {
                first_entry: 0,
                entries: 0,
                allocated: false,
            }; ODTS],
            entries: [Entry {
                ext: 0,
                address: 0,
                size: 0,
            }; ENTRIES],
            list_count: 0,
            odt_count: 0,
            entry_count: 0,
            stage: Stage::Free,
            pointer: None,
        }
    }

    /// DAQ lists the storage offers (MAX_DAQ), at most u16::MAX.
    pub(crate) const fn max_lists() -> usize {
        if LISTS > u16::MAX as usize {
            u16::MAX as usize
        } else {
            LISTS
        }
    }

    /// ODTs the storage offers, at most one per DTO PID.
    const fn max_odts() -> usize {
        if ODTS > pid::DTO_LIMIT {
            pid::DTO_LIMIT
        } else {
            ODTS
        }
    }

    /// FREE_DAQ: stops and forgets every list.
    pub(crate) fn free(&mut self) {
        self.lists = [List::EMPTY; LISTS];
        self.list_count = 0;
        self.odt_count = 0;
        self.entry_count = 0;
        self.stage = Stage::Free;
        self.pointer = None;
    }

    /// Whether any list is running.
    pub(crate) fn any_running(&self) -> bool {
        self.lists
            .iter()
            .take(self.list_count)
            .any(|list| list.running)
    }

    /// The allocated list `number`, or ERR_OUT_OF_RANGE.
    pub(crate) fn list(&self, number: u16) -> Result<&List, u8> {
        let number = usize::from(number);
        if number >= self.list_count {
            return Err(err::OUT_OF_RANGE);
        }
        self.lists.get(number).ok_or(err::OUT_OF_RANGE)
    }

    /// The allocated list `number` for changing, or ERR_OUT_OF_RANGE.
    pub(crate) fn list_mut(&mut self, number: u16) -> Result<&mut List, u8> {
        let number = usize::from(number);
        if number >= self.list_count {
            return Err(err::OUT_OF_RANGE);
        }
        self.lists.get_mut(number).ok_or(err::OUT_OF_RANGE)
    }

    /// ALLOC_DAQ: right after FREE_DAQ (or another ALLOC_DAQ).
    pub(crate) fn alloc_lists(&mut self, count: u16) -> Result<(), u8> {
        if !matches!(self.stage, Stage::Free | Stage::Lists) {
            return Err(err::SEQUENCE);
        }
        let count = usize::from(count);
        if count == 0 {
            return Err(err::OUT_OF_RANGE);
        }
        if count > Self::max_lists() {
            return Err(err::MEMORY_OVERFLOW);
        }
        self.lists = [List::EMPTY; LISTS];
        self.list_count = count;
        self.stage = Stage::Lists;
        Ok(())
    }

    /// ALLOC_ODT: after ALLOC_DAQ, before any ALLOC_ODT_ENTRY; once per list.
    pub(crate) fn alloc_odts(&mut self, list: u16, count: u8) -> Result<(), u8> {
        if !matches!(self.stage, Stage::Lists | Stage::Odts) {
            return Err(err::SEQUENCE);
        }
        let first = self.odt_count;
        let count = usize::from(count);
        let end = first.saturating_add(count);
        let entry = self.list_mut(list)?;
        if entry.allocated {
            return Err(err::SEQUENCE);
        }
        if count == 0 {
            return Err(err::OUT_OF_RANGE);
        }
        if end > Self::max_odts() {
            return Err(err::MEMORY_OVERFLOW);
        }
        entry.first_odt = first;
        entry.odts = count;
        entry.allocated = true;
        for odt in self.odts.iter_mut().take(end).skip(first) {
            *odt = Odt {
                first_entry: 0,
                entries: 0,
                allocated: false,
            };
        }
        self.odt_count = end;
        self.stage = Stage::Odts;
        Ok(())
    }

    /// ALLOC_ODT_ENTRY: after ALLOC_ODT; once per ODT; 0 entries allowed (pyxcp leaves the
    /// first ODT empty when a timestamp leaves no room for its first measurement).
    pub(crate) fn alloc_entries(&mut self, list: u16, odt: u8, count: u8) -> Result<(), u8> {
        if !matches!(self.stage, Stage::Odts | Stage::Entries) {
            return Err(err::SEQUENCE);
        }
        let owner = *self.list(list)?;
        let odt = usize::from(odt);
        if odt >= owner.odts {
            return Err(err::OUT_OF_RANGE);
        }
        let count = usize::from(count);
        if count > ODT_CAPACITY {
            return Err(err::OUT_OF_RANGE);
        }
        let first = self.entry_count;
        let end = first.saturating_add(count);
        let index = owner.first_odt.saturating_add(odt);
        let slot = self.odts.get_mut(index).ok_or(err::OUT_OF_RANGE)?;
        if slot.allocated {
            return Err(err::SEQUENCE);
        }
        if end > ENTRIES {
            return Err(err::MEMORY_OVERFLOW);
        }
        *slot = Odt {
            first_entry: first,
            entries: count,
            allocated: true,
        };
        for entry in self.entries.iter_mut().take(end).skip(first) {
            *entry = Entry {
                ext: 0,
                address: 0,
                size: 0,
            };
        }
        self.entry_count = end;
        self.stage = Stage::Entries;
        Ok(())
    }

    /// SET_DAQ_PTR: points at an allocated entry of a stopped list.
    pub(crate) fn set_pointer(&mut self, list: u16, odt: u8, entry: u8) -> Result<(), u8> {
        self.pointer = None;
        let owner = *self.list(list)?;
        let odt = usize::from(odt);
        if odt >= owner.odts {
            return Err(err::OUT_OF_RANGE);
        }
        let odt_index = owner.first_odt.saturating_add(odt);
        let slot = *self.odts.get(odt_index).ok_or(err::OUT_OF_RANGE)?;
        let entry = usize::from(entry);
        if entry >= slot.entries {
            return Err(err::OUT_OF_RANGE);
        }
        if owner.running {
            return Err(err::DAQ_ACTIVE);
        }
        self.pointer = Some(Pointer {
            list: usize::from(list),
            odt,
            odt_index,
            entry: slot.first_entry.saturating_add(entry),
        });
        Ok(())
    }

    /// Data bytes of an ODT (its entries' sizes), with `replace` standing for the size of the
    /// entry at that absolute index.
    pub(crate) fn odt_bytes(&self, odt_index: usize, replace: Option<(usize, u8)>) -> usize {
        let Some(odt) = self.odts.get(odt_index) else {
            return 0;
        };
        let mut total = 0usize;
        for index in odt.first_entry..odt.first_entry.saturating_add(odt.entries) {
            let size = match replace {
                Some((at, size)) if at == index => size,
                _ => self.entries.get(index).map_or(0, |entry| entry.size),
            };
            total = total.saturating_add(usize::from(size));
        }
        total
    }

    /// Whether every ODT of a list fits a DTO (the first one with its timestamp).
    pub(crate) fn list_fits(&self, list: &List, timestamp: bool) -> bool {
        (0..list.odts).all(|odt| {
            let room = if odt == 0 && timestamp {
                ODT_CAPACITY - TIMESTAMP_LEN
            } else {
                ODT_CAPACITY
            };
            self.odt_bytes(list.first_odt.saturating_add(odt), None) <= room
        })
    }

    /// Whether a list can run: ODTs allocated, an event channel set, every ODT fits.
    pub(crate) fn startable(&self, list: &List) -> bool {
        list.allocated && list.event.is_some() && self.list_fits(list, list.timestamp)
    }

    /// DTO frames per second of the running lists plus those `also` picks.
    pub(crate) fn load_per_s(&self, config: &Config, also: impl Fn(usize, &List) -> bool) -> u64 {
        self.lists
            .iter()
            .take(self.list_count)
            .enumerate()
            .filter(|(number, list)| list.running || also(*number, list))
            .fold(0u64, |sum, (_, list)| {
                sum.saturating_add(list.rate_per_s(config))
            })
    }
}
