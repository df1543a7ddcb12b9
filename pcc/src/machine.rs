//! The precharge state machine.
//!
//! ```text
//!            pack >= min, BMS alive, and the tractive system rising
//!  STANDBY ------------------------------------------------------> PRECHARGE
//!     ^                                                             |  |  |
//!     | TS < 60 V                      target held, after min time |  |  | too fast / too slow /
//!     |                                                             v  |  | TS falls away / BMS timeout
//!  DISCHARGE <-- pack lost --  ONLINE <-- charger safety off --  CHARGING |
//!                               (and PRECHARGE, CHARGING)                 v
//!                                                                       ERROR
//! ```
//! On the team's board the shutdown circuit closes AIR- and the precharge relay itself, and the
//! PCC has no input that reads it: precharge starts in hardware, and the PCC sees it as the
//! tractive-system voltage rising. The only output is AIR+ ([`Relays`]), high in ONLINE and
//! CHARGING alone. A shutdown circuit that opens shows as the tractive system falling away from
//! the pack (AIR- and the precharge relay drop out): that is an error, so AIR+ is released
//! before the shutdown circuit can close again and start a new precharge, which a still-high
//! AIR+ would bypass.
//!
//! ERROR holds AIR+ open. Its precharge-timing and BMS-timeout causes latch until the PCC is
//! reset (power cycle after the cause is found); a shutdown-only error clears once the
//! tractive system has been below 60 V for the settle time, so switching the car off with the
//! shutdown circuit needs no power cycle.
//!
//! What the hardware can lie about, the PCC checks from what it can see:
//! - **A silent converter is unknown, not 0 V.** An LM331 gives no pulses at 0 V, and none
//!   with a broken wire. A converter that falls silent after reading 60 V or more, or while
//!   the PCC is in PRECHARGE, ONLINE, CHARGING or DISCHARGE, latches a fault of its own in any
//!   state; `bootloader` and `restart` are refused until both converters give pulses below
//!   60 V again, and only a power cycle clears it.
//! - **The tractive system must discharge.** Once it has begun to fall after the AIRs opened,
//!   it must read below 60 V within the discharge time (5 s, the rules'), or `no-discharge`
//!   latches: an AIR welded or the discharge circuit failed. The timer starts at the fall,
//!   not when AIR+ opens: with the shutdown circuit still closed (a BMS timeout, say) the
//!   tractive system stays charged through the precharge resistor, rightly.
//! - **A precharge faster than the resistor allows** (under [`PrechargeConfig::bypass_max_ms`])
//!   latches `too-fast` with `bypassed`: AIR+ welded or the precharge resistor bypassed. So
//!   does a rise no resistor allows within one control period
//!   ([`PrechargeConfig::bypass_rise_percent`] of the accumulator's voltage, on the unfiltered
//!   readings), in PRECHARGE or in STANDBY once the tractive system was seen at rest: a
//!   welded AIR+ under a shutdown contact that closes for a few milliseconds is named too.
//! - **ONLINE and CHARGING hold only on the unfiltered readings**: the tractive system below
//!   [`PrechargeConfig::online_min_percent`] of the accumulator for
//!   [`PrechargeConfig::online_drop_periods`] periods in a row leaves them, so a contact that
//!   opens is seen in 20 ms, not after the filter has followed it.
//! - **The precharge resistor's temperature**: either thermistor at its limit latches
//!   `resistor-hot`. A thermistor with no reading (open, unplugged) is unknown: it latches
//!   nothing, and the console says the protection is off.
//!
//! What it cannot see: a single welded AIR with the other one open (the tractive system then
//! discharges as it should). The bench-day sheet's weld check before every re-closure covers it.
//!
//! Time is a free-running millisecond counter that may wrap; every comparison is on
//! differences, so a wrap (after 49.7 days) changes nothing.

use crate::constants::{PrechargeConfig, TASK_PERIOD_MS};
use crate::measurement::Pulses;
use crate::relays::Relays;
use crate::state::{Errors, State};
use aer_control::Persist;

/// What the control task measured this period.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Inputs {
    /// Free-running milliseconds.
    pub now_ms: u32,
    /// Filtered accumulator voltage (V; 0 while its converter is silent).
    pub accumulator_v: f32,
    /// Filtered tractive-system voltage (V; 0 while its converter is silent).
    pub tractive_v: f32,
    /// The same two over this period's window alone, unfiltered (V): accumulator, tractive
    /// system. The fast checks judge these (the tractive system falling away while ONLINE, a
    /// rise no resistor allows).
    pub raw_v: [f32; 2],
    /// Whether each converter gives pulses: the accumulator's (pin 14), the tractive
    /// system's (pin 15).
    pub pulses: [Pulses; 2],
    /// When the last BMS frame arrived (`None` before the first).
    pub bms_last_seen_ms: Option<u32>,
    /// The BMS reports its charger-safety output on.
    pub charger_safety: bool,
    /// The precharge resistor's temperature at each thermistor (degC); `None`: no reading.
    pub resistor_c: [Option<f32>; 2],
}

