//! A fake ECU for the slave's tests: a 32-byte calibration segment (working page 0, reference
//! page 1) at 0x0001_0000, a 16-byte measurement area at 0x0002_0000, the EPK at 0x0003_0000;
//! everything else (and every address extension but 0) is not mapped. It records every access.
#![allow(dead_code)] // each test file uses a different part

use std::cell::RefCell;

use aer_xcp::{Config, EventChannel, Refusal, SEED_LEN, Segment, Slave, Target};

pub const CAL: u32 = 0x0001_0000;
pub const CAL_LEN: usize = 32;
pub const MEAS: u32 = 0x0002_0000;
pub const MEAS_LEN: usize = 16;
pub const EPK_ADDR: u32 = 0x0003_0000;
pub const EPK: &[u8] = b"AER-CCM 0.1.0 cal-7f3a";

/// Working-page byte the target limits to 0..=100.
pub const LIMITED: usize = 0;
/// The pedal pair: rest (u16 at 4) must stay below full (u16 at 6).
pub const PEDAL_REST: usize = 4;
pub const PEDAL_FULL: usize = 6;

/// Bytes of the key the fake expects (two UNLOCK packets).
pub const KEY_LEN: usize = 8;

pub static EVENTS: [EventChannel; 2] = [
    EventChannel {
        name: "control",
        period_us: 10_000,
        priority: 1,
    },
    EventChannel {
        name: "sensors",
        period_us: 1_000,
        priority: 2,
    },
];

pub static CONFIG: Config = Config {
    events: &EVENTS,
    id_text: "AER CCM",
    a2l_name: "aer_ccm",
    segment: Segment {
        address: CAL,
        length: CAL_LEN as u32,
        ext: 0,
    },
    frame_budget_per_s: 250,
    response_reserve_per_s: 50,
    max_bs: 8,
    min_st_100us: 0,
    max_odt_entry_size: 7,
    max_checksum_block: 256,
    driver_version: 0x10,
    idle_timeout_ms: IDLE_TIMEOUT_MS,
    unlock_delay_ms: 1_000,
    unlock_delay_max_ms: 300_000,
};

/// The test slave's idle time-out (ms).
pub const IDLE_TIMEOUT_MS: u32 = 60_000;

const _: () = assert!(CONFIG.is_valid());

/// The slave under test: 4 lists, 16 ODTs, 64 entries.
pub type TestSlave = Slave<4, 16, 64>;

/// One access the slave asked the target for.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Access {
    pub page: u8,
    pub ext: u8,
    pub address: u32,
    pub len: usize,
    pub accepted: bool,
}

/// The fake ECU.
#[derive(Debug, Clone)]
pub struct FakeTarget {
    pub working: [u8; CAL_LEN],
    pub reference: [u8; CAL_LEN],
    pub measurement: [u8; MEAS_LEN],
    pub ecu_page: u8,
    /// The car is moving: calibration changes are refused.
    pub moving: bool,
    pub store_pending: bool,
    seed_counter: u8,
    pub reads: RefCell<Vec<Access>>,
    /// Every write call with its data, accepted or not.
    pub writes: Vec<(u8, u32, Vec<u8>, bool)>,
    /// Page switches and copies that reached the target.
    pub page_calls: usize,
}

impl Default for FakeTarget {
    fn default() -> Self {
        Self::new()
    }
}

/// Offset of `[address, address + len)` inside `[base, base + size)`, if it lies inside.
fn inside(base: u32, size: usize, address: u32, len: usize) -> Option<usize> {
    let offset = usize::try_from(address.checked_sub(base)?).ok()?;
    (offset.checked_add(len)? <= size).then_some(offset)
}

impl FakeTarget {
    pub fn new() -> Self {
        let mut reference = [0u8; CAL_LEN];
        for (i, byte) in reference.iter_mut().enumerate() {
            *byte = i as u8;
        }
        reference[LIMITED] = 50;
        reference[PEDAL_REST..PEDAL_REST + 2].copy_from_slice(&100u16.to_le_bytes());
        reference[PEDAL_FULL..PEDAL_FULL + 2].copy_from_slice(&200u16.to_le_bytes());
        let mut measurement = [0u8; MEAS_LEN];
        for (i, byte) in measurement.iter_mut().enumerate() {
            *byte = 0xA0 + i as u8;
        }
        FakeTarget {
            working: reference,
            reference,
            measurement,
            ecu_page: 0,
            moving: false,
            store_pending: false,
            seed_counter: 0,
            reads: RefCell::new(Vec::new()),
            writes: Vec::new(),
            page_calls: 0,
        }
    }

