//! The relay outputs, derived from the state alone so no path can leave one closed by
//! accident.

use crate::state::State;

/// Commanded relay and shutdown-control outputs (`true` = energised / closed).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Relays {
    /// Accumulator isolation relay, positive side: bypasses the precharge resistor.
    pub air_plus: bool,
    /// Accumulator isolation relay, negative side.
    pub air_minus: bool,
    /// Precharge relay: feeds the tractive system through the precharge resistor.
    pub precharge: bool,
    /// Shutdown relay in position 1 (tractive system connected); released it sits in
    /// position 2, where the tractive system discharges.
    pub shutdown: bool,
}

impl Relays {
    /// Every relay open and the tractive system discharging: the state at reset, in ERROR,
    /// in DISCHARGE and in STANDBY.
    pub const ALL_OPEN: Self = Self {
        air_plus: false,
        air_minus: false,
        precharge: false,
        shutdown: false,
    };

    /// The outputs for `state`.
    pub const fn for_state(state: State) -> Self {
        match state {
            State::Standby | State::Discharge | State::Error => Self::ALL_OPEN,
            // AIR- and the precharge relay charge the tractive system through the resistor.
            State::Precharge => Self {
                air_plus: false,
                air_minus: true,
                precharge: true,
                shutdown: true,
            },
            // AIR+ bypasses the resistor; the precharge relay opens.
            State::Online | State::Charging => Self {
                air_plus: true,
                air_minus: true,
                precharge: false,
                shutdown: true,
            },
        }
    }

    /// True when nothing connects the accumulator to the tractive system.
    pub const fn all_open(&self) -> bool {
        !self.air_plus && !self.air_minus && !self.precharge && !self.shutdown
    }
}
