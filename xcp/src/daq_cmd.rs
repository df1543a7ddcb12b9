//! The DAQ commands and the sampling of running lists when an event channel fires.
//!
//! DTOs use the identification field "absolute ODT number": one PID byte, the list's FIRST_PID
//! plus the ODT's number in the list. A list with the TIMESTAMP mode carries a 4-byte, 1 us
//! timestamp after the PID of its first ODT. Lists only start if the running lists stay within
//! the DAQ share of the frame budget; otherwise ERR_DAQ_CONFIG, which pyxcp reports, and the
//! last refusal says which limit refused (the budget, or an ODT's room). A DTO the bus queue
//! refuses is counted, and the master hears of it: one EV_DAQ_OVERLOAD per episode, sent
//! before the next DTO the queue takes (the overload indication by event: pyxcp decodes
//! PIDs with their top bit as they are, so the PID-bit indication would corrupt its data).

use crate::daq::{Entry, ODT_CAPACITY, TIMESTAMP_LEN};
use crate::protocol::{MAX_DTO, daq_mode, err, ev, pid};
use crate::refusal::{Detail, reason};
use crate::slave::{DaqReport, Slave};
use crate::target::Target;
use crate::wire::{Answer, Args, Fail, Outcome, Packet};

/// GET_DAQ_PROCESSOR_INFO's DAQ_PROPERTIES: dynamic configuration, prescaler, timestamps,
/// overload indicated by event.
const DAQ_PROPERTIES: u8 = 0x01 | 0x02 | 0x10 | 0x80;

/// GET_DAQ_RESOLUTION_INFO's TIMESTAMP_MODE: 4 bytes, not fixed (per list), unit 1 us.
const TIMESTAMP_MODE: u8 = 0x04 | (3 << 4);

/// GET_DAQ_EVENT_INFO's properties: DAQ direction, consistency over the whole event channel
/// (every list of a channel is sampled in one [`Slave::event`] call).
const EVENT_PROPERTIES: u8 = 0x04 | 0x80;

/// Mode bits SET_DAQ_LIST_MODE accepts (everything else: ERR_MODE_NOT_VALID).
const SUPPORTED_MODE: u8 = daq_mode::TIMESTAMP;

/// Turns a DAQ table error code into an error packet (no storage left says so).
fn fail(code: u8) -> Fail {
    Fail::new(code)
}

/// `code`; with MEMORY_OVERFLOW, what was asked and what was left.
fn storage(code: u8, asked: usize, available: usize) -> Fail {
    if code == err::MEMORY_OVERFLOW {
        Fail::because(
            code,
            Detail::of(reason::DAQ_STORAGE, asked as f32, available as f32),
        )
    } else {
        Fail::new(code)
    }
}

/// A list without a periodic event channel cannot start: its rate has no bound.
fn no_event() -> Fail {
    Fail::because(err::DAQ_CONFIG, Detail::of(reason::NO_EVENT, 0.0, 0.0))
}

impl<const LISTS: usize, const ODTS: usize, const ENTRIES: usize> Slave<LISTS, ODTS, ENTRIES> {
    /// GET_DAQ_PROCESSOR_INFO: dynamic lists, absolute ODT numbers as PIDs, address extension
    /// free per entry.
    pub(crate) fn daq_processor_info(&self) -> Packet {
        let mut packet = Packet::ok(&[DAQ_PROPERTIES]);
        packet.push_u16(
            u16::try_from(crate::daq::Daq::<LISTS, ODTS, ENTRIES>::max_lists()).unwrap_or(u16::MAX),
        );
        packet.push_u16(u16::try_from(self.config.events.len()).unwrap_or(u16::MAX));
        packet.push(0); // MIN_DAQ: no predefined lists
        packet.push(0); // DAQ_KEY_BYTE: absolute ODT number, free extension, default optimisation
        packet
    }

    /// GET_DAQ_RESOLUTION_INFO: byte granularity, the entry size limit, the timestamp format.
    pub(crate) fn daq_resolution_info(&self) -> Packet {
        let mut packet = Packet::ok(&[1, self.config.entry_size_limit(), 1, 0, TIMESTAMP_MODE]);
        packet.push_u16(1); // one tick per unit
        packet
    }