    /// The key the fake accepts for a seed.
    pub fn key_for(seed: &[u8]) -> Vec<u8> {
        (0..KEY_LEN)
            .map(|i| seed[i % seed.len()] ^ (0xA5u8.wrapping_add(i as u8)))
            .collect()
    }

    /// Whether a page passes the target's checks.
    fn page_valid(page: &[u8; CAL_LEN]) -> Result<(), Refusal> {
        let rest = u16::from_le_bytes([page[PEDAL_REST], page[PEDAL_REST + 1]]);
        let full = u16::from_le_bytes([page[PEDAL_FULL], page[PEDAL_FULL + 1]]);
        if page[LIMITED] > 100 || rest >= full {
            return Err(Refusal::OutOfRange);
        }
        Ok(())
    }

    /// Whether an access is inside the map (the property tests' check).
    pub fn in_map(ext: u8, address: u32, len: usize) -> bool {
        ext == 0
            && (inside(CAL, CAL_LEN, address, len).is_some()
                || inside(MEAS, MEAS_LEN, address, len).is_some()
                || inside(EPK_ADDR, EPK.len(), address, len).is_some())
    }

    fn lookup(&self, page: u8, ext: u8, address: u32, len: usize) -> Result<&[u8], Refusal> {
        if ext != 0 {
            return Err(Refusal::NotMapped);
        }
        if let Some(offset) = inside(CAL, CAL_LEN, address, len) {
            let page = match page {
                0 => &self.working,
                1 => &self.reference,
                _ => return Err(Refusal::PageNotValid),
            };
            return Ok(&page[offset..offset + len]);
        }
        if let Some(offset) = inside(MEAS, MEAS_LEN, address, len) {
            return Ok(&self.measurement[offset..offset + len]);
        }
        if let Some(offset) = inside(EPK_ADDR, EPK.len(), address, len) {
            return Ok(&EPK[offset..offset + len]);
        }
        Err(Refusal::NotMapped)
    }
}

impl Target for FakeTarget {
    fn epk(&self) -> &[u8] {
        EPK
    }

    fn read(&self, page: u8, ext: u8, address: u32, out: &mut [u8]) -> Result<(), Refusal> {
        let result = self
            .lookup(page, ext, address, out.len())
            .map(|bytes| out.copy_from_slice(bytes));
        self.reads.borrow_mut().push(Access {
            page,
            ext,
            address,
            len: out.len(),
            accepted: result.is_ok(),
        });
        result
    }

    fn write(&mut self, ext: u8, address: u32, data: &[u8]) -> Result<(), Refusal> {
        let result = (|| {
            if ext != 0 {
                return Err(Refusal::NotMapped);
            }
            let offset = inside(CAL, CAL_LEN, address, data.len()).ok_or(Refusal::NotMapped)?;
            if self.moving {
                return Err(Refusal::WriteProtected);
            }
            let mut page = self.working;
            page[offset..offset + data.len()].copy_from_slice(data);
            Self::page_valid(&page)?;
            self.working = page;
            Ok(())
        })();
        self.writes
            .push((ext, address, data.to_vec(), result.is_ok()));
        result
    }

    fn ecu_page(&self) -> u8 {
        self.ecu_page
    }

    fn set_ecu_page(&mut self, page: u8) -> Result<(), Refusal> {
        self.page_calls += 1;
        if self.moving {
            return Err(Refusal::WriteProtected);
        }
        if page > 1 {
            return Err(Refusal::PageNotValid);
        }
        self.ecu_page = page;
        Ok(())
    }

    fn copy_page(&mut self, from: u8, to: u8) -> Result<(), Refusal> {
        self.page_calls += 1;
        if to != 0 || self.moving {
            return Err(Refusal::WriteProtected);
        }
        let source = match from {
            0 => self.working,
            1 => self.reference,
            _ => return Err(Refusal::PageNotValid),
        };
        Self::page_valid(&source)?;
        self.working = source;
        Ok(())
    }

    fn seed(&mut self, _now_us: u32, out: &mut [u8; SEED_LEN]) {
        self.seed_counter = self.seed_counter.wrapping_add(1);
        for (i, byte) in out.iter_mut().enumerate() {
            *byte = self
                .seed_counter
                .wrapping_mul(37)
                .wrapping_add(i as u8 * 11);
        }
    }

    fn key_is_valid(&self, seed: &[u8], key: &[u8]) -> bool {
        key == Self::key_for(seed).as_slice()
    }

    fn request_store(&mut self) -> Result<(), Refusal> {
        self.store_pending = true;
        Ok(())
    }

    fn store_pending(&self) -> bool {
        self.store_pending
    }
}

/// A slave and its target, with a clock.
pub struct Bench {
    pub slave: TestSlave,
    pub target: FakeTarget,
    pub now_us: u32,
}

impl Default for Bench {
    fn default() -> Self {
        Self::new()
    }
}

