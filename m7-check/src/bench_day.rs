//! The bench day's console transcripts: what a good board prints at each step of
//! docs/bench-day.md, built by the same library code the images call (`aer_ccm::console`,
//! `aer_pcc::console`, `aer_console::bringup`) and passed through the images' log buffer.
//! `cargo xtask m7-check` prints them from QEMU's Cortex-M7 and requires the host's to be the
//! same; `tests/bench_day_doc.rs` requires docs/bench-day.md to quote them exactly.

use aer::can::{
    DtiAcLimits, DtiControl, DtiCurrents, DtiDcLimits, DtiDriveEnable, DtiFlags, DtiFocCurrents,
    DtiSpeed, DtiTemperatures, OrionCellVoltages, OrionLimits, OrionPackStatus, PccStatus,
};
use aer_boards::Mode;
use aer_ccm::InverterKind;
use aer_ccm::calibration::{BenchPoint, BenchRecorder};
use aer_ccm::console::bringup::{self, Report};
use aer_ccm::console::dti::DtiBench;
use aer_ccm::console::{self as ccm_console, BootloaderAnswer};
use aer_ccm::constants::DTI_ASSUMED_COMMAND_TIMEOUT_MS;
use aer_ccm::control::HandoverRefusal;
use aer_console::LogBuffer;
use aer_console::bringup::{
    AnalogReading, BusLine, DigitalReading, Heard, HvGate, HvReadings, ReportHeader, ResetCause,
    SelfTestLine,
};
use aer_flexcan::{BusStatus, FaultState};
use aer_pcc::console::{self as pcc_console, BringupReport, StateLine, VfReading};
use aer_pcc::{Inputs, Precharge, PrechargeConfig, VfConfig};
use core::fmt::{self, Write};