/// One of the two V/F converters.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Converter {
    /// The accumulator's (pin 14).
    Accumulator,
    /// The tractive system's (pin 15).
    Tractive,
}

impl Converter {
    /// Both, in the order of [`Inputs::pulses`].
    pub const BOTH: [Self; 2] = [Self::Accumulator, Self::Tractive];

    /// As the console names it.
    pub const fn name(self) -> &'static str {
        match self {
            Self::Accumulator => "accumulator converter (pin 14)",
            Self::Tractive => "tractive-system converter (pin 15)",
        }
    }
}

/// A converter's latched silence.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Silence {
    /// Which one.
    pub converter: Converter,
    /// What it last measured before its pulses stopped (V).
    pub last_v: f32,
    /// When its last pulse came (ms, the PCC's clock).
    pub since_ms: u32,
}

/// What latched `no-discharge`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoDischarge {
    /// The tractive system's reading when the discharge time ran out (V).
    pub tractive_v: f32,
    /// When it began to fall (ms).
    pub falling_since_ms: u32,
    /// The discharge time it had (ms).
    pub limit_ms: u32,
}

/// What latched `resistor-hot`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HotResistor {
    /// Which thermistor (1 or 2, pins 21 and 22).
    pub thermistor: u8,
    /// What it read (degC).
    pub celsius: f32,
    /// The limit (degC).
    pub limit_c: f32,
}

/// A rise no precharge through the resistor makes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BypassRise {
    /// Progress before the step (% of the pack).
    pub from_percent: f32,
    /// Progress after it.
    pub to_percent: f32,
}

/// A discharge being watched in ERROR or DISCHARGE, after an energised state.
#[derive(Debug, Clone, Copy, PartialEq)]
struct DischargeWatch {
    /// The highest tractive-system reading since.
    peak_v: f32,
    /// When it first dipped below the peak (by [`DISCHARGE_DIP`]): where a fall that goes on
    /// began.
    dip_since_ms: Option<u32>,
    /// When it began to fall (the rules' 5 s count from here): the dip's start, once the fall
    /// reached the precharge drop.
    falling_since_ms: Option<u32>,
    /// The lowest reading since the fall began.
    low_v: f32,
}

/// A reading this far below the peak (as a fraction) starts a dip: a fall that goes on to the
/// precharge drop is timed from it, so a slow discharge is judged from its start.
const DISCHARGE_DIP: f32 = 0.01;
/// While AIR+ closes after ONLINE, one window this many points of progress below the highest
/// since is the tractive system falling away: a window's own reading holds to a tenth of a
/// point on a regular train, and the precharge through the resistor only rises.
const ONLINE_CLOSING_DROP: f32 = 2.0;
/// A tractive system that rose this far (as a fraction of the peak) back above its low since
/// the fall began is charged again through the closed shutdown circuit (the circuit bounced,
/// rightly): the watch starts over from there.
const DISCHARGE_RISE: f32 = 0.05;

/// The precharge controller.
#[derive(Debug, Clone, PartialEq)]
pub struct Precharge {
    config: PrechargeConfig,
    state: State,
    errors: Errors,
    /// When the current state was entered.
    entered_ms: u32,
    /// How long the standby conditions (or, in ERROR, the recovery conditions) have held.
    conditions: Persist,
    /// Since when progress has been at or above the target during this precharge.
    at_target_since_ms: Option<u32>,
    /// The highest progress seen during this precharge (%).
    peak_percent: f32,
    /// The lowest progress seen during this STANDBY since the rest was seen (%): precharge
    /// has started once progress rises above it, so a tractive system still discharging is
    /// not taken for one charging.
    trough_percent: f32,
    /// In STANDBY, the tractive system has been seen at rest (below the rest percentage)
    /// with the PCC ready (the pack read, the BMS heard) since: only then is a rise timed.
    rest_seen: bool,
    /// Since when the tractive system has been falling away while energised.
    falling_since_ms: Option<u32>,
    progress_percent: f32,
    accumulator_v: f32,
    tractive_v: f32,
    /// How the last precharge ended.
    last_precharge: Option<PrechargeTiming>,
    /// In STANDBY, what the last step was still waiting for.
    waiting: Option<Waiting>,
    /// Each converter as last read.
    pulses: [Pulses; 2],
    /// Each converter's latched silence.
    silences: [Option<Silence>; 2],
    /// The discharge watched after AIR+ opened.
    discharge: Option<DischargeWatch>,
    /// What latched `no-discharge`.
    no_discharge: Option<NoDischarge>,
    /// The resistor's temperatures as last read (degC).
    resistor_c: [Option<f32>; 2],
    /// What latched `resistor-hot`.
    hot: Option<HotResistor>,
    /// This period's progress from the unfiltered readings (%).
    raw_progress: f32,
    /// The last period's and when, while a rise is watched (STANDBY from rest, PRECHARGE).
    last_raw_progress: Option<(f32, u32)>,
    /// Windows in a row below the online minimum (ONLINE, CHARGING).
    online_low: u32,
    /// The tractive system reached the online minimum since ONLINE or CHARGING was entered
    /// (AIR+ closed): from then on it must stay there.
    online_reached: bool,
    /// Since when the BMS's charger-safety bit has asked for the other of ONLINE and CHARGING.
    charger_change_since: Option<u32>,
    /// Windows in a row above the maximum progress (energised).
    progress_high: u32,
    /// The highest unfiltered progress since ONLINE or CHARGING was entered, while AIR+ closes.
    raw_peak_percent: f32,
    /// What latched `bypassed` by the rate of rise.
    bypass: Option<BypassRise>,
}

