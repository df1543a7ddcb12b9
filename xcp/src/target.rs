//! What the slave needs from the ECU it runs in. The protocol core never touches memory: every
//! byte it reads or writes goes through [`Target`], which maps XCP addresses onto the ECU's own
//! tables (the calibration page, the measurement snapshot, the EPK) and refuses everything
//! else. So the wire can reach no memory the ECU did not choose to expose.

use crate::protocol::err;
use crate::refusal::Detail;

/// Length of the seed [`Target::seed`] produces: it fits one classic CAN response
/// (PID, length, seed).
pub const SEED_LEN: usize = 6;

/// Longest key accepted by UNLOCK, sent over several UNLOCK commands of up to six bytes.
pub const KEY_MAX: usize = 32;

/// Why the target refused an access; the slave answers the matching XCP error code.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refusal {
    /// The address range is not in the target's map: ERR_ACCESS_DENIED (0x24).
    NotMapped,
    /// The resulting values violate a limit or cross-check: ERR_OUT_OF_RANGE (0x22).
    OutOfRange,
    /// Writing is not allowed (read-only memory, or not in the vehicle's current state):
    /// ERR_WRITE_PROTECTED (0x23), which pyxcp reports to the user instead of retrying.
    WriteProtected,
    /// No such calibration page: ERR_PAGE_NOT_VALID (0x26).
    PageNotValid,
    /// The page switch is not possible in this mode: ERR_MODE_NOT_VALID (0x27).
    ModeNotValid,
    /// The target failed otherwise (e.g. storage): ERR_GENERIC (0x31).
    Failed,
}

impl Refusal {
    /// The XCP error code the slave answers for this refusal.
    pub const fn code(self) -> u8 {
        match self {
            Refusal::NotMapped => err::ACCESS_DENIED,
            Refusal::OutOfRange => err::OUT_OF_RANGE,
            Refusal::WriteProtected => err::WRITE_PROTECTED,
            Refusal::PageNotValid => err::PAGE_NOT_VALID,
            Refusal::ModeNotValid => err::MODE_NOT_VALID,
            Refusal::Failed => err::GENERIC,
        }
    }
}

/// The ECU side of the slave: memory map, calibration pages and seed and key.
///
/// Page numbers: 0 is the working page (read-write), 1 the reference page (read-only
/// defaults); the calibration lives in segment 0.
pub trait Target {
    /// The EPK (ASCII): answered to GET_ID type 5 (read by UPLOAD), and the value an A2L's
    /// `EPK` names, so a tool can check it has the right description of this software.
    fn epk(&self) -> &[u8];

    /// Reads `out.len()` bytes at an XCP address (with its extension) as seen on the given
    /// calibration page (addresses outside the calibration segment ignore the page). `Err`
    /// for any byte outside the map: the slave never sees memory the target does not expose.
    fn read(&self, page: u8, ext: u8, address: u32, out: &mut [u8]) -> Result<(), Refusal>;

    /// Writes bytes to the working page as one transaction: the target validates the whole
    /// resulting page (limits, cross-checks, whether the change is allowed in the vehicle's
    /// current state) and applies all of it or nothing.
    fn write(&mut self, ext: u8, address: u32, data: &[u8]) -> Result<(), Refusal>;

    /// The page the ECU's application currently runs on.
    fn ecu_page(&self) -> u8;

    /// Switches the ECU's application to another page; the target may refuse (e.g. while the
    /// car is moving).
    fn set_ecu_page(&mut self, page: u8) -> Result<(), Refusal>;

    /// Copies page `from` onto page `to` as one transaction (copying the reference page onto
    /// the working page restores the defaults); validated like [`Target::write`].
    fn copy_page(&mut self, from: u8, to: u8) -> Result<(), Refusal>;

    /// Fills `out` with a fresh, unpredictable seed for unlocking calibration; `now_us` is the
    /// request's time, which a generator may mix in ([`crate::seeds::SeedGenerator::fill`]).
    fn seed(&mut self, now_us: u32, out: &mut [u8; SEED_LEN]);

    /// Whether `key` is the right answer to `seed`: the key algorithm lives in the target.
    fn key_is_valid(&self, seed: &[u8], key: &[u8]) -> bool;

    /// SET_REQUEST STORE_CAL_REQ: asks the target to persist the working page when it safely
    /// can (e.g. at standstill). The default refuses: no non-volatile storage.
    fn request_store(&mut self) -> Result<(), Refusal> {
        Err(Refusal::OutOfRange)
    }

    /// Whether a requested store has not completed yet (GET_STATUS's STORE_CAL_REQ bit).
    fn store_pending(&self) -> bool {
        false
    }

    /// Why the target's last refusal happened, in the numbers the ECU's description names
    /// ([`crate::reason`]); asked right after a refusal, for the slave's last refusal.
    fn explain(&self) -> Detail {
        Detail::default()
    }
}
