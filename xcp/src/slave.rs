//! The slave's session: connection state, resource protection (seed and key), how a session
//! ends (DISCONNECT, a wrong key, the transport's end, the idle time-out), the last refusal,
//! and the dispatch of each command packet to its handler. Memory, page and DAQ commands live
//! in their own modules as further `impl Slave` blocks.
//!
//! A session ends with its master: the ECU calls [`Slave::transport_lost`] when the transport
//! ends (a TCP connection closed, a framing error), and [`Slave::poll`] every step, which ends
//! a session with no command for `idle_timeout_ms` (on CAN, where any node can speak as the
//! master, that is the only end besides DISCONNECT). A measuring master keeps its DAQ lists:
//! with DAQ running an idle session only loses its calibration unlock. A wrong key ends the
//! session and delays the next seed, longer with every wrong key in a row.

use crate::config::Config;
use crate::daq::Daq;
use crate::protocol::{MAX_CTO, MAX_DTO, cmd, comm_mode, err, ev, pid, resource, session};
use crate::refusal::{Detail, LastRefusal, reason};
use crate::target::{KEY_MAX, SEED_LEN, Target};
use crate::transfer::{Block, Mta};
use crate::wire::{Answer, Args, Fail, Outcome, Packet};

/// Running totals the ECU can log or show (all wrap at u32::MAX).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Counters {
    /// Command packets handled (ignored packets while disconnected not counted).
    pub commands: u32,
    /// Error packets answered.
    pub errors: u32,
    /// DAQ packets handed to the bus.
    pub dtos_sent: u32,
    /// DAQ packets lost because the bus queue refused them (or a packet before them in the
    /// same event).
    pub dtos_dropped: u32,
    /// DAQ samples abandoned because the target refused a read it had accepted at WRITE_DAQ.
    pub daq_faults: u32,
    /// Overload episodes: the bus queue refused a DTO after it had taken the ones before
    /// (each announced to the master with one EV_DAQ_OVERLOAD).
    pub overloads: u32,
    /// Sessions the idle time-out ended (or, with DAQ running, whose unlock it took back).
    pub idle_ends: u32,
    /// Sessions ended because their transport ended.
    pub transport_ends: u32,
    /// Wrong keys (each ended its session).
    pub wrong_keys: u32,
}

impl Counters {
    /// The values in [`crate::status::COUNTERS`]' order.
    pub fn in_order(&self) -> [u32; 8] {
        [
            self.commands,
            self.errors,
            self.dtos_sent,
            self.dtos_dropped,
            self.overloads,
            self.daq_faults,
            self.idle_ends,
            self.wrong_keys,
        ]
    }
}

/// How a session ended without a DISCONNECT, as [`Slave::poll`] and
/// [`Slave::transport_lost`] report it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SessionEnd {
    /// No command for the idle time-out, no DAQ running: disconnected, locked.
    Idle,
    /// No command for the idle time-out with DAQ running: the DAQ lists go on, calibration
    /// is locked again.
    IdleRelocked,
    /// The transport ended.
    TransportLost,
}

/// What one [`Slave::event`] call sent.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DaqReport {
    /// DAQ packets the bus queue took.
    pub sent: u32,
    /// DAQ packets that were due but not sent because the queue was full.
    pub dropped: u32,
}

/// Seed-and-key progress for the calibration resource.
#[derive(Debug, Clone, Copy)]
struct Unlock {
    /// The seed last sent, valid while `seeded`.
    seed: [u8; SEED_LEN],
    /// GET_SEED answered a seed that no UNLOCK has consumed yet.
    seeded: bool,
    /// Key bytes received so far.
    key: [u8; KEY_MAX],
    /// Total key length announced by the first UNLOCK (0: no UNLOCK yet).
    key_len: usize,
    /// Key bytes received.
    got: usize,
}

impl Unlock {
    const IDLE: Self = Unlock {
        seed: [0; SEED_LEN],
        seeded: false,
        key: [0; KEY_MAX],
        key_len: 0,
        got: 0,
    };
}

