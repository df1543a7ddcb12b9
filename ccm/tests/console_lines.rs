//! Every line the CCM's images print reaches the host: each is built from its worst case
//! (every counter at its maximum, every bus hearing as many ids as a report lists, every pin
//! of the board with its source) and the whole start-up plus a report must fit the image's
//! log at once, before the host reads anything, with no line dropped.

mod rig;

use aer_ccm::InverterKind;
use aer_ccm::calibration::store::{Slot, Startup};
use aer_ccm::calibration::{BenchPoint, BenchRecorder};
use aer_ccm::calibration::{BenchSample, ShockEnd};
use aer_ccm::console::bringup::{self, Report};
use aer_ccm::console::dti::DtiBench;
use aer_ccm::console::{self, CalibrationLine, RebootAnswer};
use aer_ccm::control::HandoverRefusal;
use aer_console::LogBuffer;
use aer_console::Reboot;
use aer_console::board_check::{BoardCheck, Teensy};
use aer_console::bringup::{
    AnalogReading, BusLine, DigitalReading, HEARD_IDS, Heard, ReportHeader, ResetCause,
};
use aer_flexcan::{BusStatus, FaultState};

/// Every queued line, in order.
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

fn busiest_bus() -> Heard {
    let mut heard = Heard::default();
    for index in 0..HEARD_IDS as u32 {
        heard.frame(0x1FFF_FF00 + index);
    }
    heard.frame(0x100);
    heard
}

const WORST_STATUS: BusStatus = BusStatus {
    state: FaultState::ErrorPassive,
    tx_errors: u8::MAX,
    rx_errors: u8::MAX,
    rx_fifo_overflows: u32::MAX,
    bus_off_events: u32::MAX,
    tx_dropped: u32::MAX,
};

fn worst_dti() -> DtiBench {
    let mut dti = DtiBench::default();
    let mut data = [0u8; 8];
    aer::can::DtiFlags {
        dti_can_map_version: u8::MAX,
        ..rig::dti_flags()
    }
    .encode(&mut data)
    .expect("encodes");
    dti.frame(0, aer::can::DtiFlags::ID, true, &data);
    dti.frame(0, (0x20 << 8) | 0x65, true, &data);
    dti
}

