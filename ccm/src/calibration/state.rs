//! The CCM's live calibration: the working page a calibration tool changes, the reference page
//! (the schema's defaults), which of the two the control step runs on, and what
//! `CCM_Calibration` reports about them.
//!
//! Every change is one transaction: the whole page that would result is checked (each
//! parameter's limits, the sensor cross-checks, and whether every parameter it changes may
//! change in the vehicle's state now) and then applied whole, or refused and nothing changes.
//! The control step copies [`CalibrationState::active`] whole, so it never sees half a change.

use super::store::{Startup, crc32};
use super::{Calibration, SensorCalibration, why};
use aer::calibration::{ChangeWhen, PAGE_LEN, PARAMETERS, VehicleState};
use aer::can::{CcmCalibration, CcmCalibrationCcmCalPage, CcmCalibrationCcmCalStartup};
use aer_xcp::Detail;

/// The two pages of the calibration segment (XCP page numbers).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Page {
    /// Page 0: the working page, tunable.
    Working,
    /// Page 1: the reference page, the schema's defaults, read-only.
    Reference,
}

impl Page {
    /// The page with XCP number `number`.
    pub const fn from_number(number: u8) -> Option<Self> {
        match number {
            0 => Some(Self::Working),
            1 => Some(Self::Reference),
            _ => None,
        }
    }

    /// Its XCP number.
    pub const fn number(self) -> u8 {
        match self {
            Self::Working => 0,
            Self::Reference => 1,
        }
    }
}

/// Why a change was refused; nothing changed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Refused {
    /// The bytes lie outside the page.
    NotMapped,
    /// A value outside its limits, or a set the sensor checks refuse.
    OutOfRange,
    /// A parameter that may not change in the vehicle's state now (see
    /// [`aer::calibration::ChangeWhen`]).
    NotNow,
}

/// The live calibration (see the module's description).
#[derive(Debug, Clone, PartialEq)]
pub struct CalibrationState {
    working: [u8; PAGE_LEN],
    working_calibration: Calibration,
    reference: [u8; PAGE_LEN],
    ecu_page: Page,
    startup: Startup,
    saved_crc: u32,
    active_crc: u32,
    changes: u8,
    refusals: u8,
    why: Detail,
    xcp_connected: bool,
    xcp_unlocked: bool,
}

impl CalibrationState {
    /// Runs `calibration` (what start-up loaded, `startup` says from where) on the working page.
    pub fn new(calibration: Calibration, startup: Startup) -> Self {
        let working = calibration.to_page();
        let crc = crc32(&working);
        Self {
            working,
            working_calibration: calibration,
            reference: Calibration::DEFAULT.to_page(),
            ecu_page: Page::Working,
            startup,
            saved_crc: crc,
            active_crc: crc,
            changes: 0,
            refusals: 0,
            why: Detail::default(),
            xcp_connected: false,
            xcp_unlocked: false,
        }
    }

    /// The calibration the control step runs on now.
    pub fn active(&self) -> &Calibration {
        match self.ecu_page {
            Page::Working => &self.working_calibration,
            Page::Reference => &Calibration::DEFAULT,
        }
    }

    /// The bytes of `page`, as a calibration tool reads them.
    pub fn page(&self, page: Page) -> &[u8; PAGE_LEN] {
        match page {
            Page::Working => &self.working,
            Page::Reference => &self.reference,
        }
    }

    /// The page the control step runs on.
    pub fn ecu_page(&self) -> Page {
        self.ecu_page
    }

    /// What start-up loaded (or the last save made).
    pub fn startup(&self) -> Startup {
        self.startup
    }

    /// CRC-32 of the page the control step runs on (`CCM_CalChecksum`).
    pub fn checksum(&self) -> u32 {
        self.active_crc
    }

    /// Writes `data` at `offset` of the working page, as one transaction.
    pub fn write(
        &mut self,
        offset: usize,
        data: &[u8],
        state: VehicleState,
    ) -> Result<(), Refused> {
        let mut candidate = self.working;
        let Some(target) = candidate.get_mut(offset..offset.saturating_add(data.len())) else {
            return self.refuse(Refused::NotMapped, why::NOT_MAPPED);
        };
        target.copy_from_slice(data);
        self.commit(candidate, state)
    }

