//! The slave's fixed parameters, filled by the ECU from its generated constants at compile time.

use crate::protocol::{MAX_CTO, MAX_DTO, time_unit};

/// One event channel: a point in the ECU's program where DAQ lists may sample (e.g. after the
/// control step, after a sensor sample).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EventChannel {
    /// Name shown by the calibration tool (GET_DAQ_EVENT_INFO, read by UPLOAD); at most 255
    /// bytes of ASCII.
    pub name: &'static str,
    /// Shortest interval between two firings, in microseconds. It is announced as the event's
    /// cycle and bounds the DTO rate for the frame budget; 0 means sporadic, and DAQ lists on a
    /// sporadic channel cannot be started (their rate is unbounded).
    pub period_us: u32,
    /// Priority announced to the tool (0 lowest).
    pub priority: u8,
}

/// The calibration segment (segment 0), as GET_SEGMENT_INFO reports it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Segment {
    /// XCP address of the segment's first byte.
    pub address: u32,
    /// Length of the segment in bytes.
    pub length: u32,
    /// Address extension of the segment.
    pub ext: u8,
}

/// Everything fixed about the slave.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Config {
    /// The event channels, numbered from 0 in this order.
    pub events: &'static [EventChannel],
    /// GET_ID type 0: ASCII text naming the slave (at most 255 bytes).
    pub id_text: &'static str,
    /// GET_ID type 1: the A2L file name without path and extension (at most 255 bytes).
    pub a2l_name: &'static str,
    /// The calibration segment.
    pub segment: Segment,
    /// Frames per second the slave may send on the bus in total (the CCM: 250, from the DBC's
    /// cycle time of XCP_Res).
    pub frame_budget_per_s: u32,
    /// Part of the budget kept for command responses; DAQ may use the rest.
    pub response_reserve_per_s: u32,
    /// Master block mode: most DOWNLOAD/DOWNLOAD_NEXT packets in one block (1..=42, so a block
    /// of up to 252 bytes is written in one [`crate::Target::write`]).
    pub max_bs: u8,
    /// Master block mode: minimum gap between the packets of a block, in 100 us.
    pub min_st_100us: u8,
    /// Largest ODT entry in bytes (1..=7: one entry fills at most a DTO after its PID).
    pub max_odt_entry_size: u8,
    /// Largest BUILD_CHECKSUM block in bytes: bounds the time one command can take.
    pub max_checksum_block: u32,
    /// Driver version announced by GET_COMM_MODE_INFO.
    pub driver_version: u8,
    /// No command for this long (ms): the session's calibration unlock lapses, and with no
    /// DAQ list running the session ends ([`crate::Slave::poll`]). The ECU's A2L and docs
    /// state it.
    pub idle_timeout_ms: u32,
    /// After a wrong key, GET_SEED is refused this long (ms); each further wrong key in a row
    /// doubles it, up to [`Self::unlock_delay_max_ms`]. A right key clears it.
    pub unlock_delay_ms: u32,
    /// The longest delay after wrong keys (ms).
    pub unlock_delay_max_ms: u32,
}

/// Largest block a master-block-mode DOWNLOAD can announce (its length is one byte).
pub(crate) const BLOCK_MAX: usize = 255;

/// Data bytes a DOWNLOAD or DOWNLOAD_NEXT packet carries at most.
pub(crate) const DOWNLOAD_CHUNK: usize = MAX_CTO - 2;

impl Config {
    /// Whether every field is within what the protocol can express: check it at compile time
    /// (`const _: () = assert!(CONFIG.is_valid());`). Out-of-range values are clamped at run
    /// time, never trusted.
    pub const fn is_valid(&self) -> bool {
        let mut i = 0;
        while i < self.events.len() {
            if self.events[i].name.len() > 255 {
                return false;
            }
            i += 1;
        }
        self.events.len() <= u16::MAX as usize
            && self.id_text.len() <= 255
            && self.a2l_name.len() <= 255
            && self.response_reserve_per_s < self.frame_budget_per_s
            && self.max_bs >= 1
            && self.max_bs as usize * DOWNLOAD_CHUNK <= BLOCK_MAX
            && self.max_odt_entry_size >= 1
            && (self.max_odt_entry_size as usize) < MAX_DTO
            && self.idle_timeout_ms >= 1_000
            && self.unlock_delay_ms >= 1
            && self.unlock_delay_ms <= self.unlock_delay_max_ms
            && self.unlock_delay_max_ms <= u32::MAX / 2_000
    }

    /// The delay after the `wrong`-th wrong key in a row (1 for the first), in us.
    pub const fn unlock_delay_us(&self, wrong: u32) -> u32 {
        let mut delay = self.unlock_delay_ms;
        let mut step = 1;
        while step < wrong && delay < self.unlock_delay_max_ms {
            delay = delay.saturating_mul(2);
            step += 1;
        }
        if delay > self.unlock_delay_max_ms {
            delay = self.unlock_delay_max_ms;
        }
        delay.saturating_mul(1_000)
    }

    /// MAX_BS as announced and enforced (clamped to 1..=42).
    pub(crate) const fn block_packets(&self) -> u8 {
        let most = (BLOCK_MAX / DOWNLOAD_CHUNK) as u8;
        if self.max_bs == 0 {
            1
        } else if self.max_bs > most {
            most
        } else {
            self.max_bs
        }
    }

    /// MAX_ODT_ENTRY_SIZE_DAQ as announced and enforced (clamped to 1..=7).
    pub(crate) const fn entry_size_limit(&self) -> u8 {
        let most = (MAX_DTO - 1) as u8;
        if self.max_odt_entry_size == 0 {
            1
        } else if self.max_odt_entry_size > most {
            most
        } else {
            self.max_odt_entry_size
        }
    }

    /// DTO frames per second DAQ may use.
    pub(crate) const fn daq_budget_per_s(&self) -> u32 {
        self.frame_budget_per_s
            .saturating_sub(self.response_reserve_per_s)
    }
}

impl EventChannel {
    /// The period as GET_DAQ_EVENT_INFO's (cycle, unit): the finest unit from 1 us to 1 s in
    /// which the period is a whole number of at most 255; (0, 1 us unit) for a sporadic channel
    /// or a period no such pair expresses exactly (announced as sporadic rather than wrong).
    pub const fn cycle(&self) -> (u8, u8) {
        let mut unit = time_unit::US_1;
        let mut scale: u32 = 1;
        while unit <= time_unit::S_1 {
            if self.period_us % scale == 0 && self.period_us / scale <= 255 {
                return ((self.period_us / scale) as u8, unit);
            }
            unit += 1;
            scale = scale.saturating_mul(10);
        }
        (0, time_unit::US_1)
    }
}
