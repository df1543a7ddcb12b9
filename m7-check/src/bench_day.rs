//! The bench day's console transcripts: what a good board prints at each step of
//! docs/bench-day.md. The bring-up images' transcripts come from the images' own bench code
//! (`aer_ccm::bench`, `aer_pcc::bench`) driven by the console's bench loop over a simulated
//! board (`bench_sim`), with typed commands, at the images' own periods; the race images'
//! from their library code (`aer_ccm::console`, `aer_pcc::console`, the precharge state
//! machine behind the V/F measurement chain). `cargo xtask m7-check` prints them from QEMU's
//! Cortex-M7 and requires the host's to be the same; `tests/bench_day_doc.rs` requires
//! docs/bench-day.md to quote them exactly (`cargo run -p aer-m7-check --example bench_day`
//! prints them all).

use crate::bench_sim::{
    ACTIVE, CcmSession, Discard, Keep, PccSession, PulseTrain, Pulses, SimCcm, SimDti, SimPcc,
};
use aer::can::{OrionLimits, PrechargeState};
use aer_ccm::InverterKind;
use aer_ccm::calibration::Calibration;
use aer_ccm::calibration::measured::{MEASURED, SOURCE};
use aer_ccm::calibration::store::{Startup, crc32};
use aer_ccm::console::bringup;
use aer_ccm::console::{self as ccm_console, CalibrationLine};
use aer_ccm::control::HandoverRefusal;
use aer_console::board_check::{BoardCheck, Teensy};
use aer_console::bringup::ResetCause;
use aer_console::{LogBuffer, Reboot};
use aer_pcc::console::{
    self as pcc_console, ConverterVolts, CountersLine, RaceLog, RebootAnswer, ResistorTemperature,
};
use aer_pcc::constants::CONVERTERS;
use aer_pcc::measurement::VoltageChannel;
use aer_pcc::{Inputs, Precharge, PrechargeConfig, Relays, State, TASK_PERIOD_MS};
use core::fmt::{self, Write};

