//! What the forwarded XCP says about the CCM's calibration. The gateway shows the recorder
//! every command a master sends and every answer (positive or error) the slave gives; the
//! recorder pairs them (XCP answers one command at a time) and turns each write, revert, page
//! switch and save into [`Entry`]s: which parameter, the value before and after (or the one
//! refused, and why), and the checksum the CCM runs on afterwards.
//!
//! Old values come from the working page as the gateway knows it: read whole when a master
//! connects ([`Recorder::found`]) and kept up to date with every accepted change. The slave
//! judges every change; the recorder only follows what it answered, so it never disagrees
//! with the CCM about what happened.

use crate::store::calibration::{ECU_PAGE, Entry, Kind};
use aer::calibration::xcp::{CALIBRATION_ADDRESS, CALIBRATION_LEN, REFERENCE_PAGE, WORKING_PAGE};
use aer::calibration::{Calibration, PAGE_LEN, PARAMETERS, Parameter};
use aer_host::calibration::refusal_text;
use aer_xcp::protocol::{cmd, err, page_mode, pid, session};

/// Data bytes in one DOWNLOAD or DOWNLOAD_NEXT at MAX_CTO 8.
const DOWNLOAD_CHUNK: usize = 6;

/// A command waiting for the slave's answer.
#[derive(Debug, Clone, PartialEq)]
enum Pending {
    Connect,
    Disconnect,
    /// UNLOCK: a wrong key ends the session.
    Unlock,
    /// A command that points the MTA somewhere the recorder does not follow (a text).
    MtaElsewhere,
    /// BUILD_CHECKSUM: the MTA moves past the block.
    Checksum {
        size: u32,
    },
    SetMta {
        ext: u8,
        address: u32,
    },
    Upload {
        count: u32,
    },
    ShortUpload {
        ext: u8,
        address: u32,
        count: u32,
    },
    Write(Write),
    Revert,
    SetPage {
        mode: u8,
        page: u8,
    },
    Save,
}

/// A write the slave is taking (a block download arrives in several packets).
#[derive(Debug, Clone, PartialEq)]
struct Write {
    /// Where it goes (`None` if the MTA was never set where the gateway could see it).
    at: Option<(u8, u32)>,
    /// The bytes the master announced.
    total: usize,
    /// The bytes sent so far.
    data: Vec<u8>,
}

impl Write {
    fn remaining(&self) -> usize {
        self.total.saturating_sub(self.data.len())
    }
}

/// The calibration as the forwarded XCP shows it.
#[derive(Debug, Default)]
pub struct Recorder {
    /// The working page, once read.
    working: Option<[u8; PAGE_LEN]>,
    /// The page the control step runs on, once read or switched.
    ecu_page: Option<u8>,
    /// The page the master's writes go to (the session's XCP page).
    xcp_page: u8,
    /// The slave's memory transfer address, as far as the gateway saw it set.
    mta: Option<(u8, u32)>,
    pending: Option<Pending>,
}

impl Recorder {
    /// A recorder that knows nothing yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// CRC-32 of the page the CCM runs on, as `CCM_CalChecksum` reports it, if known.
    pub fn checksum(&self) -> Option<u32> {
        match self.ecu_page? {
            WORKING_PAGE => self.working.map(|page| crc32fast::hash(&page)),
            REFERENCE_PAGE => Some(crc32fast::hash(&Calibration::DEFAULT.to_page())),
            _ => None,
        }
    }

    /// The master's session with the slave ended (the gateway's DISCONNECT): what belonged to
    /// it is gone, the calibration stays.
    pub fn session_ended(&mut self) {
        self.pending = None;
        self.mta = None;
        self.xcp_page = WORKING_PAGE;
    }

