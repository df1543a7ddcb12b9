//! The CCM's XCP slave: the portable protocol core (`aer-xcp`) over the CCM's own tables.
//!
//! XCP addresses map onto the generated tables only (`aer::calibration::xcp`): the calibration
//! page (working page 0, reference page 1), the telemetry packet as last sent, the
//! controllers' internals and the EPK. Nothing else is readable or writable. A write goes
//! through [`CalibrationState::write`]: checked whole (limits, sensor checks, the change
//! condition in the vehicle's state now) and applied whole or refused with the XCP error a
//! master reports (ERR_OUT_OF_RANGE, ERR_WRITE_PROTECTED), the value unchanged. Saving the
//! working page (SET_REQUEST STORE_CAL_REQ) writes the flash at once, only at standstill with
//! the tractive system off.
//!
//! Unlocking calibration (GET_SEED/UNLOCK): the key is the first [`KEY_LEN`] bytes of
//! HMAC-SHA256 over the 6-byte seed, keyed with the team's 32-byte secret, which is not in
//! the repository (`ccm/xcp-secret.key`, read by the firmware's build; docs/calibration.md
//! says how to make one). An image built without a secret cannot be unlocked: it measures
//! but never calibrates. Seeds come from an HMAC_DRBG the TRNG starts
//! ([`aer_xcp::seeds`]); without 256 bits from it, calibration stays locked too.
//!
//! Besides the calibration, the slave publishes its own numbers at
//! [`XCP_STATUS_ADDRESS`]: the last refused command and why (the parameter, element, value and
//! limit, from [`crate::calibration::why`]) and its counters, refreshed after every command
//! and event.

use crate::calibration::EPK;
use crate::calibration::state::{CalibrationState, Page, Refused};
use crate::calibration::store::{CalibrationFlash, CalibrationStore, SaveError};
use aer::calibration::VehicleState;
use aer::calibration::xcp::{
    A2L_NAME, CALIBRATION_ADDRESS, CALIBRATION_LEN, DAQ_FRAMES_PER_S, EPK_ADDRESS, EVENTS,
    IDLE_TIMEOUT_MS, INTERNALS_ADDRESS, INTERNALS_LEN, MAX_BS, MAX_CHECKSUM_BLOCK, MAX_DAQ,
    MAX_ODT_ENTRY_SIZE, MIN_ST, ODT_ENTRIES, TELEMETRY_ADDRESS, TELEMETRY_LEN, UNLOCK_DELAY_MAX_MS,
    UNLOCK_DELAY_MS, XCP_STATUS_ADDRESS, XCP_STATUS_LEN,
};
pub use aer_xcp::seed_key::{KEY_LEN, SECRET_LEN, key_for};
use aer_xcp::seeds::{ENTROPY_MIN, SeedGenerator};
use aer_xcp::{
    Config, DaqReport, Detail, EventChannel, Refusal, SEED_LEN, Segment, SessionEnd, Slave, Target,
    reason,
};
use core::cell::Cell;

/// The team's secret as the build found it (`ccm/xcp-secret.key` or `AER_XCP_SECRET_FILE`;
/// `None` without one: the images then never unlock).
pub mod team {
    include!(concat!(env!("OUT_DIR"), "/xcp_secret.rs"));
}

/// ODTs the master may allocate over all DAQ lists: with [`ODT_ENTRIES`] entries of up to
/// [`MAX_ODT_ENTRY_SIZE`] bytes, more ODTs than the frame budget could carry at the control
/// rate, so a tuner can spread lists over slower prescalers.
pub const ODTS: usize = 16;
/// Frames per second kept for command responses out of the slave's budget.
const RESPONSE_RESERVE_PER_S: u32 = 50;

/// The slave as the CCM runs it.
pub type CcmSlave = Slave<{ MAX_DAQ as usize }, ODTS, { ODT_ENTRIES as usize }>;

const EVENT_CHANNELS: [EventChannel; EVENTS.len()] = {
    let mut channels = [EventChannel {
        name: "",
        period_us: 0,
        priority: 0,
    }; EVENTS.len()];
    let mut index = 0;
    while index < EVENTS.len() {
        channels[index] = EventChannel {
            name: EVENTS[index].name,
            period_us: EVENTS[index].period_us,
            priority: 0,
        };
        index += 1;
    }
    channels
};