/// A named transcript.
pub type Example = (&'static str, fn(&mut dyn Write) -> fmt::Result);

/// Every transcript docs/bench-day.md quotes, by the name its marker gives.
pub const EXAMPLES: [Example; 36] = [
    ("ccm-bringup-startup", ccm_bringup_startup),
    ("ccm-wrong-board", ccm_wrong_board),
    ("pcc-wrong-board", pcc_wrong_board),
    ("ccm-report-alone", ccm_report_alone),
    ("ccm-can-self-test", ccm_can_self_test),
    ("ccm-report-on-the-car", ccm_report_on_the_car),
    ("ccm-calibration", ccm_calibration),
    ("ccm-shock-calibration", ccm_shock_calibration),
    ("ccm-cal-save", ccm_cal_save),
    ("ccm-race-startup", ccm_race_startup),
    ("ccm-race-startup-saved", ccm_race_startup_saved),
    ("ccm-bootloader", ccm_bootloader),
    ("ccm-race-status", ccm_race_status),
    ("pcc-bringup-startup", pcc_bringup_startup),
    ("pcc-report-bench-supply", pcc_report_bench_supply),
    ("pcc-confirm-silent", pcc_confirm_silent),
    ("pcc-confirm-refused", pcc_confirm_refused),
    ("pcc-air-plus", pcc_air_plus),
    ("pcc-generator-frequencies", pcc_generator_frequencies),
    ("pcc-bms-heartbeat", pcc_bms_heartbeat),
    ("pcc-race-startup", pcc_race_startup),
    ("pcc-race-precharge", pcc_race_precharge),
    ("pcc-race-missed", pcc_race_missed),
    ("pcc-race-shutdown", pcc_race_shutdown),
    ("pcc-race-converter-silent", pcc_race_converter_silent),
    ("pcc-race-no-discharge", pcc_race_no_discharge),
    ("pcc-race-bypassed", pcc_race_bypassed),
    ("pcc-bootloader", pcc_bootloader),
    ("pcc-race-watchdog", pcc_race_watchdog),
    ("pcc-race-status", pcc_race_status),
    ("ccm-dti-timeout", ccm_dti_timeout),
    ("ccm-dti-still-enabled", ccm_dti_still_enabled),
    ("ccm-panic-test", ccm_panic_test),
    ("ccm-panic-frames", ccm_panic_frames),
    ("ccm-dti-refused", ccm_dti_refused),
    ("ccm-dti-hv", ccm_dti_hv),
];

/// Writes every transcript, each under a `--- bench-day <name>` line.
pub fn transcripts(out: &mut impl Write) -> fmt::Result {
    for (name, example) in EXAMPLES {
        writeln!(out, "--- bench-day {name}")?;
        example(out)?;
    }
    Ok(())
}

/// The lines of a log, copied to `out` as the host reads them.
fn flush<const N: usize>(log: &mut LogBuffer<N>, out: &mut dyn Write) -> fmt::Result {
    let mut line = [0u8; 512];
    let mut len = 0;
    let mut chunk = [0u8; 64];
    loop {
        let count = log.peek(&mut chunk);
        if count == 0 {
            break;
        }
        for &byte in chunk.get(..count).unwrap_or(&[]) {
            match byte {
                b'\n' => {
                    let text = core::str::from_utf8(line.get(..len).unwrap_or(&[]))
                        .unwrap_or("(not text)");
                    writeln!(out, "{text}")?;
                    len = 0;
                }
                b'\r' => {}
                byte => {
                    if let Some(slot) = line.get_mut(len) {
                        *slot = byte;
                        len += 1;
                    }
                }
            }
        }
        log.consume(count);
    }
    if log.dropped() > 0 {
        writeln!(out, "(log dropped {} lines)", log.dropped())?;
    }
    Ok(())
}

/// [`flush`], leaving out the lines of the list of what is assumed after its header (the
/// start-up quotes; `status` quotes show the list whole).
fn flush_without_assumed<const N: usize>(
    log: &mut LogBuffer<N>,
    out: &mut dyn Write,
) -> fmt::Result {
    let mut bytes = [0u8; 8_192];
    let mut all = Text::new(&mut bytes);
    flush(log, &mut all)?;
    for line in all.as_str().lines() {
        if !line.starts_with("assumed: ") {
            writeln!(out, "{line}")?;
        }
    }
    Ok(())
}

const POWER_ON: ResetCause = ResetCause(0x1);
/// SRC_SRSR after a watchdog restart (WDOG1).
const WATCHDOG: ResetCause = ResetCause(1 << 4);
/// SRC_SRSR after `restart` (SYSRESETREQ).
const SOFTWARE: ResetCause = ResetCause(1 << 1);

/// The CCM's report lines end with this one.
const CCM_REPORT_END: Keep = Keep::NoReports {
    last: "brake light ",
};
/// Console exchanges and events, without the periodic reports.
const EXCHANGE: Keep = Keep::Starting(&["> ", "refused", "t="]);

fn ccm() -> CcmSession {
    let board = aer_boards::ccm::COMP_CAR;
    CcmSession::new(SimCcm::at_rest(&board), board)
}

/// The CCM bring-up image on the car's buses: the PCC (its race image, in STANDBY), the BMS,
/// and the DTI at rest.
fn ccm_on_the_car() -> CcmSession {
    let mut session = ccm();
    let sim = session.sim();
    sim.buses = [Some(ACTIVE); 2];
    sim.pcc = Some(PrechargeState::Standby);
    sim.bms = true;
    sim.dti = Some(SimDti::AT_REST);
    session
}

fn ccm_bringup_startup(out: &mut dyn Write) -> fmt::Result {
    let mut log = LogBuffer::<{ bringup::LOG_BYTES }>::new();
    bringup::startup(
        &mut log,
        &aer_boards::ccm::COMP_CAR,
        POWER_ON,
        BoardCheck::passed("AER CCM bring-up", Teensy::T41),
    );
    flush(&mut log, out)
}

fn ccm_report_alone(out: &mut dyn Write) -> fmt::Result {
    // Alone on both buses after `can`: its heartbeats go unacknowledged, nothing is heard.
    let mut session = ccm();
    session.skip(11_999)?;
    session.run(12_001, out, Keep::All)
}

fn ccm_can_self_test(out: &mut dyn Write) -> fmt::Result {
    let mut session = ccm();
    session.skip(5_500)?;
    session.type_line("can", out, Keep::All)
}

fn ccm_report_on_the_car(out: &mut dyn Write) -> fmt::Result {
    let mut session = ccm_on_the_car();
    session.skip(20_999)?;
    session.run(21_001, out, Keep::All)
}

/// Records the pedal at rest and fully pressed, `cal rest` and `cal full`.
fn record_pedal(session: &mut CcmSession, out: &mut dyn Write, keep: Keep) -> fmt::Result {
    let sim = session.sim();
    for (signal, volts) in [
        ("apps1", 0.512),
        ("apps2", 0.771),
        ("bse1", 0.508),
        ("bse2", 0.514),
    ] {
        sim.set(signal, volts);
    }
    let start = session.now_ms();
    session.type_line("cal rest", out, keep)?;
    session.run(start + 1_100, out, keep)?;
    let sim = session.sim();
    sim.set("apps1", 2.793);
    sim.set("apps2", 4.187);
    session.type_line("cal full", out, keep)?;
    session.run(start + 2_200, out, keep)
}

fn ccm_calibration(out: &mut dyn Write) -> fmt::Result {
    let mut session = ccm();
    session.skip(40_250)?;
    record_pedal(&mut session, out, CCM_REPORT_END)
}

/// The team's shock sensors fully compressed (V), one corner after another.
const SHOCKS_COMPRESSED: [(&str, &str, f32); 4] = [
    ("fl", "shock1", 4.842),
    ("fr", "shock2", 4.851),
    ("rl", "shock3", 4.839),
    ("rr", "shock4", 4.830),
];

/// Records every shock sensor: all four extended at once, then each compressed in turn.
fn record_shocks(session: &mut CcmSession, out: &mut dyn Write, keep: Keep) -> fmt::Result {
    let mut at = session.now_ms();
    session.type_line("cal shock all extended", out, keep)?;
    at += 1_100;
    session.run(at, out, keep)?;
    let mut line = [0u8; 40];
    for (corner, signal, volts) in SHOCKS_COMPRESSED {
        session.sim().set(signal, volts);
        let mut typed = Text::new(&mut line);
        write!(typed, "cal shock {corner} compressed")?;
        session.type_line(typed.as_str(), out, keep)?;
        at += 1_100;
        session.run(at, out, keep)?;
        session.sim().set(signal, 4.98);
    }
    Ok(())
}

/// A short line written into a borrowed buffer, without an allocator.
struct Text<'a> {
    bytes: &'a mut [u8],
    len: usize,
}