impl Bench {
    pub fn new() -> Self {
        Bench {
            slave: TestSlave::new(&CONFIG),
            target: FakeTarget::new(),
            now_us: 1_000,
        }
    }

    /// Sends one command packet; the answer's bytes, if any.
    pub fn cmd(&mut self, packet: &[u8]) -> Option<Vec<u8>> {
        let mut reply = [0u8; 8];
        let len = self
            .slave
            .command(&mut self.target, packet, self.now_us, &mut reply)?;
        assert!((1..=8).contains(&len), "answer length {len}");
        Some(reply[..len].to_vec())
    }

    /// Sends one command that must be answered; the answer.
    pub fn ask(&mut self, packet: &[u8]) -> Vec<u8> {
        self.cmd(packet)
            .unwrap_or_else(|| panic!("no answer to {packet:02X?}"))
    }

    /// A connected bench.
    pub fn connected() -> Self {
        let mut bench = Self::new();
        assert_eq!(bench.ask(&[0xFF, 0x00])[0], 0xFF);
        bench
    }

    /// A connected bench with calibration unlocked.
    pub fn unlocked() -> Self {
        let mut bench = Self::connected();
        bench.unlock();
        bench
    }

    /// Runs GET_SEED and UNLOCK with the right key.
    pub fn unlock(&mut self) {
        let seed = self.ask(&[0xF8, 0x00, 0x01]);
        assert_eq!(seed[..2], [0xFF, SEED_LEN as u8]);
        let key = FakeTarget::key_for(&seed[2..]);
        let first = self.ask(&[&[0xF7, KEY_LEN as u8][..], &key[..6]].concat());
        assert_eq!(first, [0xFF, 0x01], "still locked after the first part");
        let second = self.ask(&[&[0xF7, (KEY_LEN - 6) as u8][..], &key[6..]].concat());
        assert_eq!(second, [0xFF, 0x00], "unlocked");
    }

    /// SET_MTA to an address (extension 0).
    pub fn set_mta(&mut self, address: u32) {
        let a = address.to_le_bytes();
        assert_eq!(self.ask(&[0xF6, 0, 0, 0, a[0], a[1], a[2], a[3]]), [0xFF]);
    }

    /// Fires an event channel; the DTOs sent.
    pub fn event(&mut self, channel: u16) -> Vec<Vec<u8>> {
        let mut sent = Vec::new();
        let report = self.slave.event(
            &self.target,
            channel,
            self.now_us,
            &mut |packet: &[u8]| {
                sent.push(packet.to_vec());
                true
            },
        );
        assert_eq!(report.sent as usize, sent.len());
        assert_eq!(report.dropped, 0);
        sent
    }
}

/// A u32 as the four Intel-order bytes of a command.
pub fn le32(value: u32) -> [u8; 4] {
    value.to_le_bytes()
}

/// Allocates one list of two ODTs (2 entries, 1 entry) and fills it:
/// ODT 0 = measurement[0..2] + measurement[5], ODT 1 = measurement[8..12].
pub fn configure_two_odt_list(bench: &mut Bench) {
    for packet in [
        &[0xD6][..],
        &[0xD5, 0, 1, 0],
        &[0xD4, 0, 0, 0, 2],
        &[0xD3, 0, 0, 0, 0, 2],
        &[0xD3, 0, 0, 0, 1, 1],
        &[0xE2, 0, 0, 0, 0, 0],
    ] {
        assert_eq!(bench.ask(packet), [0xFF], "{packet:02X?}");
    }
    let write = |bench: &mut Bench, size: u8, address: u32| {
        let a = le32(address);
        assert_eq!(
            bench.ask(&[0xE1, 0xFF, size, 0, a[0], a[1], a[2], a[3]]),
            [0xFF]
        );
    };
    write(bench, 2, MEAS);
    write(bench, 1, MEAS + 5);
    assert_eq!(bench.ask(&[0xE2, 0, 0, 0, 1, 0]), [0xFF]);
    write(bench, 4, MEAS + 8);
}

/// The two-ODT list on the control channel, started by select + START_STOP_SYNCH.
pub fn start_two_odt_list(bench: &mut Bench, timestamp: bool) {
    configure_two_odt_list(bench);
    let mode = if timestamp { 0x10 } else { 0x00 };
    assert_eq!(bench.ask(&[0xE0, mode, 0, 0, 0, 0, 1, 0]), [0xFF]);
    assert_eq!(
        bench.ask(&[0xDE, 0x02, 0, 0]),
        [0xFF, 0x00],
        "selected; FIRST_PID 0"
    );
    assert_eq!(bench.ask(&[0xDD, 0x01]), [0xFF]);
    assert!(bench.slave.is_daq_running());
}