/// What STANDBY waits for before precharge starts: each `true` is a condition not met yet.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Waiting {
    /// The accumulator reads below the pack minimum (60 V).
    pub pack: bool,
    /// No BMS frame within its timeout.
    pub bms: bool,
    /// The tractive system does not rise (the shutdown circuit has not closed).
    pub rise: bool,
    /// The tractive system is not at rest (above [`PrechargeConfig::rest_percent`] of the
    /// pack, or at the discharged limit, 60 V, or more): a precharge began that the PCC could
    /// not time (no pack reading, no BMS, the shutdown circuit closed before start-up or
    /// again before the tractive system had discharged). It never counts: the shutdown
    /// circuit must stay open until the tractive system is at rest.
    pub discharge: bool,
    /// Of those, the tractive system reads the discharged limit (60 V) or more: treat it as
    /// live.
    pub live: bool,
    /// Neither precharge-resistor thermistor gives a reading: a precharge would heat the
    /// resistor unwatched, so none is timed (one is enough).
    pub resistor: bool,
}

/// How long a precharge took, against the window it must fall in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PrechargeTiming {
    /// Which precharge since start-up (1 for the first).
    pub attempt: u32,
    /// When the target was first reached after the rise (ms); `None` when it was not
    /// reached within the window's end.
    pub reached_ms: Option<u32>,
    /// The target (% of the accumulator).
    pub target_percent: u8,
    /// The window (ms).
    pub window_ms: (u32, u32),
    /// Faster than this (ms) the rise did not go through the precharge resistor.
    pub bypass_max_ms: u32,
}

impl core::fmt::Display for PrechargeTiming {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let (min, max) = self.window_ms;
        match self.reached_ms {
            Some(ms) => write!(
                f,
                "precharge {}: {} % reached {ms} ms after the rise (window {min}-{max} ms){}",
                self.attempt,
                self.target_percent,
                if ms < self.bypass_max_ms {
                    ", TOO FAST: faster than any precharge through the resistor: AIR+ welded or the precharge resistor bypassed (open the shutdown circuit; the weld check before any re-closure)"
                } else if ms < min {
                    ", TOO FAST"
                } else if ms > max {
                    ", TOO SLOW"
                } else {
                    ""
                }
            ),
            None => write!(
                f,
                "precharge {}: {} % NOT reached within {max} ms of the rise (window {min}-{max} ms)",
                self.attempt, self.target_percent
            ),
        }
    }
}

/// Why the PCC keeps running instead of handing the chip to the bootloader.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum HandoverRefusal {
    /// In a state where AIR+ may be closed or the tractive system is live.
    Energised(State),
    /// The tractive system is not yet below the discharged limit.
    Charged {
        /// What it reads (V).
        tractive_v: f32,
        /// The limit (V).
        limit_v: f32,
    },
    /// `restart` only: `bypassed` or `no-discharge` is latched (an AIR or the discharge circuit
    /// failed), which only a power cycle clears.
    PowerCycle,
    /// A converter fell silent at high voltage, and this one does not yet show it is alive
    /// below the discharged limit.
    ConverterFault {
        /// The converter.
        converter: Converter,
        /// What it reads now (V); `None`: no pulses.
        reading: Option<f32>,
        /// The limit (V).
        limit_v: f32,
    },
}