    /// GET_DAQ_EVENT_INFO: cycle, unit and priority; the name is read by UPLOAD from the MTA.
    pub(crate) fn get_daq_event_info(&mut self, args: Args<'_>) -> Outcome {
        let number = args.u16(2)?;
        let event = self
            .config
            .events
            .get(usize::from(number))
            .ok_or(fail(err::OUT_OF_RANGE))?;
        let (cycle, unit) = event.cycle();
        let name_len = u8::try_from(event.name.len()).unwrap_or(u8::MAX);
        self.mta = crate::transfer::Mta::Text {
            text: crate::transfer::Text::EventName(number),
            offset: 0,
        };
        // Any list may use any channel: as many lists as there are.
        let max_lists =
            u8::try_from(crate::daq::Daq::<LISTS, ODTS, ENTRIES>::max_lists()).unwrap_or(u8::MAX);
        Ok(Answer::Reply(Packet::ok(&[
            EVENT_PROPERTIES,
            max_lists,
            name_len,
            cycle,
            unit,
            event.priority,
        ])))
    }

    /// ALLOC_DAQ.
    pub(crate) fn alloc_daq(&mut self, args: Args<'_>) -> Outcome {
        let count = args.u16(2)?;
        let available = crate::daq::Daq::<LISTS, ODTS, ENTRIES>::max_lists();
        self.daq
            .alloc_lists(count)
            .map_err(|code| storage(code, usize::from(count), available))?;
        Ok(Answer::Reply(Packet::ok(&[])))
    }

    /// ALLOC_ODT.
    pub(crate) fn alloc_odt(&mut self, args: Args<'_>) -> Outcome {
        let list = args.u16(2)?;
        let count = args.u8(4)?;
        let available = self.daq.free_odts();
        self.daq
            .alloc_odts(list, count)
            .map_err(|code| storage(code, usize::from(count), available))?;
        Ok(Answer::Reply(Packet::ok(&[])))
    }

    /// ALLOC_ODT_ENTRY.
    pub(crate) fn alloc_odt_entry(&mut self, args: Args<'_>) -> Outcome {
        let list = args.u16(2)?;
        let odt = args.u8(4)?;
        let count = args.u8(5)?;
        let available = self.daq.free_entries();
        self.daq
            .alloc_entries(list, odt, count)
            .map_err(|code| storage(code, usize::from(count), available))?;
        Ok(Answer::Reply(Packet::ok(&[])))
    }

    /// CLEAR_DAQ_LIST: stops the list and empties its entries (allocation stays).
    pub(crate) fn clear_daq_list(&mut self, args: Args<'_>) -> Outcome {
        let number = args.u16(2)?;
        let list = self.daq.list_mut(number).map_err(fail)?;
        list.running = false;
        list.selected = false;
        let list = *list;
        for odt in list.first_odt..list.first_odt.saturating_add(list.odts) {
            let Some(odt) = self.daq.odts.get(odt).copied() else {
                continue;
            };
            for entry in self
                .daq
                .entries
                .iter_mut()
                .skip(odt.first_entry)
                .take(odt.entries)
            {
                *entry = Entry {
                    ext: 0,
                    address: 0,
                    size: 0,
                };
            }
        }
        if self
            .daq
            .pointer
            .is_some_and(|pointer| pointer.list == usize::from(number))
        {
            self.daq.pointer = None;
        }
        Ok(Answer::Reply(Packet::ok(&[])))
    }

    /// SET_DAQ_PTR.
    pub(crate) fn set_daq_ptr(&mut self, args: Args<'_>) -> Outcome {
        let list = args.u16(2)?;
        let odt = args.u8(4)?;
        let entry = args.u8(5)?;
        self.daq.set_pointer(list, odt, entry).map_err(fail)?;
        Ok(Answer::Reply(Packet::ok(&[])))
    }

    /// WRITE_DAQ: the entry at the DAQ pointer, which then moves to the next entry of the ODT.
    /// The address is checked by reading it through the target now, so a list never samples
    /// memory the target does not expose.
    pub(crate) fn write_daq(&mut self, target: &impl Target, args: Args<'_>) -> Outcome {
        let bit_offset = args.u8(1)?;
        let size = args.u8(2)?;
        let ext = args.u8(3)?;
        let address = args.u32(4)?;
        let pointer = self.daq.pointer.ok_or(fail(err::SEQUENCE))?;
        let list = *self
            .daq
            .lists
            .get(pointer.list)
            .ok_or(fail(err::SEQUENCE))?;
        if list.running {
            return Err(fail(err::DAQ_ACTIVE));
        }
        if bit_offset != 0xFF || size == 0 || size > self.config.entry_size_limit() {
            return Err(fail(err::OUT_OF_RANGE));
        }
        let room = if pointer.odt == 0 && list.timestamp {
            ODT_CAPACITY - TIMESTAMP_LEN
        } else {
            ODT_CAPACITY
        };
        let with_entry = self
            .daq
            .odt_bytes(pointer.odt_index, Some((pointer.entry, size)));
        if with_entry > room {
            let left = room.saturating_sub(with_entry.saturating_sub(usize::from(size)));
            return Err(Fail::because(
                err::DAQ_CONFIG,
                Detail::of(reason::ODT_FULL, f32::from(size), left as f32),
            ));
        }
        let mut probe = [0u8; MAX_DTO];
        let probe = probe
            .get_mut(..usize::from(size))
            .ok_or(fail(err::OUT_OF_RANGE))?;
        target
            .read(target.ecu_page(), ext, address, probe)
            .map_err(|refusal| Fail::refused(refusal, target))?;
        let slot = self
            .daq
            .entries
            .get_mut(pointer.entry)
            .ok_or(fail(err::SEQUENCE))?;
        *slot = Entry { ext, address, size };
        let odt = self.daq.odts.get(pointer.odt_index).copied();
        let next = pointer.entry.saturating_add(1);
        self.daq.pointer = match odt {
            Some(odt) if next < odt.first_entry.saturating_add(odt.entries) => {
                Some(crate::daq::Pointer {
                    entry: next,
                    ..pointer
                })
            }
            _ => None,
        };
        Ok(Answer::Reply(Packet::ok(&[])))
    }