impl<'a> Text<'a> {
    fn new(bytes: &'a mut [u8]) -> Self {
        Self { bytes, len: 0 }
    }

    fn as_str(&self) -> &str {
        core::str::from_utf8(self.bytes.get(..self.len).unwrap_or(&[])).unwrap_or("")
    }
}

impl Write for Text<'_> {
    fn write_str(&mut self, text: &str) -> fmt::Result {
        let end = self.len + text.len();
        self.bytes
            .get_mut(self.len..end)
            .ok_or(fmt::Error)?
            .copy_from_slice(text.as_bytes());
        self.len = end;
        Ok(())
    }
}

fn ccm_shock_calibration(out: &mut dyn Write) -> fmt::Result {
    let mut session = ccm();
    session.skip(60_250)?;
    record_shocks(&mut session, out, CCM_REPORT_END)
}

fn ccm_cal_save(out: &mut dyn Write) -> fmt::Result {
    let mut session = ccm();
    session.skip(80_250)?;
    session.type_line("cal load", out, CCM_REPORT_END)?;
    record_pedal(&mut session, &mut Discard, Keep::Nothing)?;
    record_shocks(&mut session, &mut Discard, Keep::Nothing)?;
    for line in ["cal save", "cal load", "cal save"] {
        session.type_line(line, out, CCM_REPORT_END)?;
    }
    Ok(())
}

fn ccm_race_startup(out: &mut dyn Write) -> fmt::Result {
    let mut log = LogBuffer::<{ ccm_console::LOG_BYTES }>::new();
    let calibration = MEASURED.applied_to(Calibration::DEFAULT);
    ccm_console::race_startup(
        &mut log,
        aer_boards::ccm::COMP_CAR.name,
        InverterKind::Dti,
        POWER_ON,
        BoardCheck::passed("AER CCM", Teensy::T41),
        CalibrationLine {
            startup: Startup::NoneSaved,
            checksum: crc32(&calibration.to_page()),
            file_source: SOURCE,
        },
    );
    flush(&mut log, out)
}

fn ccm_race_startup_saved(out: &mut dyn Write) -> fmt::Result {
    let mut log = LogBuffer::<{ ccm_console::LOG_BYTES }>::new();
    // After step 5's `cal save`: copy A, with the measured sensors.
    let mut session = ccm();
    record_pedal(&mut session, &mut Discard, Keep::Nothing)?;
    record_shocks(&mut session, &mut Discard, Keep::Nothing)?;
    session.type_line("cal save", &mut Discard, Keep::Nothing)?;
    let (_, loaded) = aer_ccm::calibration::store::CalibrationStore::load(
        aer_ccm::bench::CcmHardware::flash(session.sim()),
        aer_ccm::calibration::EPK,
    );
    ccm_console::race_startup(
        &mut log,
        aer_boards::ccm::COMP_CAR.name,
        InverterKind::Dti,
        POWER_ON,
        BoardCheck::passed("AER CCM", Teensy::T41),
        CalibrationLine {
            startup: loaded.startup,
            checksum: crc32(&loaded.calibration.to_page()),
            file_source: SOURCE,
        },
    );
    // Up to the calibration line: the list of what is assumed follows as before.
    let mut bytes = [0u8; 4_096];
    let mut all = Text::new(&mut bytes);
    flush(&mut log, &mut all)?;
    for line in all
        .as_str()
        .lines()
        .take_while(|line| !line.starts_with("this image runs"))
    {
        writeln!(out, "{line}")?;
    }
    Ok(())
}

