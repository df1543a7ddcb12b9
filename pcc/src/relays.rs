//! The PCC's one relay output, derived from the state alone so no path can leave it high by
//! accident.
//!
//! On the team's board the PCC switches one thing: the line that closes AIR+ (pin 11, "Close
//! AIR+" in the team's firmware). AIR- and the precharge relay are closed by the shutdown
//! circuit itself, so precharge starts in hardware when the shutdown circuit closes; the PCC
//! watches the tractive-system voltage rise and closes AIR+, bypassing the precharge resistor,
//! only once precharge is complete. Closing it any earlier bypasses the resistor at pack voltage.

use crate::state::State;
use aer_boards::Pin;
use aer_boards::pcc::Revision;

/// The commanded output (`true` = high = AIR+ closed).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Relays {
    /// Close AIR+ (pin 11): connects the pack to the tractive system without the precharge
    /// resistor. High only in ONLINE and CHARGING.
    pub air_plus: bool,
}

impl Relays {
    /// AIR+ open: the state at reset and in STANDBY, PRECHARGE, DISCHARGE and ERROR.
    pub const ALL_OPEN: Self = Self { air_plus: false };

    /// The output for `state`.
    pub const fn for_state(state: State) -> Self {
        Self {
            air_plus: matches!(state, State::Online | State::Charging),
        }
    }

    /// The level of every relay output of `board`: its pin and whether it is driven high.
    pub const fn outputs(&self, board: &Revision) -> [(Pin, bool); 1] {
        [(board.air_plus, self.air_plus)]
    }

    /// True when the PCC holds AIR+ open.
    pub const fn all_open(&self) -> bool {
        !self.air_plus
    }
}