/// The slave's fixed parameters, from the schema (the A2L promises the same).
pub static CONFIG: Config = Config {
    events: &EVENT_CHANNELS,
    id_text: "AER CCM",
    a2l_name: A2L_NAME,
    segment: Segment {
        address: CALIBRATION_ADDRESS,
        length: CALIBRATION_LEN as u32,
        ext: 0,
    },
    frame_budget_per_s: DAQ_FRAMES_PER_S,
    response_reserve_per_s: RESPONSE_RESERVE_PER_S,
    max_bs: MAX_BS,
    min_st_100us: MIN_ST,
    max_odt_entry_size: MAX_ODT_ENTRY_SIZE,
    max_checksum_block: MAX_CHECKSUM_BLOCK,
    driver_version: 1,
    idle_timeout_ms: IDLE_TIMEOUT_MS,
    unlock_delay_ms: UNLOCK_DELAY_MS,
    unlock_delay_max_ms: UNLOCK_DELAY_MAX_MS,
};

const _: () = assert!(CONFIG.is_valid());
const _: () = assert!(
    XCP_STATUS_LEN == aer_xcp::status::STATUS_LEN,
    "the A2L's XCP status block and the slave's must agree"
);

/// A fresh slave, disconnected and locked.
pub const fn slave() -> CcmSlave {
    CcmSlave::new(&CONFIG)
}

/// What DAQ and UPLOAD read besides the calibration: refreshed after each control step.
#[derive(Debug, Clone, PartialEq)]
pub struct Measurements {
    /// The telemetry packet as last sent.
    pub telemetry: [u8; TELEMETRY_LEN],
    /// The controllers' internals ([`aer::calibration::Internals::to_bytes`]).
    pub internals: [u8; INTERNALS_LEN],
}

impl Default for Measurements {
    fn default() -> Self {
        Self {
            telemetry: [0; TELEMETRY_LEN],
            internals: [0; INTERNALS_LEN],
        }
    }
}

/// Seeds and keys: a generator for unpredictable seeds, and the secret keys are checked with.
#[derive(Clone)]
pub struct SeedKey {
    secret: Option<[u8; SECRET_LEN]>,
    seeds: Option<SeedGenerator>,
}

impl SeedKey {
    /// With the team's `secret` (`None`: calibration can never be unlocked), `entropy` from a
    /// true random source (the Teensy's TRNG; fixed bytes in tests) and `personalization`
    /// (the chip's unique id). Fewer than [`ENTROPY_MIN`] bytes of entropy cannot make
    /// unpredictable seeds: calibration then stays locked, as without a secret.
    pub fn new(
        secret: Option<[u8; SECRET_LEN]>,
        entropy: Option<&[u8]>,
        personalization: &[u8],
    ) -> Self {
        let seeds = entropy
            .filter(|entropy| entropy.len() >= ENTROPY_MIN)
            .map(|entropy| SeedGenerator::new(entropy, personalization));
        Self {
            secret: seeds.as_ref().and(secret),
            seeds,
        }
    }

    /// Whether a master can ever unlock calibration: a secret and a seeded generator.
    pub fn can_unlock(&self) -> bool {
        self.secret.is_some()
    }
}

/// Where an XCP address lies.
enum Region {
    Calibration(usize),
    Telemetry(usize),
    Internals(usize),
    Epk(usize),
    XcpStatus(usize),
}

/// The region and offset of `len` bytes at `address`, if all of them lie in one region.
fn region(ext: u8, address: u32, len: usize) -> Option<Region> {
    if ext != 0 {
        return None;
    }
    let within = |base: u32, size: usize| {
        let offset = usize::try_from(address.checked_sub(base)?).ok()?;
        (offset.checked_add(len)? <= size).then_some(offset)
    };
    if let Some(offset) = within(CALIBRATION_ADDRESS, CALIBRATION_LEN) {
        Some(Region::Calibration(offset))
    } else if let Some(offset) = within(TELEMETRY_ADDRESS, TELEMETRY_LEN) {
        Some(Region::Telemetry(offset))
    } else if let Some(offset) = within(INTERNALS_ADDRESS, INTERNALS_LEN) {
        Some(Region::Internals(offset))
    } else if let Some(offset) = within(EPK_ADDRESS, EPK.len()) {
        Some(Region::Epk(offset))
    } else {
        within(XCP_STATUS_ADDRESS, XCP_STATUS_LEN).map(Region::XcpStatus)
    }
}

/// The CCM as the slave sees it during one command or event: borrowed for that long.
pub struct CcmTarget<'a, F: CalibrationFlash> {
    /// The live calibration.
    pub calibration: &'a mut CalibrationState,
    /// The telemetry and internals.
    pub measurements: &'a Measurements,
    /// The slave's own numbers ([`aer_xcp::Slave::status_bytes`]) as of its last command or
    /// event.
    pub status: &'a [u8; XCP_STATUS_LEN],
    /// Whether the car moves and the tractive system is live now.
    pub vehicle: VehicleState,
    /// Seeds and the secret.
    pub keys: &'a mut SeedKey,
    /// The saved copies.
    pub store: &'a mut CalibrationStore,
    /// Their flash.
    pub flash: &'a mut F,
    /// Why this target last refused ([`Target::explain`]).
    pub why: Cell<Detail>,
}