    /// Copies the reference page (the defaults) over the working page, as one transaction.
    pub fn revert_to_reference(&mut self, state: VehicleState) -> Result<(), Refused> {
        self.commit(self.reference, state)
    }

    /// Makes the control step run on `page`: allowed when every parameter that would change
    /// may change now.
    pub fn select(&mut self, page: Page, state: VehicleState) -> Result<(), Refused> {
        if page == self.ecu_page {
            return Ok(());
        }
        let (from, to) = (*self.page(self.ecu_page), *self.page(page));
        if let Err((index, change)) = allowed(&from, &to, state) {
            return self.refuse(Refused::NotNow, why::not_now(index, change));
        }
        self.ecu_page = page;
        self.active_crc = crc32(self.page(page));
        self.changes = self.changes.wrapping_add(1);
        Ok(())
    }

    /// The working page was saved to flash as `startup` says.
    pub fn saved(&mut self, startup: Startup) {
        self.startup = startup;
        self.saved_crc = crc32(&self.working);
    }

    /// The XCP slave's state, for `CCM_Calibration`.
    pub fn set_xcp(&mut self, connected: bool, unlocked: bool) {
        self.xcp_connected = connected;
        self.xcp_unlocked = unlocked;
    }

    /// `CCM_Calibration` as it stands.
    pub fn status(&self) -> CcmCalibration {
        CcmCalibration {
            ccm_cal_checksum: self.active_crc,
            ccm_cal_startup: CcmCalibrationCcmCalStartup::from_raw(self.startup.raw()),
            ccm_cal_page: CcmCalibrationCcmCalPage::from_raw(self.ecu_page.number()),
            ccm_cal_unsaved: crc32(&self.working) != self.saved_crc,
            ccm_xcp_connected: self.xcp_connected,
            ccm_xcp_unlocked: self.xcp_unlocked,
            ccm_cal_changes: self.changes,
            ccm_cal_refusals: self.refusals,
        }
    }

    fn commit(&mut self, candidate: [u8; PAGE_LEN], state: VehicleState) -> Result<(), Refused> {
        let calibration = match Calibration::from_page(&candidate) {
            Ok(calibration) => calibration,
            Err(error) => {
                return self.refuse(Refused::OutOfRange, why::limits(&error, &candidate));
            }
        };
        if let Err(error) = SensorCalibration::of(&calibration).check() {
            return self.refuse(Refused::OutOfRange, why::sensors(&error));
        }
        // Changing the working page changes the car only while the car runs on it.
        if self.ecu_page == Page::Working {
            if let Err((index, change)) = allowed(&self.working, &candidate, state) {
                return self.refuse(Refused::NotNow, why::not_now(index, change));
            }
        }
        if candidate != self.working {
            self.changes = self.changes.wrapping_add(1);
        }
        self.working = candidate;
        self.working_calibration = calibration;
        if self.ecu_page == Page::Working {
            self.active_crc = crc32(&candidate);
        }
        Ok(())
    }

    fn refuse(&mut self, refused: Refused, why: Detail) -> Result<(), Refused> {
        self.refusals = self.refusals.wrapping_add(1);
        self.why = why;
        Err(refused)
    }

    /// Why the last change was refused: the parameter, element, value and limit
    /// ([`why`]).
    pub fn last_refusal(&self) -> Detail {
        self.why
    }
}

/// Whether every parameter that differs between `from` and `to` may change in `state`; the
/// first that may not, by index, and its condition.
fn allowed(
    from: &[u8; PAGE_LEN],
    to: &[u8; PAGE_LEN],
    state: VehicleState,
) -> Result<(), (usize, ChangeWhen)> {
    for (index, parameter) in PARAMETERS.iter().enumerate() {
        let range = parameter.offset..parameter.offset + parameter.len();
        if from.get(range.clone()) != to.get(range) && !parameter.change.allows(state) {
            return Err((index, parameter.change));
        }
    }
    Ok(())
}
