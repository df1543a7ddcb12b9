//! The accumulator: open-circuit voltage over SOC and an internal resistance, so the current
//! for a given power rises as the terminal voltage sags.

use crate::params::accumulator::{
    CAPACITY_AH, CELL_OCV, CELLS_IN_SERIES, HEATING_DEGC_PER_KJ, RESISTANCE_OHM,
};

/// The pack's state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pack {
    /// State of charge (0..1).
    pub soc: f32,
    /// Terminal voltage (V) under the present load.
    pub voltage_v: f32,
    /// Current (A, positive discharging).
    pub current_a: f32,
    /// Hottest cell temperature (degC).
    pub temperature_degc: f32,
}

impl Pack {
    /// A pack at rest at `soc`.
    pub fn new(soc: f32, temperature_degc: f32) -> Self {
        Self {
            soc,
            voltage_v: open_circuit_v(soc),
            current_a: 0.0,
            temperature_degc,
        }
    }

    /// Delivers `power_w` (battery terminals) for `dt_s`: solves for the current with the
    /// sagging terminal voltage, then discharges and warms the pack.
    pub fn deliver(&mut self, power_w: f32, dt_s: f32) {
        let ocv = open_circuit_v(self.soc);
        // P = (OCV - R I) I, by fixed-point iteration from I = P / OCV (R I is a few % of
        // OCV, so four rounds converge to well below a milliampere).
        let mut current = power_w / ocv;
        for _ in 0..4 {
            current = power_w / (ocv - RESISTANCE_OHM * current).max(1.0);
        }
        self.current_a = current;
        self.voltage_v = ocv - RESISTANCE_OHM * current;
        self.soc = (self.soc - current * dt_s / (CAPACITY_AH * 3_600.0)).clamp(0.0, 1.0);
        let loss_kj = current * current * RESISTANCE_OHM * dt_s / 1_000.0;
        self.temperature_degc += loss_kj * HEATING_DEGC_PER_KJ;
    }

    /// Average cell voltage (V) under load.
    pub fn cell_v(&self) -> f32 {
        self.voltage_v / CELLS_IN_SERIES
    }
}

/// Pack open-circuit voltage (V) at `soc`, interpolated in the cell table.
pub fn open_circuit_v(soc: f32) -> f32 {
    let soc = soc.clamp(0.0, 1.0);
    let mut cell = CELL_OCV[0].1;
    for pair in CELL_OCV.windows(2) {
        let [(soc0, v0), (soc1, v1)] = [pair[0], pair[1]];
        if soc >= soc0 {
            cell = v0 + (v1 - v0) * ((soc - soc0) / (soc1 - soc0)).min(1.0);
        }
    }
    cell * CELLS_IN_SERIES
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn voltage_sags_and_current_rises_under_load() {
        let mut pack = Pack::new(0.8, 30.0);
        let rest = pack.voltage_v;
        pack.deliver(80_000.0, 0.001);
        assert!(pack.voltage_v < rest - 20.0, "{pack:?}");
        let power = pack.voltage_v * pack.current_a;
        assert!((power - 80_000.0).abs() < 1.0, "{power}");
        assert!(pack.current_a > 80_000.0 / rest);
    }

    #[test]
    fn open_circuit_voltage_follows_the_table() {
        assert!((open_circuit_v(0.5) - 3.7 * 96.0).abs() < 1e-3);
        assert!((open_circuit_v(0.65) - 3.825 * 96.0).abs() < 1e-2);
        assert!((open_circuit_v(1.5) - 4.15 * 96.0).abs() < 1e-3);
    }
}