/// An XCP slave: feed it command packets with [`Slave::command`] and event-channel firings with
/// [`Slave::event`]. `LISTS`, `ODTS` and `ENTRIES` size the dynamic DAQ storage (DAQ lists,
/// ODTs and ODT entries over all lists); at most 252 ODTs are usable (one PID each).
pub struct Slave<const LISTS: usize, const ODTS: usize, const ENTRIES: usize> {
    pub(crate) config: &'static Config,
    connected: bool,
    /// Calibration and page switching need seed and key (set at every CONNECT).
    pub(crate) cal_locked: bool,
    unlock: Unlock,
    /// The memory transfer address.
    pub(crate) mta: Mta,
    /// The page UPLOAD and DOWNLOAD access (0 working, 1 reference).
    pub(crate) xcp_page: u8,
    /// The master-block-mode download being collected.
    pub(crate) block: Block,
    pub(crate) daq: Daq<LISTS, ODTS, ENTRIES>,
    pub(crate) counters: Counters,
    /// When the last command came (us, the ECU's clock).
    last_command_us: u32,
    /// The idle time-out has acted since the last command.
    idle_handled: bool,
    /// Wrong keys in a row (cleared by a right one).
    wrong_keys_in_a_row: u32,
    /// GET_SEED is refused until then (us), after a wrong key.
    seed_after_us: Option<u32>,
    /// A DTO was dropped: an EV_DAQ_OVERLOAD is due as soon as the bus queue takes one.
    pub(crate) overload_pending: bool,
    last_refusal: LastRefusal,
}

impl<const LISTS: usize, const ODTS: usize, const ENTRIES: usize> Slave<LISTS, ODTS, ENTRIES> {
    /// A disconnected slave with the given fixed parameters.
    pub const fn new(config: &'static Config) -> Self {
        Slave {
            config,
            connected: false,
            cal_locked: true,
            unlock: Unlock::IDLE,
            mta: Mta::START,
            xcp_page: 0,
            block: Block::IDLE,
            daq: Daq::new(),
            counters: Counters {
                commands: 0,
                errors: 0,
                dtos_sent: 0,
                dtos_dropped: 0,
                daq_faults: 0,
                overloads: 0,
                idle_ends: 0,
                transport_ends: 0,
                wrong_keys: 0,
            },
            last_command_us: 0,
            idle_handled: false,
            wrong_keys_in_a_row: 0,
            seed_after_us: None,
            overload_pending: false,
            last_refusal: LastRefusal {
                count: 0,
                command: 0,
                error: 0,
                detail: Detail {
                    reason: reason::NONE,
                    item: Detail::NO_ITEM,
                    element: 0,
                    value: 0.0,
                    limit: 0.0,
                },
            },
        }
    }

    /// Whether a master is connected.
    pub fn is_connected(&self) -> bool {
        self.connected
    }

    /// Whether calibration writes and page switches still need seed and key.
    pub fn is_calibration_locked(&self) -> bool {
        self.cal_locked
    }

    /// Whether any DAQ list is running.
    pub fn is_daq_running(&self) -> bool {
        self.daq.any_running()
    }

    /// The running totals.
    pub fn counters(&self) -> Counters {
        self.counters
    }

    /// The last refused command, and why.
    pub fn last_refusal(&self) -> LastRefusal {
        self.last_refusal
    }

    /// The block the ECU publishes about the slave ([`crate::status`]).
    pub fn status_bytes(&self) -> [u8; crate::status::STATUS_LEN] {
        let mut bytes = [0u8; crate::status::STATUS_LEN];
        let (refusal, counters) = bytes.split_at_mut(crate::refusal::LAST_REFUSAL_LEN);
        refusal.copy_from_slice(&self.last_refusal.to_bytes());
        for (slot, value) in counters.chunks_exact_mut(4).zip(self.counters.in_order()) {
            slot.copy_from_slice(&value.to_le_bytes());
        }
        bytes
    }

    /// The transport the master spoke on ended (its TCP connection closed, a framing error):
    /// the session ends with it, calibration locked, any block download and DAQ list
    /// abandoned. Nothing happens when no master was connected.
    pub fn transport_lost(&mut self) -> Option<SessionEnd> {
        if !self.connected {
            return None;
        }
        self.end_session();
        self.counters.transport_ends = self.counters.transport_ends.wrapping_add(1);
        Some(SessionEnd::TransportLost)
    }

