//! What the PCC's images print on the USB console, without hardware types, so every line a
//! bench procedure relies on is built here, tested on the host (worst cases included) and
//! quoted in docs/bench-day.md from the test that prints it: the race image's start-up, state,
//! precharge-time and bus lines ([`RaceLog`]) and its answer to `bootloader` and `restart`;
//! the bring-up image's start-up lines and its report every second.

use crate::bringup::GateLine;
use crate::constants::TASK_PERIOD_MS;
use crate::constants::VfConfig;
use crate::machine::{
    BypassRise, HandoverRefusal, HotResistor, NoDischarge, Precharge, PrechargeTiming, Silence,
    Waiting,
};
use crate::measurement::Pulses;
use crate::relays::Relays;
use crate::state::{Errors, State};
use aer_boards::assumed::Board as AssumedBoard;
use aer_boards::pcc::Revision;
use aer_console::board_check::BoardCheck;
use aer_console::bringup::{
    AnalogReading, BusLine, Clocks, DigitalReading, ReportHeader, ResetCause, Startup,
    write_assumed,
};
use aer_console::{LogBuffer, Reboot, Watch};
use aer_flexcan::BusStatus;
use core::fmt;

/// Bytes of log the race image keeps for the host: its start-up lines (with what is still
/// assumed) and every fault line at its longest besides, for a console opened late.
pub const LOG_BYTES: usize = 8_192;
/// Bytes of log the bring-up image keeps for the host.
pub const BRINGUP_LOG_BYTES: usize = 8_192;

/// The race image's start-up lines. Returns the lines that did not fit.
pub fn race_startup<const N: usize>(
    log: &mut LogBuffer<N>,
    board: &Revision,
    reset: ResetCause,
    check: BoardCheck,
) -> u32 {
    Startup {
        image: "AER PCC",
        board: board.name,
        fingerprints: &[("schema", aer::can::SCHEMA_FINGERPRINT)],
        reset,
        clocks: None,
        pins: &[],
        check,
    }
    .write(log)
        + write_assumed(log, AssumedBoard::Pcc)
}

/// A converter's reading as the console prints it: its voltage, or `no pulses`, never a 0 V
/// that a broken wire would give just as well.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConverterVolts {
    /// The filtered voltage (V).
    pub volts: f32,
    /// Whether it gives pulses.
    pub pulses: Pulses,
}

impl ConverterVolts {
    /// Both converters of `pcc` as last read: accumulator, tractive system.
    pub fn of(pcc: &Precharge) -> [Self; 2] {
        let [accumulator, tractive] = pcc.pulses();
        [
            Self {
                volts: pcc.accumulator_v(),
                pulses: accumulator,
            },
            Self {
                volts: pcc.tractive_v(),
                pulses: tractive,
            },
        ]
    }
}

impl fmt::Display for ConverterVolts {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.pulses {
            Pulses::Live => write!(f, "{:.1} V", self.volts),
            Pulses::Silent { .. } => f.write_str("no pulses"),
        }
    }
}

/// The precharge resistor's temperature at one thermistor, as the console prints it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ResistorTemperature(pub Option<f32>);

impl fmt::Display for ResistorTemperature {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.0 {
            Some(celsius) if celsius > 999.0 => f.write_str("shorted (hot)"),
            Some(celsius) => write!(f, "{celsius:.1} degC"),
            None => f.write_str("no reading"),
        }
    }
}

/// The race image's line when the state or the errors change.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StateLine {
    /// Milliseconds since start-up.
    pub now_ms: u32,
    /// The new state.
    pub state: State,
    /// The relays applied in the same period.
    pub relays: Relays,
    /// The latched error causes.
    pub errors: Errors,
    /// The accumulator's converter.
    pub accumulator: ConverterVolts,
    /// The tractive system's converter.
    pub tractive: ConverterVolts,
}

impl fmt::Display for StateLine {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "t={} ms state {:?}, AIR+ {}, errors: {}, accumulator {}, tractive {}",
            self.now_ms,
            self.state,
            if self.relays.air_plus {
                "closed"
            } else {
                "open"
            },
            self.errors,
            self.accumulator,
            self.tractive
        )
    }
}