    /// A command the master sends to the slave.
    pub fn command(&mut self, packet: &[u8]) {
        let byte = |i: usize| packet.get(i).copied().unwrap_or(0);
        let word = |i: usize| {
            packet
                .get(i..i + 4)
                .and_then(|b| b.try_into().ok())
                .map_or(0, u32::from_le_bytes)
        };
        let data = |from: usize, count: usize| {
            packet
                .get(from..)
                .unwrap_or_default()
                .iter()
                .take(count)
                .copied()
                .collect::<Vec<u8>>()
        };
        let count = usize::from(byte(1));
        self.pending = match byte(0) {
            cmd::CONNECT => Some(Pending::Connect),
            cmd::DISCONNECT => Some(Pending::Disconnect),
            cmd::UNLOCK => Some(Pending::Unlock),
            cmd::GET_ID | cmd::GET_DAQ_EVENT_INFO => Some(Pending::MtaElsewhere),
            cmd::BUILD_CHECKSUM => Some(Pending::Checksum { size: word(4) }),
            cmd::SET_MTA => Some(Pending::SetMta {
                ext: byte(3),
                address: word(4),
            }),
            cmd::UPLOAD => Some(Pending::Upload {
                count: u32::from(byte(1)),
            }),
            cmd::SHORT_UPLOAD => Some(Pending::ShortUpload {
                ext: byte(3),
                address: word(4),
                count: u32::from(byte(1)),
            }),
            cmd::DOWNLOAD => match self.pending.take() {
                // pyxcp sends the tail of a 7..11-byte block as a DOWNLOAD, which the slave
                // takes as the block's last packet.
                Some(Pending::Write(mut open))
                    if open.remaining() > 0
                        && count == open.remaining()
                        && count <= DOWNLOAD_CHUNK =>
                {
                    open.data.extend(data(2, count));
                    Some(Pending::Write(open))
                }
                _ => Some(Pending::Write(Write {
                    at: self.mta,
                    total: count,
                    data: data(2, count.min(DOWNLOAD_CHUNK)),
                })),
            },
            cmd::DOWNLOAD_NEXT => match self.pending.take() {
                Some(Pending::Write(mut open))
                    if open.remaining() > 0 && count == open.remaining() =>
                {
                    open.data.extend(data(2, count.min(DOWNLOAD_CHUNK)));
                    Some(Pending::Write(open))
                }
                // Out of sequence: the slave refuses it and writes nothing.
                _ => None,
            },
            cmd::SHORT_DOWNLOAD => Some(Pending::Write(Write {
                at: Some((byte(3), word(4))),
                total: count,
                data: data(8, count),
            })),
            cmd::SET_CAL_PAGE => Some(Pending::SetPage {
                mode: byte(1),
                page: byte(3),
            }),
            cmd::COPY_CAL_PAGE if byte(2) == REFERENCE_PAGE && byte(4) == WORKING_PAGE => {
                Some(Pending::Revert)
            }
            cmd::SET_REQUEST if byte(1) == session::STORE_CAL_REQ => Some(Pending::Save),
            _ => None,
        };
    }