impl core::fmt::Display for HandoverRefusal {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Energised(state) => write!(
                f,
                "the PCC is in {state:?}: open the shutdown circuit, wait for Standby with the tractive system discharged, then ask again"
            ),
            Self::Charged {
                tractive_v,
                limit_v,
            } => write!(
                f,
                "the tractive system reads {tractive_v:.1} V: open the shutdown circuit, wait until it is below {limit_v:.0} V, then ask again"
            ),
            Self::PowerCycle => f.write_str(
                "`bypassed` or `no-discharge` is latched: an AIR or the discharge circuit failed; nothing closes again until the electrical lead has found it, then power-cycle the PCC (LV off, USB out) with the shutdown circuit open",
            ),
            Self::ConverterFault {
                converter,
                reading,
                limit_v,
            } => {
                write!(
                    f,
                    "a converter fell silent at high voltage, and the {} ",
                    converter.name()
                )?;
                match reading {
                    Some(volts) => write!(f, "reads {volts:.1} V")?,
                    None => f.write_str("gives no pulses")?,
                }
                write!(
                    f,
                    ": treat the tractive system as live (the ESO measures at the TSMP); the PCC hands over only once both converters give pulses below {limit_v:.0} V (the bench supply on both sense inputs, step 6c), or power-cycle it (LV off, USB out) with the shutdown circuit open"
                )
            }
        }
    }
}

impl Precharge {
    /// A controller in STANDBY with every relay open, as at reset.
    pub fn new(config: PrechargeConfig, now_ms: u32) -> Self {
        Self {
            config,
            state: State::Standby,
            errors: Errors::default(),
            entered_ms: now_ms,
            conditions: Persist::default(),
            at_target_since_ms: None,
            peak_percent: 0.0,
            trough_percent: f32::MAX,
            rest_seen: false,
            falling_since_ms: None,
            progress_percent: 0.0,
            accumulator_v: 0.0,
            tractive_v: 0.0,
            last_precharge: None,
            waiting: None,
            pulses: [Pulses::Live; 2],
            silences: [None; 2],
            discharge: None,
            no_discharge: None,
            resistor_c: [None; 2],
            hot: None,
            raw_progress: 0.0,
            last_raw_progress: None,
            online_low: 0,
            online_reached: false,
            charger_change_since: None,
            progress_high: 0,
            raw_peak_percent: 0.0,
            bypass: None,
        }
    }

    /// A controller that restarted because its watchdog expired: it cannot know what state
    /// it was in (it hung or panicked there), so it starts in ERROR with every relay open
    /// and the "undefined state" cause latched until the PCC is power-cycled.
    pub fn after_watchdog_reset(config: PrechargeConfig, now_ms: u32) -> Self {
        let mut pcc = Self::new(config, now_ms);
        pcc.errors.undefined_state = true;
        pcc.state = State::Error;
        pcc
    }

    /// Current state.
    pub fn state(&self) -> State {
        self.state
    }

    /// Latched error causes.
    pub fn errors(&self) -> Errors {
        self.errors
    }

    /// Tractive-system voltage as % of the accumulator's, as last computed.
    pub fn progress_percent(&self) -> f32 {
        self.progress_percent
    }

    /// Accumulator voltage as last measured (V, never negative or NaN).
    pub fn accumulator_v(&self) -> f32 {
        self.accumulator_v
    }

    /// Tractive-system voltage as last measured (V, never negative or NaN).
    pub fn tractive_v(&self) -> f32 {
        self.tractive_v
    }

    /// How the last precharge ended (`None` before the first).
    pub fn last_precharge(&self) -> Option<PrechargeTiming> {
        self.last_precharge
    }

    /// The limits it runs with.
    pub fn config(&self) -> &PrechargeConfig {
        &self.config
    }

    /// In STANDBY, what precharge still waits for; `None` in any other state.
    pub fn waiting(&self) -> Option<Waiting> {
        self.waiting
    }

    /// Each converter as last read: the accumulator's, the tractive system's.
    pub fn pulses(&self) -> [Pulses; 2] {
        self.pulses
    }

    /// Each converter's latched silence, in the same order.
    pub fn silences(&self) -> [Option<Silence>; 2] {
        self.silences
    }

    /// What latched `no-discharge`, if it is latched.
    pub fn no_discharge(&self) -> Option<NoDischarge> {
        self.no_discharge
    }

    /// The precharge resistor's temperatures as last read (degC; `None`: no reading).
    pub fn resistor_c(&self) -> [Option<f32>; 2] {
        self.resistor_c
    }

    /// What latched `resistor-hot`, if it is latched.
    pub fn hot_resistor(&self) -> Option<HotResistor> {
        self.hot
    }

    /// The rise that latched `bypassed`, if the rate of rise latched it.
    pub fn bypass_rise(&self) -> Option<BypassRise> {
        self.bypass
    }