/// The race image's voltages, resistor temperatures, bus and drop counters, every 5 s.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CountersLine {
    /// Milliseconds since start-up.
    pub now_ms: u32,
    /// The accumulator's converter.
    pub accumulator: ConverterVolts,
    /// The tractive system's converter.
    pub tractive: ConverterVolts,
    /// The precharge resistor at its two thermistors.
    pub resistor: [ResistorTemperature; 2],
    /// The CAN controller.
    pub bus: BusStatus,
    /// Frames dropped because the receive queue was full.
    pub rx_queue_overflows: u32,
    /// Status frames not sent.
    pub status_not_sent: u32,
    /// Log lines dropped.
    pub log_dropped: u32,
}

impl fmt::Display for CountersLine {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let [first, second] = self.resistor;
        write!(
            f,
            "t={} ms accumulator {}, tractive {}; resistor {first}, {second}; CAN2 {}; rx queue overflows {}, status not sent {}, log lines dropped {}",
            self.now_ms,
            self.accumulator,
            self.tractive,
            self.bus,
            self.rx_queue_overflows,
            self.status_not_sent,
            self.log_dropped
        )
    }
}

/// The race image's answer to `bootloader` (or 134 baud) and `restart`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RebootAnswer {
    /// What was asked.
    pub reboot: Reboot,
    /// Obeyed (AIR+ open), or refused and why.
    pub outcome: Result<(), HandoverRefusal>,
}

impl fmt::Display for RebootAnswer {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (asked, doing) = match self.reboot {
            Reboot::Bootloader => ("bootloader", "rebooting into the bootloader"),
            Reboot::Restart => ("restart", "restarting"),
        };
        match self.outcome {
            Ok(()) => write!(f, "{asked}: pin 11 (AIR+) low; {doing}"),
            Err(why) => write!(f, "{asked} REFUSED: {why}"),
        }
    }
}

/// What the race image's control task logs: the state and errors when they change, what
/// STANDBY waits for when that changes, each precharge's timing when it ends, and every 5 s
/// the voltages, the bus and the drop counters.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RaceLog {
    state: Watch<(State, Errors)>,
    waiting: Watch<Option<Waiting>>,
    precharge: Watch<Option<PrechargeTiming>>,
    silences: [Watch<Option<Silence>>; 2],
    no_discharge: Watch<Option<NoDischarge>>,
    hot: Watch<Option<HotResistor>>,
    bypass: Watch<Option<BypassRise>>,
    thermistors: Watch<[bool; 2]>,
}

/// The line that names a converter's latched silence.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SilenceLine {
    /// Milliseconds since start-up.
    pub now_ms: u32,
    /// What latched.
    pub silence: Silence,
    /// The discharged limit (V).
    pub discharged_v: f32,
}

impl fmt::Display for SilenceLine {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let Silence {
            converter,
            last_v,
            since_ms,
        } = self.silence;
        write!(
            f,
            "t={} ms {} SILENT since t={since_ms} ms, last read {last_v:.1} V: a broken wire or a dead converter, not 0 V. Treat the tractive system as live: AIR+ stays open; open the shutdown circuit and have the ESO measure at the TSMP (below {:.0} V before anyone touches it); bootloader, restart and a new precharge wait for a power cycle (LV off, USB out) after that measurement, or for both converters to give pulses below it (the bench, step 6c)",
            self.now_ms,
            converter.name(),
            self.discharged_v
        )
    }
}

/// The line that names a tractive system that did not discharge.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoDischargeLine {
    /// Milliseconds since start-up.
    pub now_ms: u32,
    /// What latched.
    pub fault: NoDischarge,
    /// The discharged limit (V).
    pub discharged_v: f32,
}

impl fmt::Display for NoDischargeLine {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let NoDischarge {
            tractive_v,
            falling_since_ms,
            limit_ms,
        } = self.fault;
        write!(
            f,
            "t={} ms NO DISCHARGE: the tractive system reads {tractive_v:.1} V {limit_ms} ms after it began to fall (t={falling_since_ms} ms; the rules: below {:.0} V within {limit_ms} ms): an AIR welded or the discharge circuit failed. Hands off: the ESO isolates the accumulator (maintenance plug) and measures at the TSMP",
            self.now_ms, self.discharged_v
        )
    }
}

