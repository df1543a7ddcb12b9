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
    /// In ONLINE and CHARGING, progress below this in [`Self::online_drop_periods`] windows in
    /// a row (each window's own, unfiltered reading) means the tractive system is no longer
    /// connected to the pack (the shutdown circuit opened) or is shorted: AIR+ is released.
    /// With AIR+ closed the two converters read the same voltage but for the contacts' drop
    /// and the converters' disagreement (6c allows 1 %), so 95 % is far from a healthy
    /// reading, and a shutdown circuit that opens and closes again within the detection time
    /// finds the tractive system still above 90 % (as a precharge would) on the car's
    /// discharge circuit.
    pub online_min_percent: f32,
    /// Windows in a row below [`Self::online_min_percent`] that count (one stray window is
    /// noise on a converter's line).
    pub online_drop_periods: u32,
    /// After ONLINE or CHARGING is entered, AIR+ must bring the tractive system to
    /// [`Self::online_min_percent`] within this (ms), or `air-plus-open` latches. The online
    /// minimum is watched from the first window that reaches it: AIR+ takes 20-30 ms to
    /// close on the car, the bench's linear sweep about half a second from 90 % (6d). Until
    /// then a fall from the peak, as in PRECHARGE, still opens AIR+.
    pub air_plus_close_ms: u32,
    /// ONLINE and CHARGING follow the BMS's charger-safety bit once it has held a new value
    /// this long (ms): a bit that flickers (a garbled frame, a mis-mapped byte) switches
    /// nothing.
    pub charger_debounce_ms: u32,
    /// While energised, the unfiltered progress above this in
    /// [`Self::online_drop_periods`] windows in a row latches `converters-disagree`: no
    /// circuit puts the tractive system above the pack, and with AIR+ closed both converters
    /// read one node (6c and 8.1 let them disagree by 1 %, and a window's reading is robust to
    /// a stray edge), so a reading this high is a converter's scaling or divider gone wrong,
    /// which would also move every other judgement (a precharge judged at the wrong point).
    pub max_progress_percent: f32,
    /// In STANDBY (from rest) and PRECHARGE, progress rising this many points within one
    /// window is no precharge through the resistor (the car's rises at most a few tenths of a
    /// point per 10 ms): AIR+ is welded or the resistor bypassed, latched at once.
    pub bypass_rise_percent: f32,
    /// Once the tractive system has begun to fall after the AIRs opened, it must read below
    /// [`Self::discharged_v`] within this time (ms), or the PCC latches `no-discharge` (an AIR
    /// welded or the discharge circuit failed). The FSAE EV rules' discharge requirement:
    /// below 60 V DC within 5 s of the shutdown circuit opening.
    pub discharge_time_ms: u32,
    /// A precharge that reaches the target sooner than this after the rise did not go through
    /// the precharge resistor: AIR+ is welded or the resistor is bypassed. Through any
    /// resistor the board could carry the rise takes seconds; a bypassed one reaches the pack
    /// in one or two control periods plus the 16 ms measurement filter.
    pub bypass_max_ms: u32,
    /// The precharge resistor's temperature limit (degC): either thermistor at or above it
    /// latches `resistor-hot`.
    pub resistor_limit_c: f32,
}

impl PrechargeConfig {
    /// The car's values: 90 % target reached between 8.2 s and 9.2 s, BMS timeout 1.5 s.
    pub const CAR: Self = Self {
        target_percent: aer_params::PRECHARGE_TARGET_PERCENT,
        min_time_ms: 8_200,
        max_time_ms: 9_200,
        target_hold_ms: 20,
        min_accumulator_v: 60.0,
        standby_settle_ms: 200,
        bms_timeout_ms: 1_500,
        discharged_v: aer_params::TRACTIVE_LOW_VOLTAGE_V,
        start_percent: 2.0,
        rest_percent: 5.0,
        precharge_drop_percent: 10.0,
        online_min_percent: 95.0,
        online_drop_periods: 2,
        air_plus_close_ms: 1_000,
        charger_debounce_ms: 100,
        max_progress_percent: 102.0,
        bypass_rise_percent: 20.0,
        discharge_time_ms: 5_000,
        bypass_max_ms: 500,
        resistor_limit_c: THERMISTORS.limit_c,
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

/// The precharge resistor's two thermistors (pins 21 and 22, A7 and A8): NTC parts on the low
/// side of a divider whose high side goes to 3.3 V, read by the on-chip ADC (12 bits).
///
/// Every figure is the team's (embedded-mz@0c18690 fsae-pcc/src/precharge.cpp:19-27: 10 kOhm at
/// 25 degC, beta 3880, a 6.8 kOhm divider resistor, a 69 degC threshold); the parts and the
/// limit are assumed until the bench day checks them (docs/bench-day.md, 6a).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ThermistorConfig {
    /// Resistance at `t0_c` (Ohm).
    pub r0_ohm: f32,
    /// The reference temperature (degC).
    pub t0_c: f32,
    /// The beta constant (K).
    pub beta_k: f32,
    /// The divider's resistor between the pin and 3.3 V (Ohm).
    pub divider_ohm: f32,
    /// Full scale of the ADC (counts).
    pub full_scale: u16,
    /// Below this temperature (degC) a reading is not a resistor on a car but an open or
    /// unplugged thermistor (the pin pulled to 3.3 V): no reading.
    pub open_below_c: f32,
    /// The resistor's limit (degC).
    pub limit_c: f32,
}

/// The PCC board's thermistors.
pub const THERMISTORS: ThermistorConfig = ThermistorConfig {
    r0_ohm: 10_000.0,
    t0_c: 25.0,
    beta_k: 3_880.0,
    divider_ohm: 6_800.0,
    full_scale: 4_095,
    open_below_c: -30.0,
    limit_c: 69.0,
};

impl ThermistorConfig {
    /// The temperature (degC) that `counts` mean, or `None` for an open or unplugged
    /// thermistor (a reading colder than [`Self::open_below_c`], the pin at the rail). A
    /// shorted thermistor reads hotter than any limit, which fails safe.
    pub fn temperature_c(&self, counts: u16) -> Option<f32> {
        let full = f32::from(self.full_scale);
        let counts = f32::from(counts.min(self.full_scale));
        if counts >= full {
            return None;
        }
        // The thermistor is the low side: counts / full = R / (R + divider).
        let resistance = self.divider_ohm * counts / (full - counts);
        if resistance <= 0.0 {
            return Some(f32::MAX);
        }
        let kelvin0 = self.t0_c + 273.15;
        let inverse = 1.0 / kelvin0 + libm::logf(resistance / self.r0_ohm) / self.beta_k;
        let celsius = 1.0 / inverse - 273.15;
        if !celsius.is_finite() || celsius < self.open_below_c {
            None
        } else {
            Some(celsius)
        }
    }

    /// The counts a thermistor at `celsius` gives (for simulations and tests).
    pub fn counts_for(&self, celsius: f32) -> u16 {
        let kelvin0 = self.t0_c + 273.15;
        let resistance =
            self.r0_ohm * libm::expf(self.beta_k * (1.0 / (celsius + 273.15) - 1.0 / kelvin0));
        let full = f32::from(self.full_scale);
        let counts = full * resistance / (resistance + self.divider_ohm);
        libm::roundf(counts).clamp(0.0, full) as u16
    }
}