    /// SET_DAQ_LIST_MODE: event channel, prescaler (>= 1), priority, timestamp on or off.
    pub(crate) fn set_daq_list_mode(&mut self, args: Args<'_>) -> Outcome {
        let mode = args.u8(1)?;
        let number = args.u16(2)?;
        let event = args.u16(4)?;
        let prescaler = args.u8(6)?;
        let priority = args.u8(7)?;
        let list = *self.daq.list(number).map_err(fail)?;
        if mode & !SUPPORTED_MODE != 0 {
            return Err(fail(err::MODE_NOT_VALID));
        }
        if usize::from(event) >= self.config.events.len() || prescaler == 0 {
            return Err(fail(err::OUT_OF_RANGE));
        }
        if list.running {
            return Err(fail(err::DAQ_ACTIVE));
        }
        let timestamp = mode & daq_mode::TIMESTAMP != 0;
        if !self.daq.list_fits(&list, timestamp) {
            // The timestamp does not fit beside the first ODT's entries: what it needs, and
            // the bytes they leave.
            let room = self.daq.first_odt_room(&list);
            return Err(Fail::because(
                err::DAQ_CONFIG,
                Detail::of(reason::ODT_FULL, TIMESTAMP_LEN as f32, room as f32),
            ));
        }
        let list = self.daq.list_mut(number).map_err(fail)?;
        list.event = Some(event);
        list.prescaler = prescaler;
        list.priority = priority;
        list.timestamp = timestamp;
        Ok(Answer::Reply(Packet::ok(&[])))
    }

    /// GET_DAQ_LIST_MODE.
    pub(crate) fn get_daq_list_mode(&self, args: Args<'_>) -> Outcome {
        let list = *self.daq.list(args.u16(2)?).map_err(fail)?;
        let mut mode = 0;
        if list.selected {
            mode |= daq_mode::SELECTED;
        }
        if list.timestamp {
            mode |= daq_mode::TIMESTAMP;
        }
        if list.running {
            mode |= daq_mode::RUNNING;
        }
        let mut packet = Packet::ok(&[mode, 0, 0]);
        packet.push_u16(list.event.unwrap_or(0));
        packet.push(list.prescaler);
        packet.push(list.priority);
        Ok(Answer::Reply(packet))
    }

    /// ERR_DAQ_CONFIG if running the current lists plus those `also` picks would exceed the
    /// DAQ share of the frame budget.
    fn check_budget(&self, also: impl Fn(usize, &crate::daq::List) -> bool) -> Result<(), Fail> {
        let load = self.daq.load_per_s(self.config, also);
        let budget = self.config.daq_budget_per_s();
        if load > u64::from(budget) {
            return Err(Fail::because(
                err::DAQ_CONFIG,
                Detail::of(reason::DAQ_BUDGET, load as f32, budget as f32),
            ));
        }
        Ok(())
    }

    /// START_STOP_DAQ_LIST: stop (0), start (1) or select (2) one list; answers FIRST_PID.
    pub(crate) fn start_stop_daq_list(&mut self, args: Args<'_>) -> Outcome {
        let mode = args.u8(1)?;
        let number = args.u16(2)?;
        let list = *self.daq.list(number).map_err(fail)?;
        if mode > 2 {
            return Err(fail(err::MODE_NOT_VALID));
        }
        if mode != 0 && !self.daq.startable(&list) {
            return Err(no_event());
        }
        if mode == 1 && !list.running {
            self.check_budget(|index, _| index == usize::from(number))?;
        }
        let list = self.daq.list_mut(number).map_err(fail)?;
        match mode {
            0 => list.running = false,
            1 => {
                if !list.running {
                    list.skip = 0;
                }
                list.running = true;
            }
            _ => list.selected = true,
        }
        let first_pid = u8::try_from(list.first_odt).unwrap_or(u8::MAX);
        Ok(Answer::Reply(Packet::ok(&[first_pid])))
    }