/// The line that names a rise no precharge resistor allows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BypassLine {
    /// Milliseconds since start-up.
    pub now_ms: u32,
    /// The rise.
    pub rise: BypassRise,
}

impl fmt::Display for BypassLine {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "t={} ms BYPASSED: the tractive system rose from {:.0} % to {:.0} % of the pack in one step, faster than any precharge through the resistor: AIR+ welded or the precharge resistor bypassed. Open the shutdown circuit; nothing closes again until the electrical lead has found it (the weld check)",
            self.now_ms, self.rise.from_percent, self.rise.to_percent
        )
    }
}

/// The line that names a hot precharge resistor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HotResistorLine {
    /// Milliseconds since start-up.
    pub now_ms: u32,
    /// What latched.
    pub hot: HotResistor,
}

impl fmt::Display for HotResistorLine {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let HotResistor {
            thermistor,
            celsius,
            limit_c,
        } = self.hot;
        write!(
            f,
            "t={} ms RESISTOR HOT: thermistor {thermistor} (pin {}) reads {}, limit {limit_c:.0} degC: the precharge resistor overheats (a precharge that stalls, a load on the tractive system). Open the shutdown circuit and let it cool; AIR+ stays open until a power cycle",
            self.now_ms,
            if thermistor == 1 { 21 } else { 22 },
            ResistorTemperature(Some(celsius))
        )
    }
}

/// STANDBY's line: what precharge waits for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WaitingLine {
    /// Milliseconds since start-up.
    pub now_ms: u32,
    /// What is not met yet.
    pub waiting: Waiting,
    /// Accumulator voltage (V).
    pub accumulator_v: f32,
    /// The pack minimum (V).
    pub pack_min_v: f32,
    /// The discharged limit (V).
    pub discharged_v: f32,
    /// The rest a timed precharge starts from (% of the pack).
    pub rest_percent: f32,
    /// The BMS timeout (ms).
    pub bms_timeout_ms: u32,
}

impl fmt::Display for WaitingLine {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "t={} ms standby: precharge waits for", self.now_ms)?;
        let mut first = true;
        let mut item = |f: &mut fmt::Formatter<'_>, args: fmt::Arguments<'_>| {
            let sep = if first { " " } else { ", " };
            first = false;
            write!(f, "{sep}{args}")
        };
        if self.waiting.pack {
            item(
                f,
                format_args!(
                    "the pack (accumulator {:.1} V, below {:.0} V)",
                    self.accumulator_v, self.pack_min_v
                ),
            )?;
        }
        if self.waiting.bms {
            item(
                f,
                format_args!("the BMS (no frame in {} ms)", self.bms_timeout_ms),
            )?;
        }
        if self.waiting.rise {
            item(
                f,
                format_args!("the tractive system to rise (the shutdown circuit to close)"),
            )?;
        }
        if self.waiting.resistor {
            item(
                f,
                format_args!(
                    "a precharge-resistor thermistor (neither gives a reading: a precharge would \
                     heat the resistor unwatched; check their wiring, 6a)"
                ),
            )?;
        }
        if self.waiting.discharge {
            if self.waiting.live {
                item(
                    f,
                    format_args!(
                        "the tractive system to discharge (at {:.0} V or more with AIR+ open: it \
                         charged while the PCC could not time it; open the shutdown circuit and \
                         treat it as live until the TSMP meter reads below {:.0} V)",
                        self.discharged_v, self.discharged_v
                    ),
                )?;
            } else {
                item(
                    f,
                    format_args!(
                        "the tractive system to discharge to rest (below {:.0} % of the pack, \
                         {:.0} V without a pack reading, where a timed precharge starts: open \
                         the shutdown circuit and wait)",
                        self.rest_percent,
                        self.pack_min_v * self.rest_percent / 100.0
                    ),
                )?;
            }
        }
        if first {
            f.write_str(" nothing")?;
        }
        Ok(())
    }
}