impl<'a, F: CalibrationFlash> CcmTarget<'a, F> {
    /// The refusal for `refused`, the calibration's reason kept for [`Target::explain`].
    fn refused(&self, refused: Refused) -> Refusal {
        self.why.set(self.calibration.last_refusal());
        match refused {
            Refused::NotMapped => Refusal::NotMapped,
            Refused::OutOfRange => Refusal::OutOfRange,
            Refused::NotNow => Refusal::WriteProtected,
        }
    }

    /// `refusal`, with `reason` kept for [`Target::explain`].
    fn because(&self, refusal: Refusal, reason: u8) -> Refusal {
        self.why.set(Detail::of(reason, 0.0, 0.0));
        refusal
    }

    /// `out.len()` bytes at `offset` of `source`.
    fn copy_out(&self, source: &[u8], offset: usize, out: &mut [u8]) -> Result<(), Refusal> {
        let bytes = source
            .get(offset..offset.saturating_add(out.len()))
            .ok_or_else(|| self.because(Refusal::NotMapped, reason::NOT_MAPPED))?;
        out.copy_from_slice(bytes);
        Ok(())
    }

    fn page(&self, page: u8) -> Result<Page, Refusal> {
        Page::from_number(page).ok_or_else(|| self.because(Refusal::PageNotValid, reason::NONE))
    }
}

impl<F: CalibrationFlash> Target for CcmTarget<'_, F> {
    fn epk(&self) -> &[u8] {
        EPK
    }

    fn read(&self, page: u8, ext: u8, address: u32, out: &mut [u8]) -> Result<(), Refusal> {
        let region = region(ext, address, out.len())
            .ok_or_else(|| self.because(Refusal::NotMapped, reason::NOT_MAPPED))?;
        match region {
            Region::Calibration(offset) => {
                let page = self.page(page)?;
                self.copy_out(self.calibration.page(page), offset, out)
            }
            Region::Telemetry(offset) => self.copy_out(&self.measurements.telemetry, offset, out),
            Region::Internals(offset) => self.copy_out(&self.measurements.internals, offset, out),
            Region::Epk(offset) => self.copy_out(EPK, offset, out),
            Region::XcpStatus(offset) => self.copy_out(self.status, offset, out),
        }
    }

    fn write(&mut self, ext: u8, address: u32, data: &[u8]) -> Result<(), Refusal> {
        match region(ext, address, data.len()) {
            Some(Region::Calibration(offset)) => {
                let written = self.calibration.write(offset, data, self.vehicle);
                written.map_err(|refused| self.refused(refused))
            }
            // Measurements and the EPK are read-only.
            Some(_) => Err(self.because(Refusal::WriteProtected, reason::READ_ONLY)),
            None => Err(self.because(Refusal::NotMapped, reason::NOT_MAPPED)),
        }
    }

    fn ecu_page(&self) -> u8 {
        self.calibration.ecu_page().number()
    }

    fn set_ecu_page(&mut self, page: u8) -> Result<(), Refusal> {
        let page = self.page(page)?;
        let selected = self.calibration.select(page, self.vehicle);
        selected.map_err(|refused| self.refused(refused))
    }

    fn copy_page(&mut self, from: u8, to: u8) -> Result<(), Refusal> {
        let from = self.page(from)?;
        let to = self.page(to)?;
        match (from, to) {
            (Page::Reference, Page::Working) => {
                let reverted = self.calibration.revert_to_reference(self.vehicle);
                reverted.map_err(|refused| self.refused(refused))
            }
            (Page::Working, Page::Reference) => {
                Err(self.because(Refusal::WriteProtected, reason::READ_ONLY))
            }
            _ => Ok(()),
        }
    }

    fn seed(&mut self, now_us: u32, out: &mut [u8; SEED_LEN]) {
        match &mut self.keys.seeds {
            Some(seeds) => seeds.fill(out, &now_us.to_le_bytes()),
            // No generator, no secret: any seed will do, no key is ever right.
            None => out.fill(0),
        }
    }

    fn key_is_valid(&self, seed: &[u8], key: &[u8]) -> bool {
        let Some(secret) = &self.keys.secret else {
            return false;
        };
        let expected = key_for(secret, seed);
        // Compare every byte whatever the first difference, so timing says nothing.
        key.len() == KEY_LEN
            && expected
                .iter()
                .zip(key)
                .fold(0u8, |diff, (a, b)| diff | (a ^ b))
                == 0
    }

    fn request_store(&mut self) -> Result<(), Refusal> {
        // Nothing to save: the working page is what start-up loads now. The flash is not
        // written again (each save erases a sector: a tool saving in a loop must not wear it).
        if !self.calibration.status().ccm_cal_unsaved {
            return Ok(());
        }
        let page = *self.calibration.page(Page::Working);
        match self.store.save(self.flash, &page, EPK, self.vehicle) {
            Ok(saved) => {
                self.calibration.saved(saved);
                Ok(())
            }
            Err(SaveError::NotAllowedNow) => {
                Err(self.because(Refusal::WriteProtected, reason::SAVE_NOT_NOW))
            }
            Err(SaveError::EpkTooLong | SaveError::Flash(_)) => {
                Err(self.because(Refusal::Failed, reason::NONE))
            }
        }
    }

    fn explain(&self) -> Detail {
        self.why.get()
    }
}

