//! Every line the PCC's images print reaches the host: each is built from its worst case
//! (every counter at its maximum, the bus hearing as many ids as a report lists, every pin of
//! the board with its source, the longest pin source of all: pin 11's) and the start-up plus
//! a report must fit the image's log at once, before the host reads anything.

use aer_boards::assumed::{Assumed, Board as AssumedBoard};
use aer_boards::pcc::COMP_CAR;
use aer_console::LogBuffer;
use aer_console::Reboot;
use aer_console::board_check::{BoardCheck, Teensy};
use aer_console::bringup::{
    AnalogReading, BusLine, DigitalReading, HEARD_IDS, Heard, ReportHeader, ResetCause,
};
use aer_console::hv_gate::HvReading;
use aer_flexcan::{BusStatus, FaultState};
use aer_pcc::bringup::AirPlusBench;
use aer_pcc::console::{
    self, BringupReport, ConverterVolts, CountersLine, HotResistorLine, NoDischargeLine,
    RebootAnswer, ResistorTemperature, SilenceLine, StateLine, ThermistorReading, VfReading,
};
use aer_pcc::machine::{Converter, HotResistor, NoDischarge, Silence};
use aer_pcc::measurement::Pulses;
use aer_pcc::{Errors, HandoverRefusal, PrechargeTiming, Relays, State, VfConfig};

fn drain<const N: usize>(log: &mut LogBuffer<N>) -> Vec<String> {
    let mut bytes = vec![0u8; N];
    let count = log.peek(&mut bytes);
    log.consume(count);
    String::from_utf8(bytes[..count].to_vec())
        .expect("text")
        .split_terminator("\r\n")
        .map(String::from)
        .collect()
}

const WORST_STATUS: BusStatus = BusStatus {
    state: FaultState::BusOff,
    tx_errors: u8::MAX,
    rx_errors: u8::MAX,
    rx_fifo_overflows: u32::MAX,
    bus_off_events: u32::MAX,
    tx_dropped: u32::MAX,
};

#[test]
fn the_bring_up_start_up_and_a_worst_case_report_fit_the_log_together() {
    let mut log = LogBuffer::<{ console::BRINGUP_LOG_BYTES }>::new();
    assert_eq!(
        console::bringup_startup(
            &mut log,
            &COMP_CAR,
            ResetCause(0x1FF),
            BoardCheck::passed("AER PCC bring-up", Teensy::T40)
        ),
        0
    );
    let mut heard = Heard::default();
    for index in 0..=HEARD_IDS as u32 {
        heard.frame(0x1FFF_FF00 + index);
    }
    let vf = COMP_CAR.voltage_freq.map(|pin| VfReading {
        input: DigitalReading {
            pin,
            high: true,
            edges: u32::MAX,
            hz: 4.0e9,
        },
        vf: VfConfig::PCC_BOARD,
    });
    let thermistors = COMP_CAR.thermistors.map(|pin| AnalogReading {
        pin,
        counts: u16::MAX,
        divider: 1.0,
    });
    let report = BringupReport {
        header: ReportHeader {
            now_ms: u32::MAX,
            dropped: u32::MAX,
            dropped_total: u32::MAX,
        },
        vf,
        thermistors: thermistors.map(ThermistorReading),
        bus: BusLine {
            name: "CAN2",
            status: Some(WORST_STATUS),
            heard: &heard,
        },
        gate: worst_gate_line(),
    };
    assert_eq!(report.write(&mut log), 0);
    assert_eq!(log.dropped(), 0);
    let lines = drain(&mut log);
    // Image, reset cause, board check, clocks; the pins; the pin 11 line; the report.
    assert_eq!(lines.len(), 4 + COMP_CAR.pins().len() + 1 + 7);
    let pin_11 = lines
        .iter()
        .find(|line| line.starts_with("pin 11 air-plus-close"))
        .expect("pin 11's line, the longest, is printed");
    assert!(pin_11.len() > 192, "{} bytes", pin_11.len());
}

/// The gate's longest line: armed, then a converter silent (the refusal with the most text).
fn worst_gate_line() -> aer_pcc::bringup::GateLine {
    let mut gate = AirPlusBench::new();
    let alive = [HvReading::Volts {
        volts: 24.0,
        at_ms: 0,
    }; 2];
    gate.confirm(0, alive).expect("alive and low");
    let silent = [HvReading::Silent; 2];
    let implausible = [HvReading::Volts {
        volts: -f32::MAX,
        at_ms: 0,
    }; 2];
    let lines = [gate.line(0, silent), gate.line(0, implausible)];
    let longest = lines
        .iter()
        .max_by_key(|line| line.to_string().len())
        .copied();
    longest.expect("two lines")
}