impl RaceLog {
    /// Logs what changed in the step at `now_ms` that left `pcc` with `relays` applied.
    pub fn changes<const N: usize>(
        &mut self,
        now_ms: u32,
        pcc: &Precharge,
        relays: Relays,
        log: &mut LogBuffer<N>,
    ) {
        if let Some((state, errors)) = self.state.changed((pcc.state(), pcc.errors())) {
            let [accumulator, tractive] = ConverterVolts::of(pcc);
            let line = StateLine {
                now_ms,
                state,
                relays,
                errors,
                accumulator,
                tractive,
            };
            log.line(format_args!("{line}"));
        }
        let discharged_v = pcc.config().discharged_v;
        for (watch, silence) in self.silences.iter_mut().zip(pcc.silences()) {
            if let Some(Some(silence)) = watch.changed(silence) {
                let line = SilenceLine {
                    now_ms,
                    silence,
                    discharged_v,
                };
                log.line(format_args!("{line}"));
            }
        }
        if let Some(Some(fault)) = self.no_discharge.changed(pcc.no_discharge()) {
            let line = NoDischargeLine {
                now_ms,
                fault,
                discharged_v,
            };
            log.line(format_args!("{line}"));
        }
        if let Some(Some(hot)) = self.hot.changed(pcc.hot_resistor()) {
            log.line(format_args!("{}", HotResistorLine { now_ms, hot }));
        }
        if let Some(Some(rise)) = self.bypass.changed(pcc.bypass_rise()) {
            log.line(format_args!("{}", BypassLine { now_ms, rise }));
        }
        let readings = pcc.resistor_c().map(|reading| reading.is_some());
        if let Some(readings) = self.thermistors.changed(readings) {
            for (thermistor, (reads, celsius)) in (1u8..).zip(readings.iter().zip(pcc.resistor_c()))
            {
                let pin = if thermistor == 1 { 21 } else { 22 };
                if *reads {
                    log.line(format_args!(
                        "t={now_ms} ms thermistor {thermistor} (pin {pin}) reads {}",
                        ResistorTemperature(celsius)
                    ));
                } else {
                    log.line(format_args!(
                        "t={now_ms} ms thermistor {thermistor} (pin {pin}) gives no reading (open or unplugged): the precharge resistor's temperature is not watched there"
                    ));
                }
            }
        }
        // What STANDBY waits for, when it changes and again with every counters line: a
        // terminal opened late still reads it within 5 s.
        let changed = self.waiting.changed(pcc.waiting()).is_some();
        if let Some(waiting) = pcc.waiting()
            && (changed || Self::counters_due(now_ms))
        {
            let config = pcc.config();
            let line = WaitingLine {
                now_ms,
                waiting,
                accumulator_v: pcc.accumulator_v(),
                pack_min_v: config.min_accumulator_v,
                discharged_v: config.discharged_v,
                rest_percent: config.rest_percent,
                bms_timeout_ms: config.bms_timeout_ms,
            };
            log.line(format_args!("{line}"));
        }
        if let Some(Some(timing)) = self.precharge.changed(pcc.last_precharge()) {
            log.line(format_args!("t={now_ms} ms {timing}"));
        }
    }

    /// `status`: the state and what is latched now, each latched cause's own line, the
    /// resistor's temperatures, then what the image runs with that the bench day has not
    /// settled.
    pub fn status<const N: usize>(
        &self,
        now_ms: u32,
        pcc: &Precharge,
        relays: Relays,
        log: &mut LogBuffer<N>,
    ) {
        let [accumulator, tractive] = ConverterVolts::of(pcc);
        let line = StateLine {
            now_ms,
            state: pcc.state(),
            relays,
            errors: pcc.errors(),
            accumulator,
            tractive,
        };
        log.line(format_args!("{line}"));
        let discharged_v = pcc.config().discharged_v;
        for silence in pcc.silences().into_iter().flatten() {
            let line = SilenceLine {
                now_ms,
                silence,
                discharged_v,
            };
            log.line(format_args!("{line}"));
        }
        if let Some(fault) = pcc.no_discharge() {
            let line = NoDischargeLine {
                now_ms,
                fault,
                discharged_v,
            };
            log.line(format_args!("{line}"));
        }
        if let Some(hot) = pcc.hot_resistor() {
            log.line(format_args!("{}", HotResistorLine { now_ms, hot }));
        }
        if let Some(rise) = pcc.bypass_rise() {
            log.line(format_args!("{}", BypassLine { now_ms, rise }));
        }
        let [first, second] = pcc.resistor_c().map(ResistorTemperature);
        log.line(format_args!(
            "t={now_ms} ms resistor: thermistor 1 (pin 21) {first}, thermistor 2 (pin 22) {second}"
        ));
        write_assumed(log, AssumedBoard::Pcc);
    }