fn ccm_bootloader(out: &mut dyn Write) -> fmt::Result {
    let mut log = LogBuffer::<{ ccm_console::LOG_BYTES }>::new();
    for (now, reboot, outcome) in [
        (84_310, Reboot::Bootloader, Err(HandoverRefusal::Driving)),
        (96_020, Reboot::Bootloader, Ok(())),
        (131_400, Reboot::Restart, Ok(())),
    ] {
        let answer = ccm_console::RebootAnswer { reboot, outcome };
        log.line(format_args!("t={now} ms {answer}"));
    }
    flush(&mut log, out)
}

fn ccm_dti_timeout(out: &mut dyn Write) -> fmt::Result {
    let mut session = ccm_on_the_car();
    session.skip(30_250)?;
    let keep = Keep::Starting(&["> ", "refused", "t="]);
    session.type_line("confirm hv-disconnected", out, keep)?;
    session.type_line("dti enable", out, keep)?;
    session.run(32_100, out, keep)
}

fn ccm_dti_still_enabled(out: &mut dyn Write) -> fmt::Result {
    // The DTI's CAN timeout left disabled in its tool: it keeps its drive enabled.
    let mut session = ccm_on_the_car();
    session.sim().dti = Some(SimDti {
        timeout_ms: None,
        ..SimDti::AT_REST
    });
    session.skip(30_250)?;
    let keep = Keep::Starting(&["> ", "refused", "t=", "CAN2 (inverter) DTI"]);
    session.type_line("confirm hv-disconnected", out, keep)?;
    session.type_line("dti enable", out, keep)?;
    session.run(33_400, out, keep)
}

fn ccm_panic_test(out: &mut dyn Write) -> fmt::Result {
    let mut session = ccm();
    session.skip(30_250)?;
    session.type_line("panic test", out, EXCHANGE)
}

/// The frames the CCM's panic handler sends the DTI, as `candump can0` shows them on the
/// inverter bus.
fn ccm_panic_frames(out: &mut dyn Write) -> fmt::Result {
    let stop = aer_ccm::stop::StopFrames::new();
    if let Ok(frames) = aer_ccm::console::dti::EnableTest::disable_frames() {
        stop.publish(&frames);
    }
    // Queued at once in separate mailboxes, they leave in arbitration order: lowest identifier
    // first.
    let latest = stop.latest();
    let mut frames: [Option<&_>; 8] = [None; 8];
    for (slot, frame) in frames.iter_mut().zip(latest.iter()) {
        *slot = Some(frame);
    }
    frames.sort_unstable_by_key(|frame| frame.map_or(u32::MAX, |frame| frame.id));
    for frame in frames.iter().flatten() {
        write!(out, "  can0  {:08X}   [{}] ", frame.id, frame.data().len())?;
        for byte in frame.data() {
            write!(out, " {byte:02X}")?;
        }
        writeln!(out)?;
    }
    Ok(())
}

fn ccm_dti_refused(out: &mut dyn Write) -> fmt::Result {
    // The DTI's logic not powered: nothing on the inverter bus.
    let mut session = ccm();
    session.skip(30_250)?;
    session.type_line("confirm hv-disconnected", out, EXCHANGE)?;
    // High voltage on the DTI's DC link while the PCC precharges.
    let sim = session.sim();
    sim.buses = [Some(ACTIVE); 2];
    sim.dti = Some(SimDti {
        dc_link_v: 36,
        ..SimDti::AT_REST
    });
    sim.pcc = Some(PrechargeState::Precharge);
    session.skip(31_250)?;
    session.sim().dti = Some(SimDti {
        dc_link_v: 344,
        ..SimDti::AT_REST
    });
    session.skip(31_500)?;
    for line in [
        "confirm hv-disconnected",
        "dti enable",
        "confirm wheels-off-ground",
        "dti enable",
    ] {
        session.type_line(line, out, EXCHANGE)?;
    }
    Ok(())
}

fn ccm_dti_hv(out: &mut dyn Write) -> fmt::Result {
    let mut session = ccm_on_the_car();
    let sim = session.sim();
    sim.pcc = Some(PrechargeState::Online);
    sim.dti = Some(SimDti {
        dc_link_v: 392,
        ..SimDti::AT_REST
    });
    session.skip(50_250)?;
    let keep = Keep::Starting(&["> ", "refused", "t="]);
    session.type_line("confirm wheels-off-ground", out, keep)?;
    session.type_line("dti enable", out, keep)?;
    session.run(52_100, out, keep)?;
    // Again, and the shutdown circuit opens mid-test: the PCC reports ERROR.
    session.type_line("dti enable", out, keep)?;
    session.run(52_500, out, keep)?;
    session.sim().pcc = Some(PrechargeState::Error);
    session.run(52_700, out, keep)
}