    /// Whether `restart` may run, and the relays to apply before it does: as
    /// [`Self::handover`], and not while `bypassed` or `no-discharge` is latched. Those say an
    /// AIR or the discharge circuit failed: only a power cycle, once the electrical lead has
    /// found it, clears them, never a typed word.
    pub fn restart(&self) -> Result<Relays, HandoverRefusal> {
        let relays = self.handover()?;
        if self.errors.bypassed || self.errors.no_discharge {
            return Err(HandoverRefusal::PowerCycle);
        }
        Ok(relays)
    }

    /// Whether the PCC may stop running its state machine (the bootloader), and the relays
    /// to apply before it does. Only in STANDBY or ERROR, where AIR+ is open, and only with
    /// the tractive system measured below the discharged limit: a PCC that stopped with
    /// AIR+ closed would leave nothing to open it before the shutdown circuit closes again
    /// and starts a precharge AIR+ would bypass.
    ///
    /// After a converter fell silent at high voltage, both converters must first show they
    /// are alive below the discharged limit: until then a reading of 0 V proves nothing.
    pub fn handover(&self) -> Result<Relays, HandoverRefusal> {
        if !matches!(self.state, State::Standby | State::Error) {
            return Err(HandoverRefusal::Energised(self.state));
        }
        if self.errors.converter_silent() {
            let volts = [self.accumulator_v, self.tractive_v];
            for ((converter, pulses), volts) in
                Converter::BOTH.into_iter().zip(self.pulses).zip(volts)
            {
                let reading = match pulses {
                    Pulses::Live if volts < self.config.discharged_v => continue,
                    Pulses::Live => Some(volts),
                    Pulses::Silent { .. } => None,
                };
                return Err(HandoverRefusal::ConverterFault {
                    converter,
                    reading,
                    limit_v: self.config.discharged_v,
                });
            }
        }
        if self.tractive_v >= self.config.discharged_v {
            return Err(HandoverRefusal::Charged {
                tractive_v: self.tractive_v,
                limit_v: self.config.discharged_v,
            });
        }
        Ok(Relays::ALL_OPEN)
    }

    /// The relay outputs for the current state.
    pub fn relays(&self) -> Relays {
        Relays::for_state(self.state)
    }

    /// Runs one control period and returns the relay outputs to apply now.
    pub fn step(&mut self, inputs: &Inputs) -> Relays {
        let now = inputs.now_ms;
        // A measurement that is not a number cannot vouch for anything: treat it as 0 V,
        // which opens the relays (pack lost) rather than closing any.
        self.accumulator_v = sanitise(inputs.accumulator_v);
        self.tractive_v = sanitise(inputs.tractive_v);
        self.progress_percent = if self.accumulator_v >= self.config.min_accumulator_v {
            100.0 * self.tractive_v / self.accumulator_v
        } else {
            0.0
        };
        let pack_present = self.accumulator_v >= self.config.min_accumulator_v;
        let [raw_accumulator, raw_tractive] = inputs.raw_v.map(sanitise);
        self.raw_progress = if raw_accumulator >= self.config.min_accumulator_v {
            100.0 * raw_tractive / raw_accumulator
        } else {
            0.0
        };
        let bms_alive = inputs
            .bms_last_seen_ms
            .is_some_and(|seen| now.wrapping_sub(seen) <= self.config.bms_timeout_ms);
        self.pulses = inputs.pulses;
        self.resistor_c = inputs
            .resistor_c
            .map(|reading| reading.filter(|c| !c.is_nan()));
        self.latch_silences(now);
        self.latch_hot_resistor();
        self.watch_discharge(now);
        self.latch_bypass_rise(now);

        if self.state.is_energised() {
            // Faults first: whatever else happens this period, they open everything.
            self.latch_disagreement();
            if self.falling_away(now) {
                self.errors.shutdown = true;
            }
            if !bms_alive {
                self.errors.bms_timeout = true;
            }
            if self.errors.any() {
                self.enter(State::Error, now);
                return self.relays();
            }
            if !pack_present {
                self.enter(State::Discharge, now);
                return self.relays();
            }
        } else if self.errors.needs_reset() && self.state != State::Error {
            // A fault latched outside the energised states (a silent converter, a hot
            // resistor, no discharge): ERROR until a power cycle.
            self.enter(State::Error, now);
            return self.relays();
        }

        match self.state {
            State::Standby => {
                // The hardware started precharging (the shutdown circuit closed): the timer
                // starts now, at the rise, not after a settle time that would shorten the
                // measured precharge.
                //
                // A rise is timed only from rest seen with the PCC ready (the pack read, the
                // BMS heard): a tractive system that charged while the PCC could not start,
                // or was closed again before it discharged, would otherwise start a PRECHARGE
                // timed short. A jump from rest still starts PRECHARGE, whose `too-fast` then
                // names a bypassed precharge resistor or a welded AIR+.
                let resistor_watched = self.resistor_c.iter().any(Option::is_some);
                let ready = pack_present && bms_alive && resistor_watched;
                // Without a pack reading the rest is judged against the smallest pack the PCC
                // accepts, so a tractive system charging with the pack unread says so.
                let at_rest = if pack_present {
                    self.progress_percent < self.config.rest_percent
                        && self.tractive_v < self.config.discharged_v
                } else {
                    self.tractive_v
                        < self.config.min_accumulator_v * self.config.rest_percent / 100.0
                };
                if !ready {
                    self.rest_seen = false;
                } else if at_rest {
                    self.rest_seen = true;
                }
                self.trough_percent = if self.rest_seen {
                    self.trough_percent.min(self.progress_percent)
                } else {
                    self.progress_percent
                };
                let rising = self.rest_seen
                    && self.progress_percent >= self.trough_percent + self.config.start_percent;
                if ready && rising {
                    self.enter(State::Precharge, now);
                } else {
                    let discharge = !self.rest_seen && !at_rest;
                    self.waiting = Some(Waiting {
                        pack: !pack_present,
                        bms: !bms_alive,
                        rise: !rising && !discharge,
                        discharge,
                        live: discharge && self.tractive_v >= self.config.discharged_v,
                        resistor: !resistor_watched,
                    });
                }
            }
            State::Precharge => self.precharge(now, inputs.charger_safety),
            State::Online | State::Charging => self.follow_charger(now, inputs.charger_safety),
            State::Discharge => {
                if self.tractive_v < self.config.discharged_v {
                    self.enter(State::Standby, now);
                }
            }
            State::Error => {
                let recovered =
                    !self.errors.needs_reset() && self.tractive_v < self.config.discharged_v;
                if self.held_for(recovered, now, self.config.standby_settle_ms) {
                    self.errors = Errors::default();
                    self.enter(State::Standby, now);
                }
            }
        }
        self.relays()
    }