    /// Whether the step at `now_ms` logs the counters (the first step of every 5 s).
    pub const fn counters_due(now_ms: u32) -> bool {
        now_ms % 5_000 < TASK_PERIOD_MS
    }
}

/// The bring-up image's start-up lines. Returns the lines that did not fit.
pub fn bringup_startup<const N: usize>(
    log: &mut LogBuffer<N>,
    board: &Revision,
    reset: ResetCause,
    check: BoardCheck,
) -> u32 {
    let mut missed = Startup {
        image: "AER PCC bring-up",
        board: board.name,
        fingerprints: &[("schema", aer::can::SCHEMA_FINGERPRINT)],
        reset,
        clocks: Some(Clocks::TEENSY4),
        pins: &board.pins(),
        check,
    }
    .write(log);
    if !log.line(format_args!(
        "pin 11 (AIR+) is low; `confirm hv-disconnected` (both V/F converters alive and below 60 V) then `out air-plus-close on` to move it; `help`"
    )) {
        missed += 1;
    }
    missed
}

/// A V/F converter's input as the bring-up report prints it: its edges, their rate, and the
/// voltage that rate means.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VfReading {
    /// The input and its edges.
    pub input: DigitalReading,
    /// The measurement chain.
    pub vf: VfConfig,
}

impl VfReading {
    /// The voltage the edge rate means (V).
    pub fn volts(&self) -> f32 {
        self.vf.volts_for_hz(self.input.hz)
    }
}

impl fmt::Display for VfReading {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.input.hz > 0.0 {
            write!(f, "{} = {:.1} V", self.input, self.volts())
        } else {
            // No pulses is not 0 V: the converter may be unplugged, unpowered or broken.
            write!(f, "{} = no reading (no pulses)", self.input)
        }
    }
}

/// A precharge-resistor thermistor's input as the bring-up report prints it: the counts and
/// volts, and the temperature the race image's conversion makes of them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ThermistorReading(pub AnalogReading);

impl fmt::Display for ThermistorReading {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let celsius = crate::constants::THERMISTORS.temperature_c(self.0.counts);
        match celsius {
            Some(_) => write!(f, "{} = {}", self.0, ResistorTemperature(celsius)),
            None => write!(f, "{} = no reading (open or unplugged)", self.0),
        }
    }
}

/// The bring-up image's report every second.
#[derive(Debug, Clone, Copy)]
pub struct BringupReport<'a> {
    /// Time and dropped lines.
    pub header: ReportHeader,
    /// The accumulator and tractive-system converters.
    pub vf: [VfReading; 2],
    /// Both thermistor inputs.
    pub thermistors: [ThermistorReading; 2],
    /// The CAN controller.
    pub bus: BusLine<'a>,
    /// Pin 11 (AIR+) and its gate.
    pub gate: GateLine,
}

impl BringupReport<'_> {
    /// Queues the report's lines; returns how many did not fit.
    pub fn write<const N: usize>(&self, log: &mut LogBuffer<N>) -> u32 {
        let mut missed = 0;
        let mut line = |args: fmt::Arguments<'_>| {
            if !log.line(args) {
                missed += 1;
            }
        };
        line(format_args!("{}", self.header));
        for reading in &self.vf {
            line(format_args!("{reading}"));
        }
        for reading in &self.thermistors {
            line(format_args!("{reading}"));
        }
        line(format_args!("{}", self.bus));
        line(format_args!("{}", self.gate));
        missed
    }
}
