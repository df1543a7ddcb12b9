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
//! but never calibrates.

use crate::calibration::EPK;
use crate::calibration::state::{CalibrationState, Page, Refused};
use crate::calibration::store::{CalibrationFlash, CalibrationStore, SaveError};
use aer::calibration::VehicleState;
use aer::calibration::xcp::{
    A2L_NAME, CALIBRATION_ADDRESS, CALIBRATION_LEN, DAQ_FRAMES_PER_S, EPK_ADDRESS, EVENTS,
    INTERNALS_ADDRESS, INTERNALS_LEN, MAX_BS, MAX_CHECKSUM_BLOCK, MAX_DAQ, MAX_ODT_ENTRY_SIZE,
    MIN_ST, ODT_ENTRIES, TELEMETRY_ADDRESS, TELEMETRY_LEN,
};
pub use aer_xcp::seed_key::{KEY_LEN, SECRET_LEN, key_for};
use aer_xcp::{Config, DaqReport, EventChannel, Refusal, SEED_LEN, Segment, Slave, Target};

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
};

const _: () = assert!(CONFIG.is_valid());

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
    state: u64,
}

impl SeedKey {
    /// With the team's `secret` (`None`: calibration can never be unlocked) and `entropy` to
    /// start the seed generator (the Teensy's TRNG; the host's clock in tests). Seeds never
    /// repeat within 2^64 draws, so a recorded answer cannot be replayed.
    pub const fn new(secret: Option<[u8; SECRET_LEN]>, entropy: u64) -> Self {
        Self {
            secret,
            // xorshift64* must not start at zero.
            state: entropy | 1,
        }
    }

    fn next(&mut self) -> u64 {
        self.state ^= self.state >> 12;
        self.state ^= self.state << 25;
        self.state ^= self.state >> 27;
        self.state.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
}

/// Where an XCP address lies.
enum Region {
    Calibration(usize),
    Telemetry(usize),
    Internals(usize),
    Epk(usize),
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
    } else {
        within(EPK_ADDRESS, EPK.len()).map(Region::Epk)
    }
}

/// The CCM as the slave sees it during one command or event: borrowed for that long.
pub struct CcmTarget<'a, F: CalibrationFlash> {
    /// The live calibration.
    pub calibration: &'a mut CalibrationState,
    /// The telemetry and internals.
    pub measurements: &'a Measurements,
    /// Whether the car moves and the tractive system is live now.
    pub vehicle: VehicleState,
    /// Seeds and the secret.
    pub keys: &'a mut SeedKey,
    /// The saved copies.
    pub store: &'a mut CalibrationStore,
    /// Their flash.
    pub flash: &'a mut F,
}

fn refusal(refused: Refused) -> Refusal {
    match refused {
        Refused::NotMapped => Refusal::NotMapped,
        Refused::OutOfRange => Refusal::OutOfRange,
        Refused::NotNow => Refusal::WriteProtected,
    }
}

fn copy_out(source: &[u8], offset: usize, out: &mut [u8]) -> Result<(), Refusal> {
    let bytes = source
        .get(offset..offset.saturating_add(out.len()))
        .ok_or(Refusal::NotMapped)?;
    out.copy_from_slice(bytes);
    Ok(())
}

impl<F: CalibrationFlash> Target for CcmTarget<'_, F> {
    fn epk(&self) -> &[u8] {
        EPK
    }

    fn read(&self, page: u8, ext: u8, address: u32, out: &mut [u8]) -> Result<(), Refusal> {
        match region(ext, address, out.len()).ok_or(Refusal::NotMapped)? {
            Region::Calibration(offset) => {
                let page = Page::from_number(page).ok_or(Refusal::PageNotValid)?;
                copy_out(self.calibration.page(page), offset, out)
            }
            Region::Telemetry(offset) => copy_out(&self.measurements.telemetry, offset, out),
            Region::Internals(offset) => copy_out(&self.measurements.internals, offset, out),
            Region::Epk(offset) => copy_out(EPK, offset, out),
        }
    }

    fn write(&mut self, ext: u8, address: u32, data: &[u8]) -> Result<(), Refusal> {
        match region(ext, address, data.len()) {
            Some(Region::Calibration(offset)) => self
                .calibration
                .write(offset, data, self.vehicle)
                .map_err(refusal),
            // Measurements and the EPK are read-only.
            Some(_) => Err(Refusal::WriteProtected),
            None => Err(Refusal::NotMapped),
        }
    }

    fn ecu_page(&self) -> u8 {
        self.calibration.ecu_page().number()
    }

    fn set_ecu_page(&mut self, page: u8) -> Result<(), Refusal> {
        let page = Page::from_number(page).ok_or(Refusal::PageNotValid)?;
        self.calibration.select(page, self.vehicle).map_err(refusal)
    }

    fn copy_page(&mut self, from: u8, to: u8) -> Result<(), Refusal> {
        let from = Page::from_number(from).ok_or(Refusal::PageNotValid)?;
        let to = Page::from_number(to).ok_or(Refusal::PageNotValid)?;
        match (from, to) {
            (Page::Reference, Page::Working) => self
                .calibration
                .revert_to_reference(self.vehicle)
                .map_err(refusal),
            (Page::Working, Page::Reference) => Err(Refusal::WriteProtected),
            _ => Ok(()),
        }
    }

    fn seed(&mut self, out: &mut [u8; SEED_LEN]) {
        let random = self.keys.next().to_le_bytes();
        for (byte, value) in out.iter_mut().zip(random) {
            *byte = value;
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
        let page = *self.calibration.page(Page::Working);
        match self.store.save(self.flash, &page, EPK, self.vehicle) {
            Ok(saved) => {
                self.calibration.saved(saved);
                Ok(())
            }
            Err(SaveError::NotAllowedNow) => Err(Refusal::WriteProtected),
            Err(SaveError::EpkTooLong | SaveError::Flash(_)) => Err(Refusal::Failed),
        }
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
            vehicle,
            keys: &mut self.keys,
            store: &mut self.store,
            flash: &mut self.flash,
        };
        let answer = self.slave.command(&mut target, packet, now_us, reply);
        let connected = self.slave.is_connected();
        target
            .calibration
            .set_xcp(connected, connected && !self.slave.is_calibration_locked());
        answer
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
            // Sampling only reads: the vehicle's state decides writes alone.
            vehicle: VehicleState {
                moving: true,
                tractive_live: true,
            },
            keys: &mut self.keys,
            store: &mut self.store,
            flash: &mut self.flash,
        };
        self.slave.event(&target, channel, now_us, send)
    }
}