    /// Call every step with the ECU's microsecond clock: a session with no command for the
    /// idle time-out ends (with DAQ running, it only loses its calibration unlock), and an
    /// EV_SESSION_TERMINATED goes to `send` (best effort: `send` may refuse it).
    pub fn poll(
        &mut self,
        now_us: u32,
        send: &mut impl FnMut(&[u8]) -> bool,
    ) -> Option<SessionEnd> {
        if !self.connected || self.idle_handled {
            return None;
        }
        let idle_us = u64::from(self.config.idle_timeout_ms) * 1_000;
        if u64::from(now_us.wrapping_sub(self.last_command_us)) < idle_us {
            return None;
        }
        self.idle_handled = true;
        self.counters.idle_ends = self.counters.idle_ends.wrapping_add(1);
        if self.daq.any_running() {
            self.cal_locked = true;
            self.unlock = Unlock::IDLE;
            self.block = crate::transfer::Block::IDLE;
            return Some(SessionEnd::IdleRelocked);
        }
        self.end_session();
        let _sent = send(&[pid::EV, ev::SESSION_TERMINATED]);
        Some(SessionEnd::Idle)
    }

    /// Disconnected, with nothing of the session left.
    fn end_session(&mut self) {
        self.reset_session();
        self.connected = false;
    }

    /// Handles one command packet: at most one response or error packet is written into
    /// `reply`, and its length returned; `None` means no answer (not connected, or the middle
    /// of a block download). `now_us` is the slave's microsecond clock (GET_DAQ_CLOCK).
    pub fn command(
        &mut self,
        target: &mut impl Target,
        packet: &[u8],
        now_us: u32,
        reply: &mut [u8; MAX_CTO],
    ) -> Option<usize> {
        let code = packet.first().copied();
        if !self.connected && code != Some(cmd::CONNECT) {
            return None;
        }
        self.last_command_us = now_us;
        self.idle_handled = false;
        self.counters.commands = self.counters.commands.wrapping_add(1);
        let outcome = match code {
            Some(code) if packet.len() <= MAX_CTO => {
                self.dispatch(target, code, Args::new(packet), now_us)
            }
            _ => Err(Fail::new(err::CMD_SYNTAX)),
        };
        let answer = match outcome {
            Ok(Answer::Reply(packet)) => packet,
            Ok(Answer::Silent) => return None,
            Err(fail) => {
                self.counters.errors = self.counters.errors.wrapping_add(1);
                self.last_refusal = LastRefusal {
                    count: self.last_refusal.count.wrapping_add(1),
                    command: code.unwrap_or(0),
                    error: fail.code(),
                    detail: fail.detail,
                };
                fail.packet
            }
        };
        let bytes = answer.bytes();
        reply.fill(0);
        for (slot, byte) in reply.iter_mut().zip(bytes) {
            *slot = *byte;
        }
        Some(bytes.len())
    }

    fn dispatch(
        &mut self,
        target: &mut impl Target,
        code: u8,
        args: Args<'_>,
        now_us: u32,
    ) -> Outcome {
        // A block download is only continued by the packets that belong to it; anything else
        // abandons it, and nothing of it reaches the target.
        if code != cmd::DOWNLOAD && code != cmd::DOWNLOAD_NEXT {
            self.block = Block::IDLE;
        }
        match code {
            cmd::CONNECT => self.connect(args),
            cmd::DISCONNECT => {
                self.reset_session();
                self.connected = false;
                Ok(Answer::Reply(Packet::ok(&[])))
            }
            cmd::GET_STATUS => self.get_status(target),
            cmd::SYNCH => Err(Fail::new(err::CMD_SYNCH)),
            cmd::GET_COMM_MODE_INFO => Ok(Answer::Reply(Packet::ok(&[
                0,
                comm_mode::MASTER_BLOCK_MODE,
                0,
                self.config.block_packets(),
                self.config.min_st_100us,
                0,
                self.config.driver_version,
            ]))),
            cmd::GET_ID => self.get_id(target, args),
            cmd::SET_REQUEST => self.set_request(target, args),
            cmd::GET_SEED => self.get_seed(target, args, now_us),
            cmd::UNLOCK => self.unlock(target, args, now_us),
            cmd::SET_MTA => self.set_mta(args),
            cmd::UPLOAD => self.upload(target, args),
            cmd::SHORT_UPLOAD => self.short_upload(target, args),
            cmd::BUILD_CHECKSUM => self.build_checksum(target, args),
            cmd::DOWNLOAD => self.download(target, args),
            cmd::DOWNLOAD_NEXT => self.download_next(target, args),
            cmd::SET_CAL_PAGE => self.set_cal_page(target, args),
            cmd::GET_CAL_PAGE => self.get_cal_page(target, args),
            cmd::GET_PAG_PROCESSOR_INFO => Ok(Answer::Reply(Packet::ok(&[1, 0]))),
            cmd::GET_SEGMENT_INFO => self.get_segment_info(args),
            cmd::GET_PAGE_INFO => self.get_page_info(args),
            cmd::COPY_CAL_PAGE => self.copy_cal_page(target, args),
            cmd::CLEAR_DAQ_LIST => self.clear_daq_list(args),
            cmd::SET_DAQ_PTR => self.set_daq_ptr(args),
            cmd::WRITE_DAQ => self.write_daq(target, args),
            cmd::SET_DAQ_LIST_MODE => self.set_daq_list_mode(args),
            cmd::GET_DAQ_LIST_MODE => self.get_daq_list_mode(args),
            cmd::START_STOP_DAQ_LIST => self.start_stop_daq_list(args),
            cmd::START_STOP_SYNCH => self.start_stop_synch(args),
            cmd::GET_DAQ_CLOCK => {
                let mut packet = Packet::ok(&[0, 0, 0]);
                packet.push_u32(now_us);
                Ok(Answer::Reply(packet))
            }
            cmd::GET_DAQ_PROCESSOR_INFO => Ok(Answer::Reply(self.daq_processor_info())),
            cmd::GET_DAQ_RESOLUTION_INFO => Ok(Answer::Reply(self.daq_resolution_info())),
            cmd::GET_DAQ_EVENT_INFO => self.get_daq_event_info(args),
            cmd::FREE_DAQ => {
                self.daq.free();
                Ok(Answer::Reply(Packet::ok(&[])))
            }
            cmd::ALLOC_DAQ => self.alloc_daq(args),
            cmd::ALLOC_ODT => self.alloc_odt(args),
            cmd::ALLOC_ODT_ENTRY => self.alloc_odt_entry(args),
            _ => Err(Fail::new(err::CMD_UNKNOWN)),
        }
    }