    /// Latches a converter's silence when it cannot mean 0 V: after a reading of the
    /// discharged limit or more, or in a state where the converter must be reading.
    fn latch_silences(&mut self, now: u32) {
        let watched = matches!(
            self.state,
            State::Precharge | State::Online | State::Charging | State::Discharge
        );
        for ((converter, pulses), latched) in Converter::BOTH
            .into_iter()
            .zip(self.pulses)
            .zip(self.silences.iter_mut())
        {
            let Pulses::Silent { last_v, since_ms } = pulses else {
                continue;
            };
            if latched.is_some() || !(watched || last_v >= self.config.discharged_v) {
                continue;
            }
            *latched = Some(Silence {
                converter,
                last_v,
                since_ms: now.wrapping_sub(since_ms),
            });
            match converter {
                Converter::Accumulator => self.errors.accumulator_silent = true,
                Converter::Tractive => self.errors.tractive_silent = true,
            }
        }
    }

    /// Latches `too-fast` with `bypassed` when progress rose more in one window than any
    /// precharge through the resistor can: watched in STANDBY once the tractive system was
    /// seen at rest, and in PRECHARGE.
    fn latch_bypass_rise(&mut self, now: u32) {
        let watched =
            (self.state == State::Standby && self.rest_seen) || self.state == State::Precharge;
        let previous = self.last_raw_progress.replace((self.raw_progress, now));
        if !watched {
            self.last_raw_progress = None;
            return;
        }
        // Judged over one control period (a late step stretches it to two at most).
        if let Some((from, at)) = previous
            && now.wrapping_sub(at) <= 2 * TASK_PERIOD_MS
            && self.raw_progress - from >= self.config.bypass_rise_percent
            && !self.errors.bypassed
        {
            self.errors.too_fast = true;
            self.errors.bypassed = true;
            self.bypass = Some(BypassRise {
                from_percent: from,
                to_percent: self.raw_progress,
            });
        }
    }

    /// Latches `converters-disagree` when the tractive system reads above the pack by more
    /// than the converters can disagree, for the drop windows in a row.
    fn latch_disagreement(&mut self) {
        if self.raw_progress > self.config.max_progress_percent {
            self.progress_high = self.progress_high.saturating_add(1);
        } else {
            self.progress_high = 0;
        }
        if self.progress_high >= self.config.online_drop_periods {
            self.errors.converters_disagree = true;
        }
    }