    /// The slave's answer to the last command (a positive response or an error; events and
    /// DAQ packets are not answers): the entries it makes, stamped `at_us` and `master`.
    pub fn answer(&mut self, packet: &[u8], at_us: i64, master: &str) -> Vec<Entry> {
        let accepted = match packet.first() {
            Some(&pid::RES) => true,
            Some(&pid::ERR) => false,
            _ => return Vec::new(),
        };
        let code = packet.get(1).copied().unwrap_or(err::GENERIC);
        let Some(pending) = self.pending.take() else {
            return Vec::new();
        };
        if let Pending::Write(write) = &pending
            && accepted
            && write.remaining() > 0
        {
            // The slave answers a block only at its end; this answers something else.
            return Vec::new();
        }
        let stamp = |kind, parameter: &str| Entry {
            at_us,
            master: master.to_owned(),
            kind,
            parameter: parameter.to_owned(),
            element: None,
            old: None,
            new: None,
            accepted,
            reason: String::new(),
            checksum: None,
        };
        let mut entries = Vec::new();
        match pending {
            Pending::Connect if accepted => {
                // A new session may follow a restart of the CCM (its page reloaded from
                // flash): nothing known of the page holds until it is read again.
                self.session_ended();
                self.working = None;
                self.ecu_page = None;
            }
            Pending::Disconnect if accepted => self.session_ended(),
            Pending::Unlock if code == err::ACCESS_LOCKED => self.session_ended(),
            Pending::MtaElsewhere if accepted => self.mta = None,
            Pending::Checksum { size } if accepted => {
                self.mta = self
                    .mta
                    .and_then(|(ext, at)| Some((ext, at.checked_add(size)?)));
            }
            Pending::SetMta { ext, address } if accepted => self.mta = Some((ext, address)),
            Pending::Upload { count } if accepted => {
                self.mta = self
                    .mta
                    .and_then(|(ext, at)| Some((ext, at.checked_add(count)?)));
            }
            Pending::ShortUpload {
                ext,
                address,
                count,
            } if accepted => self.mta = address.checked_add(count).map(|end| (ext, end)),
            Pending::Connect
            | Pending::Disconnect
            | Pending::Unlock
            | Pending::MtaElsewhere
            | Pending::Checksum { .. }
            | Pending::SetMta { .. }
            | Pending::Upload { .. }
            | Pending::ShortUpload { .. } => {}
            Pending::Write(write) => entries = self.write(&write, accepted, code, &stamp),
            Pending::Revert => {
                if accepted {
                    let reference = Calibration::DEFAULT.to_page();
                    entries = changed_elements(self.working.as_ref(), &reference, 0..PAGE_LEN)
                        .map(|(parameter, index, old, new)| Entry {
                            element: element_of(parameter, index),
                            old,
                            new,
                            ..stamp(Kind::Revert, parameter.name)
                        })
                        .collect();
                    self.working = Some(reference);
                } else {
                    entries.push(Entry {
                        reason: refusal_text(code, None, None),
                        ..stamp(Kind::Revert, "")
                    });
                }
            }
            Pending::SetPage { mode, page } => {
                if accepted && mode & page_mode::XCP != 0 {
                    self.xcp_page = page;
                }
                if mode & page_mode::ECU != 0 {
                    let old = self.ecu_page;
                    if accepted {
                        self.ecu_page = Some(page);
                    }
                    entries.push(Entry {
                        old: old.map(f64::from),
                        new: Some(f64::from(page)),
                        reason: if accepted {
                            String::new()
                        } else {
                            refusal_text(code, None, None)
                        },
                        ..stamp(Kind::Page, ECU_PAGE)
                    });
                }
            }
            Pending::Save => entries.push(Entry {
                reason: if accepted {
                    String::new()
                } else if code == err::WRITE_PROTECTED {
                    "saving to flash only at standstill with the tractive system off".into()
                } else {
                    refusal_text(code, None, None)
                },
                ..stamp(Kind::Save, "")
            }),
        }
        let checksum = self.checksum();
        for entry in &mut entries {
            entry.checksum = checksum;
        }
        entries
    }