fn pcc_bringup_startup(out: &mut dyn Write) -> fmt::Result {
    let mut log = LogBuffer::<{ pcc_console::BRINGUP_LOG_BYTES }>::new();
    pcc_console::bringup_startup(
        &mut log,
        &aer_boards::pcc::COMP_CAR,
        POWER_ON,
        BoardCheck::passed("AER PCC bring-up", Teensy::T40),
    );
    flush(&mut log, out)
}

/// The PCC bring-up image with the bench supply at `volts` on each converter's sense input
/// (`None`: that converter unplugged) and a CAN adapter sending the BMS's frame.
fn pcc(volts: [Option<f32>; 2]) -> PccSession {
    let mut sim = SimPcc::new();
    for (input, volts) in sim.inputs.iter_mut().zip(volts) {
        input.pulses = volts.map_or(Pulses::None, Pulses::volts);
    }
    sim.bms = true;
    PccSession::new(sim)
}

fn pcc_report_bench_supply(out: &mut dyn Write) -> fmt::Result {
    // 30.0 V from a bench supply on the accumulator sense input; nothing on the tractive one.
    let mut session = pcc([Some(30.0), None]);
    session.skip(14_990)?;
    session.run(15_000, out, Keep::All)
}

fn pcc_confirm_silent(out: &mut dyn Write) -> fmt::Result {
    // Both converters unplugged (or broken): no pulses, so no reading.
    let mut session = pcc([None, None]);
    session.skip(5_250)?;
    session.type_line("confirm hv-disconnected", out, EXCHANGE)?;
    // The refused output names the step that is missing in its own line first.
    let keep = Keep::Starting(&["> ", "refused", "t=", "pin 11"]);
    session.type_line("out air-plus-close on", out, keep)
}

fn pcc_confirm_refused(out: &mut dyn Write) -> fmt::Result {
    let mut session = pcc([Some(388.2), Some(24.0)]);
    session.skip(5_250)?;
    session.type_line("confirm hv-disconnected", out, EXCHANGE)
}

fn pcc_air_plus(out: &mut dyn Write) -> fmt::Result {
    // Step 6c: the bench supply (24 V) on both sense inputs.
    let mut session = pcc([Some(24.0), Some(24.0)]);
    session.skip(8_250)?;
    session.type_line("confirm hv-disconnected", out, EXCHANGE)?;
    session.type_line("out air-plus-close on", out, EXCHANGE)?;
    // The generator on the tractive input swept up from 24 V's frequency to 750 Hz (63.5 V)
    // over 2 s, as a voltage rises: AIR+ drops at the first step that reads 60 V or more. (A
    // step change of frequency reads as an irregular window, silence, not a voltage.)
    session.run(9_500, out, EXCHANGE)?;
    session.sim().inputs[1].pulses = Pulses::Sweep {
        from_hz: CONVERTERS[1].hz_for_volts(24.0),
        to_hz: 750.0,
        start_ms: 9_500,
        duration_ms: 2_000,
    };
    session.run(11_750, out, EXCHANGE)?;
    session.sim().inputs[1].pulses = Pulses::volts(24.0);
    session.run(12_000, out, EXCHANGE)?;
    session.type_line("confirm hv-disconnected", out, EXCHANGE)?;
    session.type_line("out air-plus-close on", out, EXCHANGE)?;
    // The generator switched off: pin 15 silent after eight of its periods, AIR+ drops.
    session.run(13_000, out, EXCHANGE)?;
    session.sim().inputs[1].pulses = Pulses::None;
    session.run(13_500, out, EXCHANGE)
}

fn pcc_generator_frequencies(out: &mut dyn Write) -> fmt::Result {
    // Each converter's own scaling, as the images read it (`CONVERTERS`, step 6b).
    let [accumulator, tractive] = CONVERTERS;
    writeln!(out, "volts at the input  Hz at pin 14  Hz at pin 15")?;
    for volts in [24.0f32, 30.0, 60.0, 63.5, 100.0, 200.0, 300.0, 400.0] {
        writeln!(
            out,
            "{volts:>17.1}  {:>12.1}  {:>12.1}",
            accumulator.hz_for_volts(volts),
            tractive.hz_for_volts(volts)
        )?;
    }
    Ok(())
}

fn pcc_bms_heartbeat(out: &mut dyn Write) -> fmt::Result {
    let limits = OrionLimits {
        orion_pack_dcl: 300,
        orion_pack_ccl: 50,
        orion_high_temperature: 25,
        orion_low_temperature: 24,
    };
    let mut data = [0u8; 8];
    let len = limits
        .encode(&mut data)
        .map_err(|_| fmt::Error)?
        .min(data.len());
    write!(out, "cansend can0 {:03X}#", OrionLimits::ID)?;
    for byte in data.get(..len).unwrap_or(&[]) {
        write!(out, "{byte:02X}")?;
    }
    writeln!(out)
}