    /// START_STOP_SYNCH: stop all (0), start the selected (1), stop the selected (2).
    pub(crate) fn start_stop_synch(&mut self, args: Args<'_>) -> Outcome {
        let mode = args.u8(1)?;
        let count = self.daq.list_count;
        match mode {
            0 => {
                for list in self.daq.lists.iter_mut().take(count) {
                    list.running = false;
                    list.selected = false;
                }
            }
            1 => {
                let lists = self.daq.lists.iter().take(count);
                if lists
                    .filter(|list| list.selected)
                    .any(|list| !self.daq.startable(list))
                {
                    return Err(no_event());
                }
                self.check_budget(|_, list| list.selected)?;
                for list in self
                    .daq
                    .lists
                    .iter_mut()
                    .take(count)
                    .filter(|list| list.selected)
                {
                    if !list.running {
                        list.skip = 0;
                    }
                    list.running = true;
                    list.selected = false;
                }
            }
            2 => {
                for list in self
                    .daq
                    .lists
                    .iter_mut()
                    .take(count)
                    .filter(|list| list.selected)
                {
                    list.running = false;
                    list.selected = false;
                }
            }
            _ => return Err(fail(err::MODE_NOT_VALID)),
        }
        Ok(Answer::Reply(Packet::ok(&[])))
    }

    /// An event channel fired: every running list on it whose prescaler is due samples its
    /// ODT entries through [`Target::read`] (on the ECU's page) and hands each DTO to `send`,
    /// which returns false when the bus queue is full. Packets that cannot be sent are counted
    /// as dropped (and once the queue refused one, the rest of this event's packets are not
    /// sampled, only counted). Call it from the code that owns the sampled data, after it has
    /// updated them, so an event's samples are consistent. `now_us` is the timestamp.
    pub fn event(
        &mut self,
        target: &impl Target,
        channel: u16,
        now_us: u32,
        send: &mut impl FnMut(&[u8]) -> bool,
    ) -> DaqReport {
        let mut report = DaqReport::default();
        if !self.is_connected() {
            return report;
        }
        let page = target.ecu_page();
        let mut full = false;
        if self.overload_pending {
            if send(&[pid::EV, ev::DAQ_OVERLOAD]) {
                self.overload_pending = false;
            } else {
                full = true;
            }
        }
        for number in 0..self.daq.list_count {
            let Some(list) = self.daq.lists.get_mut(number) else {
                break;
            };
            if !list.running || list.event != Some(channel) {
                continue;
            }
            let due = list.skip == 0;
            list.skip = if due {
                list.prescaler.saturating_sub(1)
            } else {
                list.skip.saturating_sub(1)
            };
            if !due {
                continue;
            }
            let list = *list;
            for odt in 0..list.odts {
                if full {
                    report.dropped = report.dropped.saturating_add(1);
                    continue;
                }
                let Some(packet) = self.sample(target, page, &list, odt, now_us) else {
                    self.counters.daq_faults = self.counters.daq_faults.wrapping_add(1);
                    break;
                };
                if send(packet.bytes()) {
                    report.sent = report.sent.saturating_add(1);
                } else {
                    report.dropped = report.dropped.saturating_add(1);
                    full = true;
                    if !self.overload_pending {
                        self.overload_pending = true;
                        self.counters.overloads = self.counters.overloads.wrapping_add(1);
                    }
                }
            }
        }
        self.counters.dtos_sent = self.counters.dtos_sent.wrapping_add(report.sent);
        self.counters.dtos_dropped = self.counters.dtos_dropped.wrapping_add(report.dropped);
        report
    }

    /// One DTO of a list: PID, timestamp in the first ODT if enabled, the entries' bytes.
    /// `None` if the target refuses a read (its map changed since WRITE_DAQ).
    fn sample(
        &self,
        target: &impl Target,
        page: u8,
        list: &crate::daq::List,
        odt: usize,
        now_us: u32,
    ) -> Option<Packet> {
        let index = list.first_odt.checked_add(odt)?;
        let mut packet = Packet::empty();
        packet.push(u8::try_from(index).ok()?);
        if odt == 0 && list.timestamp {
            packet.push_u32(now_us);
        }
        let slot = self.daq.odts.get(index)?;
        for entry in self
            .daq
            .entries
            .iter()
            .skip(slot.first_entry)
            .take(slot.entries)
        {
            if entry.size == 0 {
                continue;
            }
            let size = usize::from(entry.size);
            let tail = packet.tail_mut(size)?;
            target.read(page, entry.ext, entry.address, tail).ok()?;
            packet.commit(size);
        }
        Some(packet)
    }
}