    /// CONNECT: (re)starts a session from a clean state, calibration locked.
    fn connect(&mut self, args: Args<'_>) -> Outcome {
        // Mode 0 is normal, mode 1 user-defined (treated as normal).
        if args.u8(1)? > 1 {
            return Err(Fail::new(err::OUT_OF_RANGE));
        }
        self.reset_session();
        self.connected = true;
        let mut packet = Packet::ok(&[
            resource::CAL_PAG | resource::DAQ,
            comm_mode::OPTIONAL, // Intel byte order, byte granularity, no slave block mode
            MAX_CTO as u8,
        ]);
        packet.push_u16(MAX_DTO as u16);
        packet.push(1); // protocol layer version
        packet.push(1); // transport layer version
        Ok(Answer::Reply(packet))
    }

    /// Everything a new session starts without: DAQ, MTA, pending transfers, unlocked state.
    /// (The delay after wrong keys outlives sessions: reconnecting does not clear it.)
    fn reset_session(&mut self) {
        self.cal_locked = true;
        self.unlock = Unlock::IDLE;
        self.mta = Mta::START;
        self.xcp_page = 0;
        self.block = Block::IDLE;
        self.daq.free();
    }

    fn get_status(&self, target: &impl Target) -> Outcome {
        let mut status = 0;
        if target.store_pending() {
            status |= session::STORE_CAL_REQ;
        }
        if self.daq.any_running() {
            status |= session::DAQ_RUNNING;
        }
        let mut packet = Packet::ok(&[status, self.protection(), 0]);
        packet.push_u16(0); // session configuration id
        Ok(Answer::Reply(packet))
    }

    /// The protection status bits: which resources are locked.
    fn protection(&self) -> u8 {
        if self.cal_locked {
            resource::CAL_PAG
        } else {
            0
        }
    }

    /// ERR_ACCESS_LOCKED unless calibration was unlocked in this session.
    pub(crate) fn require_unlocked(&self) -> Result<(), Fail> {
        if self.cal_locked {
            Err(Fail::because(
                err::ACCESS_LOCKED,
                Detail::of(reason::LOCKED, 0.0, 0.0),
            ))
        } else {
            Ok(())
        }
    }

    /// SET_REQUEST: only STORE_CAL_REQ, handed to the target.
    fn set_request(&mut self, target: &mut impl Target, args: Args<'_>) -> Outcome {
        let mode = args.u8(1)?;
        if mode != session::STORE_CAL_REQ {
            return Err(Fail::new(err::OUT_OF_RANGE));
        }
        self.require_unlocked()?;
        target
            .request_store()
            .map_err(|refusal| Fail::refused(refusal, target))?;
        Ok(Answer::Reply(Packet::ok(&[])))
    }