    /// A write answered: applies it if accepted, and lists the elements it changed or tried to.
    fn write(
        &mut self,
        write: &Write,
        accepted: bool,
        code: u8,
        stamp: &dyn Fn(Kind, &str) -> Entry,
    ) -> Vec<Entry> {
        let offset = write.at.and_then(|(ext, address)| {
            let offset = usize::try_from(address.checked_sub(CALIBRATION_ADDRESS)?).ok()?;
            (ext == 0 && offset + write.data.len() <= CALIBRATION_LEN).then_some(offset)
        });
        let Some(offset) = offset else {
            // Not the calibration page (the slave refuses such writes), or not known where: a
            // write taken where the gateway cannot see leaves the page unknown until read.
            if accepted {
                self.working = None;
                self.mta = None;
            }
            let place = write.at.map_or_else(
                || "(address not seen)".to_owned(),
                |(_, address)| format!("0x{address:08X}"),
            );
            return vec![Entry {
                reason: if accepted {
                    String::new()
                } else {
                    refusal_text(code, None, None)
                },
                ..stamp(Kind::Write, &place)
            }];
        };
        if accepted && let Some((ext, address)) = write.at {
            self.mta = u32::try_from(write.data.len())
                .ok()
                .and_then(|len| Some((ext, address.checked_add(len)?)));
        }
        let range = offset..offset + write.data.len();
        // The page the write would make: known whole when the working page is, else only
        // the elements the write covers entirely.
        let mut after = self.working.unwrap_or([0; PAGE_LEN]);
        if let Some(target) = after.get_mut(range.clone()) {
            target.copy_from_slice(&write.data);
        }
        let known_after = |parameter: &Parameter, index: usize| {
            let size = parameter.element.size();
            let start = parameter.offset + index * size;
            (self.working.is_some() || (range.start <= start && start + size <= range.end))
                .then(|| parameter.value(&after, index))
                .flatten()
        };
        let reason = |parameter: &Parameter, new| {
            if accepted {
                String::new()
            } else if code == err::WRITE_PROTECTED && self.xcp_page != WORKING_PAGE {
                "written to the read-only reference page".into()
            } else {
                refusal_text(code, Some(parameter), new)
            }
        };
        let touched: Vec<Entry> = touched_elements(range.clone())
            .map(|(parameter, index)| Entry {
                element: element_of(parameter, index),
                old: self
                    .working
                    .as_ref()
                    .and_then(|page| parameter.value(page, index)),
                new: known_after(parameter, index),
                reason: reason(parameter, known_after(parameter, index)),
                ..stamp(Kind::Write, parameter.name)
            })
            .collect();
        // A value written as it was changes nothing: only the others are entries. A refused
        // write of nothing but such values still is one (the refusal is the news).
        let unchanged = |e: &Entry| e.old.is_some() && e.old == e.new;
        let entries = if !accepted && touched.iter().all(unchanged) {
            touched
        } else {
            touched.into_iter().filter(|e| !unchanged(e)).collect()
        };
        if accepted && self.working.is_some() {
            self.working = Some(after);
        }
        entries
    }

    /// The page as the gateway read it when a master connected (`working`, the page the CCM
    /// runs on `ecu_page`): every value, as `Found` entries.
    pub fn found(
        &mut self,
        working: [u8; PAGE_LEN],
        ecu_page: Option<u8>,
        at_us: i64,
        master: &str,
    ) -> Vec<Entry> {
        self.working = Some(working);
        if ecu_page.is_some() {
            self.ecu_page = ecu_page;
        }
        let checksum = self.checksum();
        let found = |parameter: &str, element, value| Entry {
            at_us,
            master: master.to_owned(),
            kind: Kind::Found,
            parameter: parameter.to_owned(),
            element,
            old: value,
            new: value,
            accepted: true,
            reason: String::new(),
            checksum,
        };
        let mut entries: Vec<Entry> = touched_elements(0..PAGE_LEN)
            .map(|(parameter, index)| {
                found(
                    parameter.name,
                    element_of(parameter, index),
                    parameter.value(&working, index),
                )
            })
            .collect();
        if let Some(page) = self.ecu_page {
            entries.push(found(ECU_PAGE, None, Some(f64::from(page))));
        }
        entries
    }
}

/// Every parameter element with a byte in `range` of the page.
fn touched_elements(
    range: std::ops::Range<usize>,
) -> impl Iterator<Item = (&'static Parameter, usize)> {
    PARAMETERS.iter().flat_map(move |parameter| {
        let size = parameter.element.size();
        let range = range.clone();
        (0..parameter.count).filter_map(move |index| {
            let start = parameter.offset + index * size;
            (start < range.end && range.start < start + size).then_some((parameter, index))
        })
    })
}

/// The elements in `range` whose value differs between `before` (unknown: all) and `after`.
fn changed_elements<'a>(
    before: Option<&'a [u8; PAGE_LEN]>,
    after: &'a [u8; PAGE_LEN],
    range: std::ops::Range<usize>,
) -> impl Iterator<Item = (&'static Parameter, usize, Option<f64>, Option<f64>)> + 'a {
    touched_elements(range).filter_map(move |(parameter, index)| {
        let old = before.and_then(|page| parameter.value(page, index));
        let new = parameter.value(after, index);
        (old.is_none() || old != new).then_some((parameter, index, old, new))
    })
}

/// The element number of a curve's or list's element, `None` for a scalar.
fn element_of(parameter: &Parameter, index: usize) -> Option<u32> {
    (parameter.count > 1)
        .then(|| u32::try_from(index).ok())
        .flatten()
}
