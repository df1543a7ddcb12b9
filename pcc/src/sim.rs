//! A model of the precharge circuit for simulations: the tractive system's capacitance
//! charges through the precharge resistor (or directly through AIR+) and discharges through
//! the discharge resistor when the relays open. Used by the tests and the Cortex-M7 check.

use crate::relays::Relays;

/// The circuit's state and time constants.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PrechargePlant {
    /// Pack voltage (V).
    pub accumulator_v: f32,
    /// Tractive-system (DC link) voltage (V).
    pub tractive_v: f32,
    /// R x C through the precharge resistor (ms).
    pub precharge_tau_ms: f32,
    /// R x C through the discharge resistor (ms).
    pub discharge_tau_ms: f32,
}

impl PrechargePlant {
    /// Advances the circuit by `dt_ms` with `relays` applied. Backward Euler: stable for any
    /// step, and plain arithmetic, so host and Cortex-M7 compute the same bits.
    pub fn advance(&mut self, relays: Relays, dt_ms: f32) {
        let (target, tau) = if relays.air_minus && relays.air_plus {
            (self.accumulator_v, 0.0)
        } else if relays.air_minus && relays.precharge {
            (self.accumulator_v, self.precharge_tau_ms)
        } else {
            (0.0, self.discharge_tau_ms)
        };
        let factor = dt_ms / (tau + dt_ms);
        self.tractive_v += (target - self.tractive_v) * factor;
    }
}