    /// GET_SEED: a fresh seed for the calibration resource while it is locked; length 0 for a
    /// resource that is not protected (DAQ, or calibration once unlocked). After a wrong key,
    /// ERR_RESOURCE_TEMPORARY_NOT_ACCESSIBLE until the delay has passed.
    fn get_seed(&mut self, target: &mut impl Target, args: Args<'_>, now_us: u32) -> Outcome {
        let mode = args.u8(1)?;
        match mode {
            0 => {
                let wanted = args.u8(2)?;
                match wanted {
                    resource::CAL_PAG if self.cal_locked => {
                        if let Some(after) = self.seed_after_us {
                            let left_us = after.wrapping_sub(now_us);
                            // Wrapping difference: "before `after`" is up to half the clock.
                            if left_us > 0 && left_us < u32::MAX / 2 {
                                return Err(Fail::because(
                                    err::RESOURCE_TEMPORARY_NOT_ACCESSIBLE,
                                    Detail::of(reason::TOO_SOON, left_us as f32 / 1e6, 0.0),
                                ));
                            }
                            self.seed_after_us = None;
                        }
                        let mut seed = [0u8; SEED_LEN];
                        target.seed(now_us, &mut seed);
                        self.unlock = Unlock {
                            seed,
                            seeded: true,
                            ..Unlock::IDLE
                        };
                        let mut packet = Packet::ok(&[SEED_LEN as u8]);
                        packet.extend(&seed);
                        Ok(Answer::Reply(packet))
                    }
                    resource::CAL_PAG | resource::DAQ => Ok(Answer::Reply(Packet::ok(&[0]))),
                    _ => Err(Fail::new(err::OUT_OF_RANGE)),
                }
            }
            // The whole seed went out with the first part: nothing remains.
            1 if self.unlock.seeded => Ok(Answer::Reply(Packet::ok(&[0]))),
            1 => Err(Fail::new(err::SEQUENCE)),
            _ => Err(Fail::new(err::OUT_OF_RANGE)),
        }
    }

    /// UNLOCK: collects the key (the first packet announces its total length, every packet the
    /// bytes still to come) and checks it against the seed once complete. A wrong key ends the
    /// session, as the standard requires, and delays the next seed.
    fn unlock(&mut self, target: &impl Target, args: Args<'_>, now_us: u32) -> Outcome {
        let remaining = usize::from(args.u8(1)?);
        if !self.unlock.seeded {
            return Err(Fail::new(err::SEQUENCE));
        }
        if self.unlock.key_len == 0 {
            if remaining == 0 || remaining > KEY_MAX {
                self.unlock = Unlock::IDLE;
                return Err(Fail::new(err::OUT_OF_RANGE));
            }
            self.unlock.key_len = remaining;
        } else if Some(remaining) != self.unlock.key_len.checked_sub(self.unlock.got) {
            self.unlock = Unlock::IDLE;
            return Err(Fail::new(err::SEQUENCE));
        }
        let chunk = remaining.min(MAX_CTO - 2);
        let bytes = match args.slice(2, chunk) {
            Ok(bytes) => bytes,
            Err(fail) => {
                self.unlock = Unlock::IDLE;
                return Err(fail);
            }
        };
        let start = self.unlock.got;
        let end = start.saturating_add(chunk);
        if let Some(slots) = self.unlock.key.get_mut(start..end) {
            for (slot, byte) in slots.iter_mut().zip(bytes) {
                *slot = *byte;
            }
        }
        self.unlock.got = end;
        if end < self.unlock.key_len {
            return Ok(Answer::Reply(Packet::ok(&[self.protection()])));
        }
        let key = self.unlock.key.get(..end).unwrap_or(&[]);
        let valid = target.key_is_valid(&self.unlock.seed, key);
        self.unlock = Unlock::IDLE;
        if valid {
            self.cal_locked = false;
            self.wrong_keys_in_a_row = 0;
            self.seed_after_us = None;
            Ok(Answer::Reply(Packet::ok(&[self.protection()])))
        } else {
            self.end_session();
            self.counters.wrong_keys = self.counters.wrong_keys.wrapping_add(1);
            self.wrong_keys_in_a_row = self.wrong_keys_in_a_row.saturating_add(1);
            let delay_us = self.config.unlock_delay_us(self.wrong_keys_in_a_row);
            self.seed_after_us = Some(now_us.wrapping_add(delay_us));
            Err(Fail::because(
                err::ACCESS_LOCKED,
                Detail::of(reason::WRONG_KEY, delay_us as f32 / 1e6, 0.0),
            ))
        }
    }
}
