//! The precharge circuit's constants, in one place.
//!
//! Values from the team's documentation (vehicle-facts.md, the seed's PCC pages). Timing
//! limits are for the current accumulator and tractive-system capacitance; they change with
//! the precharge resistor, so they live in a struct the firmware builds once.

/// Period of the control task and of the status frame, in milliseconds.
pub const TASK_PERIOD_MS: u32 = 10;

/// Everything the precharge state machine compares against.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PrechargeConfig {
    /// Progress (tractive-system voltage as % of the accumulator's) that ends precharge.
    pub target_percent: f32,
    /// Reaching the target sooner than this after precharge started means a short or a wrong
    /// measurement.
    pub min_time_ms: u32,
    /// Not reaching the target within this time means a wiring fault, a stuck discharge or a
    /// target set too high.
    pub max_time_ms: u32,
    /// Progress must stay at or above the target this long before it counts (filters a noisy
    /// sample).
    pub target_hold_ms: u32,
    /// Below this accumulator voltage the measurement cannot vouch for a pack: no precharge,
    /// and an energised tractive system is discharged.
    pub min_accumulator_v: f32,
    /// In ERROR, a shutdown-only error clears once the tractive system has been discharged
    /// for this long.
    pub standby_settle_ms: u32,
    /// A BMS frame older than this is a CAN timeout.
    pub bms_timeout_ms: u32,
    /// Tractive-system voltage below which it counts as discharged (60 V DC: the rules'
    /// limit for low voltage).
    pub discharged_v: f32,
    /// A rise in progress (above the lowest seen in STANDBY) that shows the hardware has
    /// started precharging (the shutdown circuit closed AIR- and the precharge relay); the
    /// precharge timer starts when it is seen. 2 points are reached 0.02 time constants
    /// (80 ms on the car) after the start: the measured precharge is that much shorter than
    /// the true one, well inside the 8.2-9.2 s window; 8 V at 400 V is far above the
    /// converters' noise.
    pub start_percent: f32,
    /// A precharge is timed only from a tractive system at rest: progress below this, seen
    /// with the pack read and the BMS heard, before the rise. A rise from higher (a
    /// precharge that began while the PCC could not start, the shutdown circuit closed again
    /// before the tractive system had discharged) would be timed short and judged wrong.
    /// 5 % of the pack shortens a true precharge by 0.05 time constants (200 ms on the car)
    /// at most.
    pub rest_percent: f32,
    /// In PRECHARGE, progress this far below its highest value means the precharge path
    /// opened (the shutdown circuit) or the tractive system is loaded down.
    pub precharge_drop_percent: f32,
    /// In ONLINE and CHARGING, progress below this means the tractive system is no longer
    /// connected to the pack (the shutdown circuit opened) or is shorted: AIR+ is released.
    pub online_min_percent: f32,
}

impl PrechargeConfig {
    /// The car's values: 90 % target reached between 8.2 s and 9.2 s, BMS timeout 1.5 s.
    pub const CAR: Self = Self {
        target_percent: 90.0,
        min_time_ms: 8_200,
        max_time_ms: 9_200,
        target_hold_ms: 20,
        min_accumulator_v: 60.0,
        standby_settle_ms: 200,
        bms_timeout_ms: 1_500,
        discharged_v: 60.0,
        start_percent: 2.0,
        rest_percent: 5.0,
        precharge_drop_percent: 10.0,
        online_min_percent: 80.0,
    };
}

impl Default for PrechargeConfig {
    fn default() -> Self {
        Self::CAR
    }
}

/// The voltage-to-frequency measurement chain: HV divider, then an LM331 converter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VfConfig {
    /// Converter volts per hertz of output (set by its timing resistor and capacitor).
    pub volts_per_hz: f32,
    /// HV divider ratio (input volts per converter volt): (R1 + R2) / R2.
    pub divider_ratio: f32,
    /// Low-pass cut-off applied to the measured voltage, in Hz.
    pub cutoff_hz: f32,
    /// No edge for this long means the input is at (or near) 0 V.
    pub edge_timeout_us: u32,
}

/// Each converter's scaling, as the bench day's step 6b measures it: index 0 the accumulator
/// (pin 14), 1 the tractive system (pin 15). The two are judged against each other (precharge
/// progress is their ratio), so each has its own; both are the parts list's until measured.
pub const CONVERTERS: [VfConfig; 2] = [VfConfig::PCC_BOARD, VfConfig::PCC_BOARD];

impl VfConfig {
    /// The PCC board: 0.001275 V/Hz, divider 5 x 510 kOhm over 39 kOhm, 10 Hz cut-off
    /// (a 16 ms time constant: smooths the 10 ms windows without hiding a precharge that is
    /// several seconds long).
    pub const PCC_BOARD: Self = Self {
        volts_per_hz: 0.001_275,
        divider_ratio: (5.0 * 510_000.0 + 39_000.0) / 39_000.0,
        cutoff_hz: 10.0,
        edge_timeout_us: 100_000,
    };

    /// Volts at the high-voltage input that make the converter pulse at `hz`.
    pub fn volts_for_hz(&self, hz: f32) -> f32 {
        hz * self.volts_per_hz * self.divider_ratio
    }

    /// The pulse frequency that `volts` at the high-voltage input produces (for simulations,
    /// tests and a signal generator on the bench).
    pub fn hz_for_volts(&self, volts: f32) -> f32 {
        volts / (self.volts_per_hz * self.divider_ratio)
    }
}