/// A named transcript.
pub type Example = (&'static str, fn(&mut dyn Write) -> fmt::Result);

/// Every transcript docs/bench-day.md quotes, by the name its marker gives.
pub const EXAMPLES: [Example; 16] = [
    ("ccm-bringup-startup", ccm_bringup_startup),
    ("ccm-report-alone", ccm_report_alone),
    ("ccm-can-self-test", ccm_can_self_test),
    ("ccm-report-on-the-car", ccm_report_on_the_car),
    ("ccm-calibration", ccm_calibration),
    ("ccm-dti-timeout", ccm_dti_timeout),
    ("ccm-race-startup", ccm_race_startup),
    ("ccm-bootloader", ccm_bootloader),
    ("pcc-bringup-startup", pcc_bringup_startup),
    ("pcc-report-bench-supply", pcc_report_bench_supply),
    ("pcc-confirm-refused", pcc_confirm_refused),
    ("pcc-generator-frequencies", pcc_generator_frequencies),
    ("pcc-bms-heartbeat", pcc_bms_heartbeat),
    ("pcc-race-startup", pcc_race_startup),
    ("pcc-race-precharge", pcc_race_precharge),
    ("pcc-bootloader", pcc_bootloader),
];

/// Writes every transcript, each under a `--- bench-day <name>` line.
pub fn transcripts(out: &mut impl Write) -> fmt::Result {
    for (name, example) in EXAMPLES {
        writeln!(out, "--- bench-day {name}")?;
        example(out)?;
    }
    Ok(())
}

/// The log as the images keep it: lines queue here, then go to `out` as the host reads them.
struct Console {
    log: LogBuffer<{ bringup::LOG_BYTES }>,
}

impl Console {
    fn new() -> Self {
        Self {
            log: LogBuffer::new(),
        }
    }

    /// Copies every queued line to `out` (without the line ends) and checks none was dropped.
    fn flush(&mut self, out: &mut dyn Write) -> fmt::Result {
        let mut chunk = [0u8; 64];
        let mut line = heapless_line::Line::new();
        loop {
            let count = self.log.peek(&mut chunk);
            if count == 0 {
                break;
            }
            for &byte in chunk.get(..count).unwrap_or(&[]) {
                if byte == b'\n' {
                    writeln!(out, "{}", line.as_str())?;
                    line.clear();
                } else if byte != b'\r' {
                    line.push(byte);
                }
            }
            self.log.consume(count);
        }
        if self.log.dropped() > 0 {
            writeln!(out, "(log dropped {} lines)", self.log.dropped())?;
        }
        Ok(())
    }
}

/// A line being gathered from the log's bytes, without an allocator.
mod heapless_line {
    /// Up to 512 bytes of one line.
    pub struct Line {
        bytes: [u8; 512],
        len: usize,
    }

    impl Line {
        pub const fn new() -> Self {
            Self {
                bytes: [0; 512],
                len: 0,
            }
        }

        pub fn push(&mut self, byte: u8) {
            if let Some(slot) = self.bytes.get_mut(self.len) {
                *slot = byte;
                self.len += 1;
            }
        }

        pub fn clear(&mut self) {
            self.len = 0;
        }

        pub fn as_str(&self) -> &str {
            core::str::from_utf8(self.bytes.get(..self.len).unwrap_or(&[])).unwrap_or("(not text)")
        }
    }
}

const POWER_ON: ResetCause = ResetCause(0x1);

const ACTIVE: BusStatus = BusStatus {
    state: FaultState::ErrorActive,
    tx_errors: 0,
    rx_errors: 0,
    rx_fifo_overflows: 0,
    bus_off_events: 0,
    tx_dropped: 0,
};

/// A board alone on its bus after `can`: its heartbeats go unacknowledged.
const ALONE: BusStatus = BusStatus {
    state: FaultState::ErrorPassive,
    tx_errors: 128,
    ..ACTIVE
};

/// The 12-bit ADC counts for `volts` at a sensor behind `divider`.
fn counts_for(volts: f32, divider: f32) -> u16 {
    (volts / divider / 3.3 * 4_095.0 + 0.5) as u16
}

/// The CCM's analog inputs at rest: pedal released, brakes released, shocks extended, the
/// thermistor at room temperature.
fn ccm_analog_at_rest() -> [AnalogReading; 9] {
    let board = aer_boards::ccm::COMP_CAR;
    let divider = board.adc_divider;
    let rest_volts = |signal: &str| match signal {
        "apps1" => 0.52,
        "apps2" => 0.77,
        "bse1" | "bse2" => 0.51,
        "thermistor1" => 2.45,
        _ => 4.98,
    };
    let mut readings = [AnalogReading {
        pin: board.led,
        counts: 0,
        divider,
    }; 9];
    let analog = board
        .pins()
        .into_iter()
        .filter(|pin| matches!(pin.mode, Mode::Analog(_)));
    for (slot, pin) in readings.iter_mut().zip(analog) {
        *slot = AnalogReading {
            pin,
            counts: counts_for(rest_volts(pin.signal), divider),
            divider,
        };
    }
    readings
}

fn ccm_digital_at_rest() -> [DigitalReading; 4] {
    let board = aer_boards::ccm::COMP_CAR;
    let [wheel1, wheel2] = board.wheel_speed;
    [
        (wheel1, true),
        (wheel2, true),
        (board.ready_to_move, false),
        (board.launch, false),
    ]
    .map(|(pin, high)| DigitalReading {
        pin,
        high,
        edges: 0,
        hz: 0.0,
    })
}

fn ccm_bringup_startup(out: &mut dyn Write) -> fmt::Result {
    let mut console = Console::new();
    bringup::startup(&mut console.log, &aer_boards::ccm::COMP_CAR, POWER_ON);
    console.flush(out)
}

fn ccm_report(
    out: &mut dyn Write,
    now_ms: u32,
    buses: [(BusStatus, Heard); 2],
    dti: &DtiBench,
) -> fmt::Result {
    let mut console = Console::new();
    let analog = ccm_analog_at_rest();
    let digital = ccm_digital_at_rest();
    let [(vehicle, heard_vehicle), (inverter, heard_inverter)] = buses;
    Report {
        header: ReportHeader { now_ms, dropped: 0 },
        analog: &analog,
        ads1115: None,
        digital: &digital,
        buses: [
            BusLine {
                name: "CAN3 (vehicle)",
                status: Some(vehicle),
                heard: &heard_vehicle,
            },
            BusLine {
                name: "CAN2 (inverter)",
                status: Some(inverter),
                heard: &heard_inverter,
            },
        ],
        dti,
        brake_light: false,
    }
    .write(&mut console.log);
    console.flush(out)
}

fn ccm_report_alone(out: &mut dyn Write) -> fmt::Result {
    // The CCM's own heartbeats are not received back: nothing heard on either bus.
    let empty = Heard::default();
    ccm_report(
        out,
        12_004,
        [(ALONE, empty), (ALONE, empty)],
        &DtiBench::default(),
    )
}

fn ccm_can_self_test(out: &mut dyn Write) -> fmt::Result {
    let mut console = Console::new();
    for name in ["CAN3 (vehicle)", "CAN2 (inverter)"] {
        console.log.line(format_args!(
            "{}",
            SelfTestLine {
                name,
                result: Some(Ok(())),
            }
        ));
    }
    console.flush(out)
}

/// A second of frames: `count` of each id (its cycle time's worth).
fn heard(ids: &[(u32, u32)]) -> Heard {
    let mut heard = Heard::default();
    for &(id, cycle_ms) in ids {
        for _ in 0..1_000 / cycle_ms {
            heard.frame(id);
        }
    }
    heard
}

/// Packet 0x24 of a DTI at rest: CAN map 2.5 (25), every other field 0 (drive `enabled` or
/// not).
fn flags(enabled: bool) -> Result<DtiFlags, fmt::Error> {
    let mut data = [0u8; 8];
    if let Some(map) = data.get_mut(7) {
        *map = 25;
    }
    let flags = DtiFlags::decode(&data).map_err(|_| fmt::Error)?;
    Ok(DtiFlags {
        dti_drive_enabled: if enabled {
            DtiDriveEnable::Enabled
        } else {
            DtiDriveEnable::Disabled
        },
        ..flags
    })
}

/// One second of a DTI at rest on its bus, drive disabled, no fault, DC link at 0 V (low
/// voltage only): its status packets at their cycle times.
fn dti_second(dti: &mut DtiBench, start_ms: u32) -> fmt::Result {
    let mut data = [0u8; 8];
    for tick in 0..100u32 {
        let now = start_ms + tick * 10;
        flags(false)?.encode(&mut data).map_err(|_| fmt::Error)?;
        dti.frame(now, DtiFlags::ID, true, &data);
        let speed = DtiSpeed {
            dti_erpm: 0,
            dti_duty_cycle: 0.0,
            dti_input_voltage: 0,
        };
        speed.encode(&mut data).map_err(|_| fmt::Error)?;
        dti.frame(now, DtiSpeed::ID, true, &data);
        if tick % 10 == 0 {
            let temperatures = DtiTemperatures {
                dti_controller_temp: 24.5,
                dti_motor_temp: 23.0,
                dti_fault_code: aer::can::DtiFaultCode::None,
            };
            temperatures.encode(&mut data).map_err(|_| fmt::Error)?;
            dti.frame(now, DtiTemperatures::ID, true, &data);
        }
        dti.poll(now);
    }
    Ok(())
}

fn ccm_report_on_the_car(out: &mut dyn Write) -> fmt::Result {
    let vehicle = heard(&[
        (PccStatus::ID, PccStatus::CYCLE_TIME_MS),
        (OrionPackStatus::ID, OrionPackStatus::CYCLE_TIME_MS),
        (OrionLimits::ID, OrionLimits::CYCLE_TIME_MS),
        (OrionCellVoltages::ID, OrionCellVoltages::CYCLE_TIME_MS),
    ]);
    let inverter = heard(&[
        (DtiControl::ID, DtiControl::CYCLE_TIME_MS),
        (DtiSpeed::ID, DtiSpeed::CYCLE_TIME_MS),
        (DtiCurrents::ID, DtiCurrents::CYCLE_TIME_MS),
        (DtiTemperatures::ID, DtiTemperatures::CYCLE_TIME_MS),
        (DtiFocCurrents::ID, DtiFocCurrents::CYCLE_TIME_MS),
        (DtiFlags::ID, DtiFlags::CYCLE_TIME_MS),
        (DtiAcLimits::ID, DtiAcLimits::CYCLE_TIME_MS),
        (DtiDcLimits::ID, DtiDcLimits::CYCLE_TIME_MS),
    ]);
    let mut dti = DtiBench::default();
    dti_second(&mut dti, 20_000)?;
    ccm_report(out, 21_004, [(ACTIVE, vehicle), (ACTIVE, inverter)], &dti)
}

fn ccm_calibration(out: &mut dyn Write) -> fmt::Result {
    let mut console = Console::new();
    let mut recorder = BenchRecorder::default();
    let points = [
        (BenchPoint::Rest, [0.512f32, 0.771], [0.508f32, 0.514]),
        (BenchPoint::Full, [2.793, 4.187], [0.51, 0.52]),
    ];
    for (point, pedals, brakes) in points {
        recorder.start(point);
        let mut step = 0u32;
        while recorder.recording() {
            let wobble = (step % 7) as f32 * 0.000_5 - 0.001_5;
            recorder.sample(
                [Some(pedals[0] + wobble), Some(pedals[1] - wobble)],
                [brakes[0] + wobble, brakes[1] - wobble],
            );
            step += 1;
        }
        bringup::calibration(&mut console.log, &recorder);
    }
    console.flush(out)
}

fn ccm_dti_timeout(out: &mut dyn Write) -> fmt::Result {
    let mut console = Console::new();
    let mut dti = DtiBench::default();
    dti_second(&mut dti, 30_000)?;
    let mut gate = HvGate::new(60.0);
    let start = 31_000;
    let dc_link = [("DTI DC link", dti.dc_link_v(start))];
    gate.confirm(start, HvReadings { volts: &dc_link })
        .map_err(|_| fmt::Error)?;
    console.log.line(format_args!("{}", dti.timeout));
    // `dti enable`: the bring-up's commands every 10 ms for 1 s; a DTI that obeys them and
    // drops its drive enable the assumed timeout after the last one (status every 10 ms).
    dti.test.start(start);
    let mut last_command = None;
    for ms in 0..2_000u32 {
        let now = start + ms;
        if dti.due(now).is_some() {
            last_command = Some(now);
        }
        if ms % 10 == 5 {
            let enabled = last_command.is_some_and(|at| now - at <= DTI_ASSUMED_COMMAND_TIMEOUT_MS);
            let mut data = [0u8; 8];
            flags(enabled)?.encode(&mut data).map_err(|_| fmt::Error)?;
            dti.frame(now, DtiFlags::ID, true, &data);
        }
        dti.poll(now);
    }
    console.log.line(format_args!("{}", dti.timeout));
    console.flush(out)
}

fn ccm_race_startup(out: &mut dyn Write) -> fmt::Result {
    let mut console = Console::new();
    ccm_console::race_startup(
        &mut console.log,
        aer_boards::ccm::COMP_CAR.name,
        InverterKind::Dti,
        POWER_ON,
    );
    console.flush(out)
}

fn ccm_bootloader(out: &mut dyn Write) -> fmt::Result {
    let mut console = Console::new();
    for (now, answer) in [
        (84_310, BootloaderAnswer::Refused(HandoverRefusal::Driving)),
        (96_020, BootloaderAnswer::Obeyed),
    ] {
        console.log.line(format_args!("t={now} ms {answer}"));
    }
    console.flush(out)
}

fn pcc_bringup_startup(out: &mut dyn Write) -> fmt::Result {
    let mut console = Console::new();
    pcc_console::bringup_startup(&mut console.log, &aer_boards::pcc::COMP_CAR, POWER_ON);
    console.flush(out)
}

/// The PCC bring-up's report with `hz` on the accumulator and tractive-system inputs.
fn pcc_report(console: &mut Console, now_ms: u32, hz: [f32; 2]) {
    let board = aer_boards::pcc::COMP_CAR;
    let mut vf = board.voltage_freq.map(|pin| VfReading {
        input: DigitalReading {
            pin,
            high: false,
            edges: 0,
            hz: 0.0,
        },
        vf: VfConfig::PCC_BOARD,
    });
    let seconds = now_ms / 1_000;
    for (reading, hz) in vf.iter_mut().zip(hz) {
        reading.input.hz = hz;
        reading.input.edges = (hz * seconds as f32) as u32;
    }
    let thermistors = board.thermistors.map(|pin| AnalogReading {
        pin,
        counts: 2_048,
        divider: 1.0,
    });
    let mut heard = Heard::default();
    for _ in 0..10 {
        heard.frame(OrionLimits::ID);
    }
    BringupReport {
        header: ReportHeader { now_ms, dropped: 0 },
        vf,
        thermistors,
        bus: BusLine {
            name: "CAN2",
            status: Some(ACTIVE),
            heard: &heard,
        },
        air_plus: false,
    }
    .write(&mut console.log);
}

fn pcc_report_bench_supply(out: &mut dyn Write) -> fmt::Result {
    let mut console = Console::new();
    // 30.0 V from a bench supply on the accumulator sense input; nothing on the tractive one.
    pcc_report(
        &mut console,
        15_003,
        [VfConfig::PCC_BOARD.hz_for_volts(30.0), 0.0],
    );
    console.flush(out)
}

fn pcc_confirm_refused(out: &mut dyn Write) -> fmt::Result {
    let mut console = Console::new();
    let mut gate = HvGate::new(PrechargeConfig::CAR.discharged_v);
    let live = [
        ("accumulator (pin 14)", Some(388.2)),
        ("tractive system (pin 15)", Some(0.0)),
    ];
    if let Err(refusal) = gate.confirm(1_000, HvReadings { volts: &live }) {
        console.log.line(format_args!("refused: {refusal}"));
    }
    console.flush(out)
}

fn pcc_generator_frequencies(out: &mut dyn Write) -> fmt::Result {
    let vf = VfConfig::PCC_BOARD;
    writeln!(out, "volts at the input  Hz at pin 14 or 15")?;
    for volts in [30.0f32, 60.0, 100.0, 200.0, 300.0, 400.0] {
        writeln!(out, "{volts:>17.0}  {:>18.1}", vf.hz_for_volts(volts))?;
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
    let mut console = Console::new();
    pcc_console::race_startup(&mut console.log, &aer_boards::pcc::COMP_CAR, POWER_ON);
    console.flush(out)
}

/// The race PCC on the bench with a signal generator: pin 14 at 300 V's frequency, pin 15
/// swept linearly from 0 to the same frequency over 9.9 s, the BMS's frames from a CAN
/// adapter. Every line the race image logs on the way to ONLINE.
fn pcc_race_precharge(out: &mut dyn Write) -> fmt::Result {
    let mut console = Console::new();
    let config = PrechargeConfig::CAR;
    let mut pcc = Precharge::new(config, 0);
    let mut last = None;
    let mut last_timing = None;
    let sweep_start = 5_000u32;
    let sweep_ms = 9_900u32;
    for tick in 0..2_000u32 {
        let now_ms = tick * 10;
        let swept = now_ms.saturating_sub(sweep_start).min(sweep_ms) as f32 / sweep_ms as f32;
        let inputs = Inputs {
            now_ms,
            accumulator_v: 300.0,
            tractive_v: 300.0 * swept,
            bms_last_seen_ms: Some(now_ms - now_ms % 100),
            charger_safety: false,
        };
        let relays = pcc.step(&inputs);
        let now = (pcc.state(), pcc.errors());
        if last != Some(now) {
            last = Some(now);
            let line = StateLine {
                now_ms,
                state: now.0,
                relays,
                errors: now.1,
                accumulator_v: pcc.accumulator_v(),
                tractive_v: pcc.tractive_v(),
            };
            console.log.line(format_args!("{line}"));
        }
        if pcc.last_precharge() != last_timing {
            last_timing = pcc.last_precharge();
            if let Some(timing) = last_timing {
                console.log.line(format_args!("t={now_ms} ms {timing}"));
            }
        }
    }
    console.flush(out)
}

fn pcc_bootloader(out: &mut dyn Write) -> fmt::Result {
    let mut console = Console::new();
    let config = PrechargeConfig::CAR;
    let mut pcc = Precharge::new(config, 0);
    let mut inputs = Inputs {
        now_ms: 0,
        accumulator_v: 300.0,
        tractive_v: 0.0,
        bms_last_seen_ms: Some(0),
        charger_safety: false,
    };
    // Precharge to ONLINE in 8.8 s, then ask.
    for tick in 0..1_100u32 {
        inputs.now_ms = tick * 10;
        inputs.bms_last_seen_ms = Some(inputs.now_ms);
        inputs.tractive_v = (300.0 * inputs.now_ms as f32 / 9_500.0).min(300.0);
        pcc.step(&inputs);
    }
    let answer = |pcc: &Precharge| match pcc.handover() {
        Ok(_) => pcc_console::BootloaderAnswer::Obeyed,
        Err(why) => pcc_console::BootloaderAnswer::Refused(why),
    };
    console
        .log
        .line(format_args!("t={} ms {}", inputs.now_ms, answer(&pcc)));
    // The shutdown circuit opens: the tractive system falls away, ERROR, then below 60 V.
    for tick in 1_100..1_400u32 {
        inputs.now_ms = tick * 10;
        inputs.bms_last_seen_ms = Some(inputs.now_ms);
        inputs.tractive_v *= 0.97;
        pcc.step(&inputs);
        if tick == 1_130 {
            console
                .log
                .line(format_args!("t={} ms {}", inputs.now_ms, answer(&pcc)));
        }
    }
    console
        .log
        .line(format_args!("t={} ms {}", inputs.now_ms, answer(&pcc)));
    console.flush(out)
}