/// Everything the CCM keeps for XCP besides the calibration: the slave, its seeds and secret,
/// the saved copies and their flash, and what DAQ samples.
pub struct XcpNode<F: CalibrationFlash> {
    /// The protocol core.
    pub slave: CcmSlave,
    /// Seeds and the secret.
    pub keys: SeedKey,
    /// Which saved copy is newest.
    pub store: CalibrationStore,
    /// The saved copies' flash.
    pub flash: F,
    /// The telemetry and internals as of the last control step.
    pub measurements: Measurements,
    /// The slave's own numbers as of its last command or event.
    status: [u8; XCP_STATUS_LEN],
}

impl<F: CalibrationFlash> XcpNode<F> {
    /// A disconnected, locked slave over `flash`, whose saved copies `store` describes.
    pub fn new(keys: SeedKey, store: CalibrationStore, flash: F) -> Self {
        Self {
            slave: slave(),
            keys,
            store,
            flash,
            measurements: Measurements::default(),
            status: [0; XCP_STATUS_LEN],
        }
    }

    /// Handles one command packet against `calibration` in the vehicle's state `vehicle`;
    /// the answer (if any) goes into `reply`. `calibration` learns whether a master is
    /// connected and has unlocked (CCM_Calibration reports it).
    pub fn command(
        &mut self,
        calibration: &mut CalibrationState,
        vehicle: VehicleState,
        packet: &[u8],
        now_us: u32,
        reply: &mut [u8; aer_xcp::MAX_CTO],
    ) -> Option<usize> {
        let mut target = CcmTarget {
            calibration,
            measurements: &self.measurements,
            status: &self.status,
            vehicle,
            keys: &mut self.keys,
            store: &mut self.store,
            flash: &mut self.flash,
            why: Cell::new(Detail::default()),
        };
        let answer = self.slave.command(&mut target, packet, now_us, reply);
        let connected = self.slave.is_connected();
        target
            .calibration
            .set_xcp(connected, connected && !self.slave.is_calibration_locked());
        self.status = self.slave.status_bytes();
        answer
    }

    /// Runs the slave's clock ([`Slave::poll`]): call it every few milliseconds. A session
    /// with no command for the idle time-out ends (or, with DAQ running, is relocked); the
    /// event telling the master goes to `send`. `calibration` learns the new state.
    pub fn poll(
        &mut self,
        calibration: &mut CalibrationState,
        now_us: u32,
        send: &mut impl FnMut(&[u8]) -> bool,
    ) -> Option<SessionEnd> {
        let ended = self.slave.poll(now_us, send)?;
        self.session_changed(calibration);
        Some(ended)
    }

    /// The transport under the session is gone (a TCP connection closed): the session ends
    /// at once, locked, its DAQ lists stopped.
    pub fn transport_lost(&mut self, calibration: &mut CalibrationState) -> Option<SessionEnd> {
        let ended = self.slave.transport_lost()?;
        self.session_changed(calibration);
        Some(ended)
    }

    fn session_changed(&mut self, calibration: &mut CalibrationState) {
        let connected = self.slave.is_connected();
        calibration.set_xcp(connected, connected && !self.slave.is_calibration_locked());
        self.status = self.slave.status_bytes();
    }

    /// Event channel `channel` fired: the running DAQ lists on it sample the measurements and
    /// `calibration`'s pages; their packets go to `send`.
    pub fn event(
        &mut self,
        calibration: &mut CalibrationState,
        channel: u16,
        now_us: u32,
        send: &mut impl FnMut(&[u8]) -> bool,
    ) -> DaqReport {
        let target = CcmTarget {
            calibration,
            measurements: &self.measurements,
            status: &self.status,
            // Sampling only reads: the vehicle's state decides writes alone.
            vehicle: VehicleState {
                moving: true,
                tractive_live: true,
            },
            keys: &mut self.keys,
            store: &mut self.store,
            flash: &mut self.flash,
            why: Cell::new(Detail::default()),
        };
        let report = self.slave.event(&target, channel, now_us, send);
        if report.sent > 0 || report.dropped > 0 {
            self.status = self.slave.status_bytes();
        }
        report
    }
}