#[test]
fn the_race_lines_fit_the_race_log() {
    let mut log = LogBuffer::<{ console::LOG_BYTES }>::new();
    assert_eq!(
        console::race_startup(
            &mut log,
            &COMP_CAR,
            ResetCause(0x1FF),
            BoardCheck::passed("AER PCC", Teensy::T40)
        ),
        0
    );
    let every_error = Errors {
        too_fast: true,
        too_slow: true,
        bms_timeout: true,
        shutdown: true,
        accumulator_silent: true,
        tractive_silent: true,
        no_discharge: true,
        undefined_state: true,
        bypassed: true,
        resistor_hot: true,
        air_plus_open: true,
        converters_disagree: true,
    };
    let worst_volts = ConverterVolts {
        volts: -f32::MAX,
        pulses: Pulses::Live,
    };
    let state = StateLine {
        now_ms: u32::MAX,
        state: State::Discharge,
        relays: Relays::ALL_OPEN,
        errors: every_error,
        accumulator: worst_volts,
        tractive: worst_volts,
    };
    let counters = CountersLine {
        now_ms: u32::MAX,
        accumulator: worst_volts,
        tractive: worst_volts,
        resistor: [ResistorTemperature(Some(-f32::MAX)); 2],
        bus: WORST_STATUS,
        rx_queue_overflows: u32::MAX,
        status_not_sent: u32::MAX,
        log_dropped: u32::MAX,
    };
    let timing = PrechargeTiming {
        attempt: u32::MAX,
        reached_ms: Some(u32::MAX),
        target_percent: u8::MAX,
        window_ms: (u32::MAX, u32::MAX),
        bypass_max_ms: 0,
    };
    let bypassed = PrechargeTiming {
        reached_ms: Some(0),
        bypass_max_ms: u32::MAX,
        ..timing
    };
    let silent = SilenceLine {
        now_ms: u32::MAX,
        silence: Silence {
            converter: Converter::Tractive,
            last_v: -f32::MAX,
            since_ms: u32::MAX,
        },
        discharged_v: -f32::MAX,
    };
    let no_discharge = NoDischargeLine {
        now_ms: u32::MAX,
        fault: NoDischarge {
            tractive_v: -f32::MAX,
            falling_since_ms: u32::MAX,
            limit_ms: u32::MAX,
        },
        discharged_v: -f32::MAX,
    };
    let hot = HotResistorLine {
        now_ms: u32::MAX,
        hot: HotResistor {
            thermistor: 2,
            celsius: -f32::MAX,
            limit_c: -f32::MAX,
        },
    };
    let converter_refusal = RebootAnswer {
        reboot: Reboot::Bootloader,
        outcome: Err(HandoverRefusal::ConverterFault {
            converter: Converter::Tractive,
            reading: Some(-f32::MAX),
            limit_v: -f32::MAX,
        }),
    };
    let refused = RebootAnswer {
        reboot: Reboot::Bootloader,
        outcome: Err(HandoverRefusal::Charged {
            tractive_v: f32::MAX,
            limit_v: f32::MAX,
        }),
    };
    let waiting = aer_pcc::console::WaitingLine {
        now_ms: u32::MAX,
        waiting: aer_pcc::Waiting {
            pack: true,
            bms: true,
            rise: true,
            discharge: true,
            live: true,
            resistor: true,
        },
        accumulator_v: -f32::MAX,
        pack_min_v: f32::MAX,
        discharged_v: f32::MAX,
        rest_percent: f32::MAX,
        bms_timeout_ms: u32::MAX,
    };
    assert!(log.line(format_args!("{state}")));
    assert!(log.line(format_args!("{waiting}")));
    // The other wording of the discharge: below 60 V, not at rest.
    let mut resting = waiting;
    resting.waiting.live = false;
    resting.accumulator_v = f32::MAX;
    assert!(log.line(format_args!("{resting}")));
    assert!(log.line(format_args!("{counters}")));
    assert!(log.line(format_args!("t={} ms {timing}", u32::MAX)));
    assert!(log.line(format_args!("t={} ms {refused}", u32::MAX)));
    assert_eq!(log.dropped(), 0);
    // Image, reset cause, board check, then what is still assumed (a header and each item).
    let assumed = Assumed::for_board(AssumedBoard::Pcc).count();
    assert_eq!(drain(&mut log).len(), 3 + 1 + assumed + 6);
    // The fault lines, each at its worst, fit the log at once as well.
    for line in [
        format!("t={} ms {bypassed}", u32::MAX),
        silent.to_string(),
        no_discharge.to_string(),
        hot.to_string(),
        format!("t={} ms {converter_refusal}", u32::MAX),
    ] {
        assert!(line.len() < 600, "{} bytes: {line}", line.len());
        assert!(log.line(format_args!("{line}")));
    }
    assert_eq!(log.dropped(), 0);
}