fn pcc_race_startup(out: &mut dyn Write) -> fmt::Result {
    let mut log = LogBuffer::<{ pcc_console::LOG_BYTES }>::new();
    pcc_console::race_startup(
        &mut log,
        &aer_boards::pcc::COMP_CAR,
        POWER_ON,
        BoardCheck::passed("AER PCC", Teensy::T40),
    );
    flush(&mut log, out)
}

/// The race PCC on the bench: its control task every 10 ms, the V/F inputs from signal
/// generators through the image's measurement chain (edges time-stamped, `VoltageChannel`),
/// the BMS's frame from a CAN adapter every 100 ms, the log the image keeps.
struct RacePcc {
    pcc: Precharge,
    channels: [VoltageChannel; 2],
    inputs: [PulseTrain; 2],
    race_log: RaceLog,
    log: LogBuffer<{ pcc_console::LOG_BYTES }>,
    now_ms: u32,
    relays: Relays,
    /// The BMS's frames are heard from this time on.
    bms_from_ms: u32,
    /// What the thermistors read (degC; `None`: open).
    resistor_c: [Option<f32>; 2],
}

impl RacePcc {
    fn new(pcc: Precharge) -> Self {
        Self {
            pcc,
            channels: CONVERTERS.map(|vf| VoltageChannel::new(vf, TASK_PERIOD_MS)),
            inputs: [PulseTrain::new(); 2],
            race_log: RaceLog::default(),
            log: LogBuffer::new(),
            now_ms: 0,
            relays: Relays::ALL_OPEN,
            bms_from_ms: 0,
            resistor_c: [Some(24.0), Some(24.5)],
        }
    }

    /// Runs the control task up to `until_ms`; with `out`, what it logs is the transcript.
    fn run(&mut self, until_ms: u32, mut out: Option<&mut dyn Write>) -> fmt::Result {
        while self.now_ms < until_ms {
            self.step();
            if let Some(out) = out.as_mut() {
                flush(&mut self.log, &mut **out)?;
            } else {
                self.log.consume(self.log.len());
            }
        }
        Ok(())
    }

    fn step(&mut self) {
        let now_ms = self.now_ms;
        let now_us = now_ms.wrapping_mul(1_000);
        let [accumulator, tractive] = self
            .channels
            .each_mut()
            .map(|channel| channel.sample(now_us));
        let inputs = Inputs {
            now_ms,
            accumulator_v: accumulator.volts,
            tractive_v: tractive.volts,
            raw_v: [accumulator.raw_volts, tractive.raw_volts],
            pulses: [accumulator.pulses, tractive.pulses],
            bms_last_seen_ms: (now_ms >= self.bms_from_ms).then_some(now_ms - now_ms % 100),
            charger_safety: false,
            resistor_c: self.resistor_c,
        };
        self.relays = self.pcc.step(&inputs);
        self.race_log
            .changes(now_ms, &self.pcc, self.relays, &mut self.log);
        if RaceLog::counters_due(now_ms) {
            let dropped = self.log.dropped();
            let [accumulator, tractive] = ConverterVolts::of(&self.pcc);
            self.log.line(format_args!(
                "{}",
                CountersLine {
                    now_ms,
                    accumulator,
                    tractive,
                    resistor: self.pcc.resistor_c().map(ResistorTemperature),
                    bus: ACTIVE,
                    rx_queue_overflows: 0,
                    status_not_sent: 0,
                    log_dropped: dropped,
                }
            ));
        }
        // The next period's edges.
        for ms in now_ms..now_ms + TASK_PERIOD_MS {
            for (input, channel) in self.inputs.iter_mut().zip(self.channels.iter_mut()) {
                input.slice(u64::from(ms) * 1_000, |at_us| channel.on_edge(at_us as u32));
            }
        }
        self.now_ms += TASK_PERIOD_MS;
    }

    /// Fails the transcript unless the PCC is in `state` now: a scenario that injects its
    /// fault into the wrong state documents the wrong thing.
    fn expect(&self, state: State) -> fmt::Result {
        if self.pcc.state() == state {
            Ok(())
        } else {
            Err(fmt::Error)
        }
    }

    /// The race image's answer to `reboot` now.
    fn ask(&mut self, reboot: Reboot) {
        let outcome = match reboot {
            Reboot::Restart => self.pcc.restart(),
            Reboot::Bootloader => self.pcc.handover(),
        }
        .map(|_| ());
        let answer = RebootAnswer { reboot, outcome };
        self.log.line(format_args!("t={} ms {answer}", self.now_ms));
    }
}