    /// Latches `resistor-hot` at the first thermistor reading at or above the limit.
    fn latch_hot_resistor(&mut self) {
        if self.errors.resistor_hot {
            return;
        }
        let limit_c = self.config.resistor_limit_c;
        for (thermistor, celsius) in (1u8..).zip(self.resistor_c) {
            if let Some(celsius) = celsius.filter(|c| *c >= limit_c) {
                self.errors.resistor_hot = true;
                self.hot = Some(HotResistor {
                    thermistor,
                    celsius,
                    limit_c,
                });
                return;
            }
        }
    }

    /// In ERROR and DISCHARGE after AIR+ opened: once the tractive system falls, it must
    /// reach the discharged limit within the discharge time, or `no-discharge` latches.
    fn watch_discharge(&mut self, now: u32) {
        if !matches!(self.state, State::Error | State::Discharge) {
            self.discharge = None;
            return;
        }
        let Some(watch) = self.discharge.as_mut() else {
            return;
        };
        if self.tractive_v < self.config.discharged_v {
            self.discharge = None;
            return;
        }
        let volts = self.tractive_v;
        if watch.falling_since_ms.is_some() && volts > watch.low_v + watch.peak_v * DISCHARGE_RISE {
            // Charged again: the shutdown circuit closed again (a bounce), not a discharge.
            *watch = DischargeWatch {
                peak_v: volts,
                dip_since_ms: None,
                falling_since_ms: None,
                low_v: volts,
            };
        }
        watch.peak_v = watch.peak_v.max(volts);
        watch.low_v = watch.low_v.min(volts);
        if volts < watch.peak_v * (1.0 - DISCHARGE_DIP) {
            watch.dip_since_ms.get_or_insert(now);
        } else if watch.falling_since_ms.is_none() {
            watch.dip_since_ms = None;
        }
        let fallen = volts < watch.peak_v * (1.0 - self.config.precharge_drop_percent / 100.0);
        if watch.falling_since_ms.is_none() && fallen {
            watch.falling_since_ms = Some(watch.dip_since_ms.unwrap_or(now));
            watch.low_v = volts;
        }
        if let Some(since) = watch.falling_since_ms
            && now.wrapping_sub(since) >= self.config.discharge_time_ms
            && !self.errors.no_discharge
        {
            self.errors.no_discharge = true;
            self.no_discharge = Some(NoDischarge {
                tractive_v: self.tractive_v,
                falling_since_ms: since,
                limit_ms: self.config.discharge_time_ms,
            });
        }
    }

    /// True once the tractive system has been falling away from the pack for the hold time:
    /// in PRECHARGE, progress more than the allowed drop below its peak; in ONLINE and
    /// CHARGING until AIR+ has brought it to the online minimum, one window's own reading
    /// [`ONLINE_CLOSING_DROP`] points below the highest since (AIR+ is closing then: a shutdown
    /// circuit that bounces must be seen before its contacts close on a tractive system that
    /// fell); from then on, below the online minimum. Either means AIR- or the precharge path opened (the shutdown circuit)
    /// or the tractive system is being loaded down (a short). AIR+ that does not bring it to
    /// the online minimum within the close time latches `air-plus-open` instead.
    fn falling_away(&mut self, now: u32) -> bool {
        // Without a pack reading progress means nothing: the pack lost is DISCHARGE.
        if self.accumulator_v < self.config.min_accumulator_v {
            return false;
        }
        let progress = self.progress_percent;
        if matches!(self.state, State::Online | State::Charging) && !self.online_reached {
            self.raw_peak_percent = self.raw_peak_percent.max(self.raw_progress);
            if self.raw_progress >= self.config.online_min_percent {
                self.online_reached = true;
            } else if self.raw_progress < self.raw_peak_percent - ONLINE_CLOSING_DROP {
                return true;
            } else if now.wrapping_sub(self.entered_ms) >= self.config.air_plus_close_ms {
                self.errors.air_plus_open = true;
                return false;
            } else {
                // AIR+ still closing: a fall from the peak opens it, as in PRECHARGE.
                self.peak_percent = self.peak_percent.max(progress);
                let falling = progress < self.peak_percent - self.config.precharge_drop_percent;
                if !falling {
                    self.falling_since_ms = None;
                    return false;
                }
                let since = *self.falling_since_ms.get_or_insert(now);
                return now.wrapping_sub(since) >= self.config.target_hold_ms;
            }
        }
        if matches!(self.state, State::Online | State::Charging) {
            // Each window's own reading, no filter and no hold beyond the windows: AIR+ must
            // be open before a shutdown circuit that bounces can close again onto a tractive
            // system far below the pack.
            if self.raw_progress < self.config.online_min_percent {
                self.online_low = self.online_low.saturating_add(1);
                if self.falling_since_ms.is_none() {
                    self.falling_since_ms = Some(now);
                }
            } else {
                self.online_low = 0;
                self.falling_since_ms = None;
            }
            return self.online_low >= self.config.online_drop_periods;
        }
        let falling = match self.state {
            State::Precharge => {
                self.peak_percent = self.peak_percent.max(progress);
                progress < self.peak_percent - self.config.precharge_drop_percent
            }
            _ => false,
        };
        if !falling {
            self.falling_since_ms = None;
            return false;
        }
        let since = *self.falling_since_ms.get_or_insert(now);
        now.wrapping_sub(since) >= self.config.target_hold_ms
    }