#[test]
fn the_bring_up_start_up_and_a_worst_case_report_fit_the_log_together() {
    for board in [aer_boards::ccm::COMP_CAR, aer_boards::ccm::COMP_CAR_ADS1115] {
        let mut log = LogBuffer::<{ bringup::LOG_BYTES }>::new();
        assert_eq!(
            bringup::startup(
                &mut log,
                &board,
                ResetCause(0x1FF),
                BoardCheck::passed("AER CCM bring-up", Teensy::T41)
            ),
            0
        );
        let pins = board.pins();
        let analog: Vec<AnalogReading> = pins
            .iter()
            .filter(|pin| matches!(pin.mode, aer_boards::Mode::Analog(_)))
            .map(|&pin| AnalogReading {
                pin,
                counts: u16::MAX,
                divider: board.adc_divider,
            })
            .collect();
        let digital: Vec<DigitalReading> = pins
            .iter()
            .filter(|pin| {
                matches!(
                    pin.mode,
                    aer_boards::Mode::InputPullUp | aer_boards::Mode::InputPullDown
                )
            })
            .map(|&pin| DigitalReading {
                pin,
                high: true,
                edges: u32::MAX,
                hz: 4.0e9,
            })
            .collect();
        let heard = busiest_bus();
        let dti = worst_dti();
        let report = Report {
            header: ReportHeader {
                now_ms: u32::MAX,
                dropped: u32::MAX,
                dropped_total: u32::MAX,
            },
            analog: &analog,
            ads1115: Some(([None, Some(-6.144)], u32::MAX)),
            digital: &digital,
            buses: [
                BusLine {
                    name: "CAN3 (vehicle)",
                    status: Some(WORST_STATUS),
                    heard: &heard,
                },
                BusLine {
                    name: "CAN2 (inverter)",
                    status: Some(WORST_STATUS),
                    heard: &Heard::default(),
                },
            ],
            dti: &dti,
            brake_light: true,
        };
        assert_eq!(report.write(&mut log), 0, "{}", board.name);
        let mut recorder = BenchRecorder::default();
        let worst = BenchSample {
            pedals: [Some(-1.0e9), Some(1.0e9)],
            brakes: [-1.0e9, 1.0e9],
            shocks: [-1.0e9; 4],
        };
        for point in [BenchPoint::Rest, BenchPoint::Full] {
            recorder.start(point);
            while recorder.sample(&worst).is_none() {}
        }
        assert_eq!(
            bringup::calibration(&mut log, &recorder, BenchPoint::Full),
            0
        );
        // The shocks' longest line: three sensors recorded, far out of range.
        recorder.start(BenchPoint::Shock {
            sensors: [true, true, true, false],
            end: ShockEnd::Extended,
        });
        while recorder.sample(&worst).is_none() {}
        let shock = BenchPoint::Shock {
            sensors: [true; 4],
            end: ShockEnd::Compressed,
        };
        assert_eq!(bringup::calibration(&mut log, &recorder, shock), 0);
        assert_eq!(log.dropped(), 0, "{}", board.name);
        let lines = drain(&mut log);
        // Start-up: name, reset cause, board check, clocks, every pin, the hint; the report;
        // the pedal result (refused: no file lines) and the shocks' line.
        let report_lines = 1 + analog.len() + 1 + digital.len() + 2 + 3;
        assert_eq!(lines.len(), 4 + pins.len() + 1 + report_lines + 2);
        let longest = lines.iter().map(String::len).max().unwrap_or(0);
        assert!(
            lines
                .iter()
                .any(|line| line.contains("0x1fffff07 x1, 1 more of other ids")),
            "every heard id is printed"
        );
        println!(
            "{}: {} lines, the longest {longest} bytes",
            board.name,
            lines.len()
        );
    }
}

#[test]
fn the_race_start_up_and_the_bootloader_answers_fit_the_race_log() {
    for inverter in [InverterKind::Dti, InverterKind::Ifl100] {
        let mut log = LogBuffer::<{ console::LOG_BYTES }>::new();
        let long_source = "x".repeat(200);
        assert_eq!(
            console::race_startup(
                &mut log,
                aer_boards::ccm::COMP_CAR.name,
                inverter,
                ResetCause(0x1FF),
                BoardCheck::passed("AER CCM", Teensy::T41),
                CalibrationLine {
                    startup: Startup::OtherSchema,
                    checksum: u32::MAX,
                    file_source: &long_source,
                },
            ),
            0
        );
        let saved = CalibrationLine {
            startup: Startup::Saved {
                slot: Slot::B,
                generation: u32::MAX,
            },
            checksum: 0,
            file_source: "",
        };
        assert!(log.line(format_args!("{saved}")));
        for reboot in [Reboot::Bootloader, Reboot::Restart] {
            for outcome in [
                Ok(()),
                Err(HandoverRefusal::Driving),
                Err(HandoverRefusal::TorqueCommanded {
                    torque_nm: f32::MAX,
                }),
            ] {
                let answer = RebootAnswer { reboot, outcome };
                assert!(log.line(format_args!("t={} ms {answer}", u32::MAX)));
            }
        }
        let lines = drain(&mut log);
        // Image, reset cause, board check, calibration, what is still assumed (a header and
        // each item); the saved line and the six answers.
        let assumed =
            aer_boards::assumed::Assumed::for_board(aer_boards::assumed::Board::Ccm).count();
        assert_eq!(lines.len(), 4 + 1 + assumed + 1 + 6);
        assert!(
            lines[0].starts_with(&format!("AER CCM for the {}", inverter.name())),
            "{}",
            lines[0]
        );
    }
}