/// Pin 14 at 300 V; pin 15 swept from 0 to 300 V's frequency over 9.9 s from 5 s on: the
/// precharge the race PCC sees on the bench.
fn precharging() -> RacePcc {
    let mut pcc = RacePcc::new(Precharge::new(PrechargeConfig::CAR, 0));
    let [accumulator, tractive] = CONVERTERS;
    pcc.inputs[0].pulses = Pulses::Hz(accumulator.hz_for_volts(300.0));
    pcc.inputs[1].pulses = Pulses::Sweep {
        from_hz: 0.0,
        to_hz: tractive.hz_for_volts(300.0),
        start_ms: 5_000,
        duration_ms: 9_900,
    };
    pcc
}

fn pcc_race_precharge(out: &mut dyn Write) -> fmt::Result {
    precharging().run(15_000, Some(out))
}

fn pcc_race_missed(out: &mut dyn Write) -> fmt::Result {
    // The BMS is silent until 17 s: the hardware precharges (5-14.9 s) with the PCC waiting.
    let mut pcc = precharging();
    pcc.bms_from_ms = 17_000;
    pcc.run(17_500, Some(&mut *out))?;
    // The shutdown circuit opens: the tractive system discharges.
    pcc.inputs[1].pulses = Pulses::Sweep {
        from_hz: CONVERTERS[1].hz_for_volts(300.0),
        to_hz: 0.0,
        start_ms: 17_500,
        duration_ms: 600,
    };
    pcc.run(18_500, Some(out))
}

/// Pin 15's generator stands for the tractive system discharging after the AIRs opened: from
/// `from_v` down to `to_v` over `duration_ms`, starting at `start_ms`.
fn discharging(from_v: f32, to_v: f32, start_ms: u32, duration_ms: u32) -> Pulses {
    let tractive = CONVERTERS[1];
    Pulses::Sweep {
        from_hz: tractive.hz_for_volts(from_v),
        to_hz: tractive.hz_for_volts(to_v),
        start_ms,
        duration_ms,
    }
}

fn pcc_race_shutdown(out: &mut dyn Write) -> fmt::Result {
    let mut pcc = precharging();
    pcc.run(19_990, None)?;
    pcc.expect(State::Online)?;
    // The shutdown circuit opens: the tractive system discharges (pin 15 swept down to 0 Hz
    // over 0.6 s, as a 0.3 s discharge time constant does).
    pcc.inputs[1].pulses = discharging(300.0, 0.0, 19_990, 600);
    pcc.run(21_000, Some(out))
}

fn pcc_race_converter_silent(out: &mut dyn Write) -> fmt::Result {
    let mut pcc = precharging();
    pcc.run(19_990, None)?;
    pcc.expect(State::Online)?;
    // ONLINE at 300 V, the tractive converter's wire breaks: its pulses stop at once.
    pcc.inputs[1].pulses = Pulses::None;
    pcc.run(20_500, Some(&mut *out))?;
    pcc.ask(Reboot::Bootloader);
    flush(&mut pcc.log, &mut *out)?;
    // The wire touches again: pulses at 300 V; nothing restarts by itself.
    pcc.inputs[1].pulses = Pulses::volts(300.0);
    pcc.run(25_000, Some(&mut *out))?;
    pcc.ask(Reboot::Restart);
    flush(&mut pcc.log, out)
}

fn pcc_race_no_discharge(out: &mut dyn Write) -> fmt::Result {
    let mut pcc = precharging();
    pcc.run(19_990, None)?;
    pcc.expect(State::Online)?;
    // The shutdown circuit opens but the tractive system only sags to 150 V and stays there:
    // the discharge circuit does not work (or an AIR is welded).
    pcc.inputs[1].pulses = discharging(300.0, 150.0, 19_990, 2_000);
    pcc.run(25_700, Some(&mut *out))?;
    pcc.ask(Reboot::Bootloader);
    flush(&mut pcc.log, out)
}

fn pcc_race_bypassed(out: &mut dyn Write) -> fmt::Result {
    // The pack at 300 V, and the tractive system jumping to it when the shutdown circuit
    // closes at 5 s: AIR+ welded (or the precharge resistor bypassed).
    let mut pcc = RacePcc::new(Precharge::new(PrechargeConfig::CAR, 0));
    let [accumulator, tractive] = CONVERTERS;
    pcc.inputs[0].pulses = Pulses::Hz(accumulator.hz_for_volts(300.0));
    pcc.inputs[1].pulses = Pulses::Sweep {
        from_hz: 0.0,
        to_hz: tractive.hz_for_volts(300.0),
        start_ms: 5_000,
        duration_ms: 1,
    };
    pcc.run(4_990, None)?;
    pcc.run(5_200, Some(out))
}