    fn precharge(&mut self, now: u32, charger_safety: bool) {
        let elapsed = now.wrapping_sub(self.entered_ms);
        if self.progress_percent >= self.config.target_percent {
            let since = *self.at_target_since_ms.get_or_insert(now);
            if now.wrapping_sub(since) < self.config.target_hold_ms {
                return;
            }
            // The moment the target was first reached decides, not the end of the hold.
            let reached_after = since.wrapping_sub(self.entered_ms);
            self.record_precharge(Some(reached_after));
            if reached_after < self.config.min_time_ms {
                self.errors.too_fast = true;
                self.errors.bypassed = reached_after < self.config.bypass_max_ms;
                self.enter(State::Error, now);
            } else if reached_after > self.config.max_time_ms {
                self.errors.too_slow = true;
                self.enter(State::Error, now);
            } else if charger_safety {
                self.enter(State::Charging, now);
            } else {
                self.enter(State::Online, now);
            }
        } else {
            self.at_target_since_ms = None;
            if elapsed > self.config.max_time_ms {
                self.record_precharge(None);
                self.errors.too_slow = true;
                self.enter(State::Error, now);
            }
        }
    }

    fn record_precharge(&mut self, reached_ms: Option<u32>) {
        self.last_precharge = Some(PrechargeTiming {
            attempt: self
                .last_precharge
                .map_or(1, |last| last.attempt.wrapping_add(1)),
            reached_ms,
            target_percent: self.config.target_percent as u8,
            window_ms: (self.config.min_time_ms, self.config.max_time_ms),
            bypass_max_ms: self.config.bypass_max_ms,
        });
    }

    /// True once `condition` has held continuously for `duration_ms` (tracked across calls).
    fn held_for(&mut self, condition: bool, now: u32, duration_ms: u32) -> bool {
        self.conditions
            .update(condition, now)
            .is_some_and(|held| held >= duration_ms)
    }

    fn enter(&mut self, state: State, now: u32) {
        if self.state.is_energised() && matches!(state, State::Error | State::Discharge) {
            // AIR+ opens now: watch the discharge from the first real fall from the peak (the
            // shutdown circuit opening). A tractive system still held up through the precharge
            // resistor, the circuit closed, never starts the timer.
            self.discharge = Some(DischargeWatch {
                peak_v: self.tractive_v,
                dip_since_ms: None,
                falling_since_ms: None,
                low_v: self.tractive_v,
            });
        }
        self.state = state;
        self.waiting = None;
        self.entered_ms = now;
        self.conditions.reset();
        self.at_target_since_ms = None;
        // Entering ONLINE or CHARGING, the reading AIR+ closes on is the peak a fall is judged
        // from while it closes.
        self.peak_percent = if matches!(state, State::Online | State::Charging) {
            self.progress_percent
        } else {
            0.0
        };
        self.trough_percent = f32::MAX;
        self.rest_seen = false;
        self.falling_since_ms = None;
        self.online_low = 0;
        self.online_reached = false;
        self.charger_change_since = None;
        self.progress_high = 0;
        self.raw_peak_percent = self.raw_progress;
        self.last_raw_progress = None;
    }

    /// ONLINE and CHARGING follow the BMS's charger-safety bit once it has held its new value
    /// for the debounce time. Both keep AIR+ closed, so the switch is not a new state's start:
    /// the watch on the tractive system (its low windows, its fall) goes on across it, and a
    /// bit that flickers cannot keep restarting it.
    fn follow_charger(&mut self, now: u32, charger_safety: bool) {
        let wanted = if charger_safety {
            State::Charging
        } else {
            State::Online
        };
        if wanted == self.state {
            self.charger_change_since = None;
            return;
        }
        let since = *self.charger_change_since.get_or_insert(now);
        if now.wrapping_sub(since) >= self.config.charger_debounce_ms {
            self.state = wanted;
            self.charger_change_since = None;
        }
    }
}

fn sanitise(volts: f32) -> f32 {
    if volts.is_finite() && volts > 0.0 {
        volts
    } else {
        0.0
    }
}