fn pcc_race_status(out: &mut dyn Write) -> fmt::Result {
    let mut pcc = precharging();
    pcc.run(19_990, None)?;
    pcc.expect(State::Online)?;
    pcc.inputs[1].pulses = Pulses::None;
    pcc.run(20_500, None)?;
    pcc.race_log
        .status(pcc.now_ms, &pcc.pcc, pcc.relays, &mut pcc.log);
    flush_without_assumed(&mut pcc.log, out)
}

fn ccm_race_status(out: &mut dyn Write) -> fmt::Result {
    // The race CCM standing with the PCC in ERROR: its tractive converter fell silent.
    let mut data = [0u8; 8];
    data[0] = PrechargeState::Error.into_raw();
    data[1] = 0x20;
    let pcc = aer::can::PccStatus::decode(&data).ok();
    let mut faults = aer_ccm::faults::FaultMap::default();
    faults.set(aer_ccm::faults::Fault::PccError, true);
    let mut log = LogBuffer::<{ ccm_console::LOG_BYTES }>::new();
    let line = ccm_console::StatusLine {
        now_ms: 64_210,
        state: aer_ccm::vehicle::State::Standby,
        faults,
        pcc: ccm_console::PccLine(pcc),
    };
    log.line(format_args!("{line}"));
    aer_console::bringup::write_assumed(&mut log, aer_boards::assumed::Board::Ccm);
    flush_without_assumed(&mut log, out)
}

fn ccm_wrong_board(out: &mut dyn Write) -> fmt::Result {
    wrong_board("AER CCM DTI", Teensy::T41, Teensy::T40, out)
}

fn pcc_wrong_board(out: &mut dyn Write) -> fmt::Result {
    wrong_board("AER PCC", Teensy::T40, Teensy::T41, out)
}

/// What an image flashed onto the other board shows: its port's name, then the line it
/// repeats every 5 s.
fn wrong_board(
    image: &'static str,
    built_for: Teensy,
    found: Teensy,
    out: &mut dyn Write,
) -> fmt::Result {
    let check = BoardCheck {
        image,
        built_for,
        found: Some(found),
    };
    let mut name = [0u8; 64];
    let mut len = 0;
    for byte in check.wrong_board_product().bytes() {
        if let Some(slot) = name.get_mut(len) {
            *slot = if byte == b' ' { b'_' } else { byte };
            len += 1;
        }
    }
    let product = core::str::from_utf8(name.get(..len).unwrap_or(&[])).unwrap_or("");
    writeln!(
        out,
        "/dev/serial/by-id/usb-AER_{product}_<16 hex digits>-if00"
    )?;
    writeln!(out, "{check}")
}

fn pcc_bootloader(out: &mut dyn Write) -> fmt::Result {
    let mut pcc = precharging();
    pcc.run(15_000, None)?;
    pcc.ask(Reboot::Bootloader);
    flush(&mut pcc.log, out)?;
    // The shutdown circuit opens; asked while the tractive system discharges, and once it
    // is discharged.
    pcc.inputs[1].pulses = Pulses::Sweep {
        from_hz: CONVERTERS[1].hz_for_volts(300.0),
        to_hz: 0.0,
        start_ms: 15_000,
        duration_ms: 600,
    };
    pcc.run(15_300, None)?;
    pcc.ask(Reboot::Bootloader);
    flush(&mut pcc.log, out)?;
    pcc.run(19_000, None)?;
    pcc.ask(Reboot::Bootloader);
    pcc.ask(Reboot::Restart);
    flush(&mut pcc.log, out)
}

fn pcc_race_watchdog(out: &mut dyn Write) -> fmt::Result {
    let config = PrechargeConfig::CAR;
    // The PCC hung and its watchdog restarted it: ERROR, latched.
    let mut pcc = RacePcc::new(Precharge::after_watchdog_reset(config, 0));
    pcc_console::race_startup(
        &mut pcc.log,
        &aer_boards::pcc::COMP_CAR,
        WATCHDOG,
        BoardCheck::passed("AER PCC", Teensy::T40),
    );
    flush_without_assumed(&mut pcc.log, &mut *out)?;
    pcc.run(7_000, Some(&mut *out))?;
    pcc.ask(Reboot::Restart);
    flush(&mut pcc.log, out)?;
    // The software reset starts it as a power cycle does.
    let mut pcc = RacePcc::new(Precharge::new(config, 0));
    pcc_console::race_startup(
        &mut pcc.log,
        &aer_boards::pcc::COMP_CAR,
        SOFTWARE,
        BoardCheck::passed("AER PCC", Teensy::T40),
    );
    flush_without_assumed(&mut pcc.log, &mut *out)?;
    pcc.run(10, Some(out))
}
