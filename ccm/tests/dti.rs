//! The comp car's DTI HV-550 as the CCM drives it: the frames it sends (checked by decoding
//! them with the generated codec), what it reads from the DTI's status, and the faults the
//! DTI's own reports raise.

mod rig;

use aer::can::{
    AnyMessage, DtiDriveEnable, DtiSetCurrent, DtiSetDriveEnable, DtiSetMaxBrakeCurrentDc,
    DtiSetMaxCurrentDc,
};
use aer_ccm::constants::{DTI_ENABLE_MISMATCH_MS, MOTOR_TORQUE_PER_PEAK_A};
use aer_ccm::faults::Fault;
use aer_ccm::inverter::{DriveCommand, dti};
use aer_ccm::vehicle::State;
use aer_ccm::{InverterKind, OutFrame};
use embedded_can::Frame;
use rig::{Rig, Tick, dti_flags};

const NODE_ID: u32 = 0x41;

fn command(torque_nm: f32, drive: bool) -> DriveCommand {
    DriveCommand {
        torque_nm,
        drive,
        main_relay: true,
        precharging: false,
        brakes_engaged: false,
        discharge_limit_a: 250.0,
    }
}

fn decode(frame: &OutFrame) -> AnyMessage {
    assert!(frame.extended, "DTI commands use 29-bit ids");
    assert_eq!(frame.id & 0xFF, NODE_ID, "the node id is the low byte");
    AnyMessage::decode(frame.id, true, frame.data()).expect("decodes")
}

/// The period's frames as (current A, drive enable, DC limit A, DC brake limit A).
fn sent(command: &DriveCommand) -> (f64, DtiDriveEnable, f64, f64) {
    let (_, frames) = dti::frames(command).expect("encodes");
    assert_eq!(frames.len(), 4);
    let mut current = None;
    let mut enable = None;
    let mut dc = None;
    let mut brake = None;
    for frame in frames.iter() {
        match decode(frame) {
            AnyMessage::DtiSetCurrent(DtiSetCurrent { dti_current_cmd }) => {
                current = Some(dti_current_cmd);
            }
            AnyMessage::DtiSetDriveEnable(DtiSetDriveEnable {
                dti_drive_enable_cmd,
            }) => enable = Some(dti_drive_enable_cmd),
            AnyMessage::DtiSetMaxCurrentDc(DtiSetMaxCurrentDc {
                dti_max_current_dc_cmd,
            }) => dc = Some(dti_max_current_dc_cmd),
            AnyMessage::DtiSetMaxBrakeCurrentDc(DtiSetMaxBrakeCurrentDc {
                dti_max_brake_current_dc_cmd,
            }) => brake = Some(dti_max_brake_current_dc_cmd),
            other => panic!("unexpected {other:?}"),
        }
    }
    (
        current.unwrap(),
        enable.unwrap(),
        dc.unwrap(),
        brake.unwrap(),
    )
}

#[test]
fn torque_becomes_ac_current_through_the_torque_constant_only_while_driving() {
    let (current, enable, dc, brake) = sent(&command(150.0, true));
    let expected = f64::from(150.0 / MOTOR_TORQUE_PER_PEAK_A);
    assert!(
        (current - expected).abs() <= 0.05,
        "{current} A, 0.1 A steps"
    );
    assert_eq!(enable, DtiDriveEnable::Enabled);
    assert_eq!(dc, 250.0, "the BMS's discharge limit");
    assert_eq!(brake, 0.0, "no regeneration");

    let (current, enable, _, _) = sent(&command(150.0, false));
    assert_eq!(current, 0.0, "no current outside DRIVING");
    assert_eq!(enable, DtiDriveEnable::Disabled);

    for torque in [f32::NAN, f32::INFINITY, -50.0] {
        let (current, _, _, _) = sent(&command(torque, true));
        assert_eq!(current, 0.0, "{torque}");
    }
    let (current, _, _, _) = sent(&command(10_000.0, true));
    assert!(current <= f64::from(dti::MAX_CURRENT_A) + 0.05, "{current}");

    let (_, _, dc, _) = sent(&DriveCommand {
        discharge_limit_a: f32::NAN,
        ..command(100.0, true)
    });
    assert_eq!(dc, 0.0, "no limit known: no DC current");
}

#[test]
fn the_ccm_sends_the_dti_its_commands_and_drive_enable_only_in_driving() {
    let mut rig = Rig::with_inverter(InverterKind::Dti);
    rig.hold(&Tick::CALM, 20);
    let (_, enable, _, _) = frames_of(&mut rig);
    assert_eq!(enable, DtiDriveEnable::Disabled);
    rig.drive_away();
    rig.hold(&Tick::driving(0.5, 1_000.0), 5);
    let (current, enable, dc, _) = frames_of(&mut rig);
    assert_eq!(enable, DtiDriveEnable::Enabled);
    let torque = rig.ccm.last_outputs().torque.torque_nm;
    assert!((current - f64::from(torque / MOTOR_TORQUE_PER_PEAK_A)).abs() <= 0.05);
    assert_eq!(dc, 300.0, "the rig's BMS allows 300 A");

    // The BMS falls silent: DC limit 0 at once (its limit is stale), then the fault.
    let silent = Tick {
        bms: None,
        ..Tick::driving(0.5, 1_000.0)
    };
    rig.hold(&silent, 60);
    let (current, enable, dc, _) = frames_of(&mut rig);
    assert_eq!((current, enable, dc), (0.0, DtiDriveEnable::Disabled, 0.0));
}

fn frames_of(rig: &mut Rig) -> (f64, DtiDriveEnable, f64, f64) {
    let frames = rig.ccm.inverter_frames().expect("encodes");
    let mut out = (f64::NAN, DtiDriveEnable::Unknown(0xFF), f64::NAN, f64::NAN);
    for frame in frames.iter() {
        match decode(frame) {
            AnyMessage::DtiSetCurrent(m) => out.0 = m.dti_current_cmd,
            AnyMessage::DtiSetDriveEnable(m) => out.1 = m.dti_drive_enable_cmd,
            AnyMessage::DtiSetMaxCurrentDc(m) => out.2 = m.dti_max_current_dc_cmd,
            AnyMessage::DtiSetMaxBrakeCurrentDc(m) => out.3 = m.dti_max_brake_current_dc_cmd,
            other => panic!("unexpected {other:?}"),
        }
    }
    out
}

#[test]
fn speed_power_and_available_torque_come_from_the_dtis_packets() {
    let mut rig = Rig::with_inverter(InverterKind::Dti);
    rig.hold(&Tick::driving(0.0, 3_000.0), 20);
    let bus = rig.ccm.bus();
    let status = InverterKind::Dti.status(bus, rig.now_ms, 0);
    assert_eq!(status.motor_rpm, Some(3_000.0), "ERPM / 10 pole pairs");
    assert_eq!(status.dc_link, Some((380.0, 2.0)));
    let torque = status.available_torque_nm.unwrap();
    assert!((torque - 346.6 * MOTOR_TORQUE_PER_PEAK_A).abs() < 0.01);
    assert_eq!(status.temperatures_degc, Some((35.0, 40.0)));
    assert!(!status.fault && !status.warning && !status.lost);
    // The IFL100's view of the same bus: nothing it knows arrived.
    let ifl100 = InverterKind::Ifl100.status(bus, rig.now_ms, 0);
    assert!(ifl100.motor_rpm.is_none() && ifl100.dc_link.is_none());
    let later = InverterKind::Ifl100.status(bus, rig.now_ms, rig.now_ms.wrapping_sub(1_001));
    assert!(
        later.lost,
        "past the start-up grace the IFL100 counts as lost"
    );
}

/// Feeds a DTI packet 0x24 to the rig's CCM.
fn send_flags(rig: &mut Rig, flags: aer::can::DtiFlags) {
    let mut data = [0u8; 8];
    flags.encode(&mut data).unwrap();
    let frame = aer_flexcan::CanFrame::new(
        embedded_can::ExtendedId::new(aer::can::DtiFlags::ID).unwrap(),
        &data,
    )
    .unwrap();
    rig.ccm.on_frame(&frame, rig.now_ms);
}

#[test]
fn a_wrong_can_map_is_a_fault_and_limits_are_warnings() {
    let mut rig = Rig::with_inverter(InverterKind::Dti);
    rig.drive_away();
    rig.hold(&Tick::driving(0.5, 1_000.0), 5);
    send_flags(
        &mut rig,
        aer::can::DtiFlags {
            dti_limit_motor_temp: true,
            ..dti_flags()
        },
    );
    let outputs = rig
        .ccm
        .control(Default::default(), rig.now_ms, rig.now_ms * 1_000);
    assert!(outputs.faults.has(Fault::InverterWarning));
    assert!(!outputs.faults.has(Fault::InverterFault));
    assert_eq!(outputs.vehicle.state, State::Driving, "a limit only warns");

    send_flags(
        &mut rig,
        aer::can::DtiFlags {
            dti_can_map_version: 24,
            ..dti_flags()
        },
    );
    let outputs = rig
        .ccm
        .control(Default::default(), rig.now_ms, rig.now_ms * 1_000);
    assert!(
        outputs.faults.has(Fault::InverterFault),
        "map 2.4 is not the schema's"
    );
    assert_eq!(outputs.torque.torque_nm, 0.0);
}

#[test]
fn a_dti_that_stays_enabled_after_the_ccm_disabled_it_is_a_fault() {
    let mut rig = Rig::with_inverter(InverterKind::Dti);
    rig.hold(&Tick::CALM, 20);
    rig.ccm.inverter_frames().expect("encodes");
    let enabled = aer::can::DtiFlags {
        dti_drive_enabled: DtiDriveEnable::Enabled,
        dti_limit_drive_enable: false,
        ..dti_flags()
    };
    let start = rig.now_ms;
    let mut faulted_after = None;
    // Only the flags come (the other packets would say "disabled" again).
    let quiet = Tick {
        inverter: None,
        ..Tick::CALM
    };
    for _ in 0..20 {
        send_flags(&mut rig, enabled);
        let outputs = rig.tick(&quiet);
        if outputs.faults.has(Fault::InverterFault) {
            faulted_after = Some(rig.now_ms - start);
            break;
        }
    }
    let after = faulted_after.expect("disobedience is a fault");
    assert!(after > DTI_ENABLE_MISMATCH_MS, "{after} ms");
    assert!(after <= DTI_ENABLE_MISMATCH_MS + 20, "{after} ms");
}

#[test]
fn the_bench_check_names_node_map_drive_and_fault() {
    use aer::can::{DtiFlags, DtiTemperatures};
    use aer_ccm::console::dti::BenchCheck;
    let mut check = BenchCheck::default();
    assert_eq!(check.to_string(), "DTI: no status packet heard");
    let mut data = [0u8; 8];
    dti_flags().encode(&mut data).unwrap();
    check.frame(DtiFlags::ID, true, &data);
    let temperatures = DtiTemperatures {
        dti_controller_temp: 30.0,
        dti_motor_temp: 30.0,
        dti_fault_code: aer::can::DtiFaultCode::Undervoltage,
    };
    temperatures.encode(&mut data).unwrap();
    check.frame(DtiTemperatures::ID, true, &data);
    assert_eq!(
        check.to_string(),
        "DTI node 0x41 (schema 0x41), CAN map 25 (schema 25), drive DISABLED, fault UNDERVOLTAGE"
    );
    // A DTI configured with another node id: its packets carry it.
    let mut other = BenchCheck::default();
    other.frame((DtiFlags::ID & !0xFF) | 0x65, true, &data);
    other.frame(0x123, false, &data);
    assert_eq!(
        other.to_string(),
        "DTI node 0x65 (schema 0x41), CAN map not heard"
    );
}

/// A DTI (and the PCC beside it) as the bring-up hears them: status packets at their cycle
/// times, with the DC link, motor speed, fault code and PCC state each test sets.
struct Heard {
    dc_link_v: Option<i16>,
    erpm: i32,
    fault: aer::can::DtiFaultCode,
    pcc: Option<aer::can::PrechargeState>,
    /// The PCC's tractive converter fell silent after reading 60 V or more (latched).
    pcc_tractive_silent: bool,
    /// What the PCC reads the tractive system at (V).
    pcc_tractive_v: f64,
    /// The DTI drops its drive enable this long after the last enable command (ms); `None`:
    /// never.
    timeout_ms: Option<u32>,
}

impl Heard {
    fn low_voltage() -> Self {
        Self {
            dc_link_v: Some(0),
            erpm: 0,
            fault: aer::can::DtiFaultCode::None,
            pcc: None,
            pcc_tractive_silent: false,
            pcc_tractive_v: 392.0,
            timeout_ms: Some(80),
        }
    }

    fn high_voltage() -> Self {
        Self {
            dc_link_v: Some(392),
            pcc: Some(aer::can::PrechargeState::Online),
            ..Self::low_voltage()
        }
    }
}

/// What the bench sent, from `DtiBench::due`'s frames.
#[derive(Default)]
struct Sent {
    enables: Vec<u32>,
    disables: Vec<u32>,
    stopped: Vec<String>,
    /// Each measurement's result line, as it ended.
    ended: Vec<String>,
}

/// Runs the bench from `from` to `to` (ms) against `heard`, every millisecond as the bring-up
/// loop does.
fn run(
    bench: &mut aer_ccm::console::dti::DtiBench,
    heard: &Heard,
    sent: &mut Sent,
    from: u32,
    to: u32,
) {
    use aer::can::{DtiDriveEnable, DtiFlags, DtiSpeed, DtiTemperatures, PccStatus};
    use aer_ccm::console::dti::Step;
    for now in from..to {
        let mut frames = None;
        match bench.due(now) {
            Some(Step::Send(out)) => frames = Some(out),
            Some(Step::Stopped(why, out)) => {
                sent.stopped.push(why.to_string());
                frames = Some(out);
            }
            None => {}
        }
        if let Some(frames) = frames {
            record(frames.expect("encodes"), now, sent);
        }
        let mut data = [0u8; 8];
        if now % 10 == 3 {
            let enabled = sent.enables.last().is_some_and(|&at| {
                sent.disables.last().is_none_or(|&off| off < at)
                    && heard.timeout_ms.is_none_or(|limit| now - at <= limit)
            });
            DtiFlags {
                dti_drive_enabled: if enabled {
                    DtiDriveEnable::Enabled
                } else {
                    DtiDriveEnable::Disabled
                },
                ..dti_flags()
            }
            .encode(&mut data)
            .unwrap();
            bench.frame(now, DtiFlags::ID, true, &data);
            if let Some(volts) = heard.dc_link_v {
                DtiSpeed {
                    dti_erpm: heard.erpm,
                    dti_duty_cycle: 0.0,
                    dti_input_voltage: volts,
                }
                .encode(&mut data)
                .unwrap();
                bench.frame(now, DtiSpeed::ID, true, &data);
            }
            if let Some(state) = heard.pcc {
                PccStatus {
                    pcc_state: state,
                    pcc_error_too_fast: false,
                    pcc_error_air_plus_open: false,
                    pcc_error_converters_disagree: false,
                    pcc_error_bypassed: false,
                    pcc_error_resistor_hot: false,
                    pcc_accumulator_no_pulses: false,
                    pcc_tractive_no_pulses: false,
                    pcc_error_accumulator_silent: false,
                    pcc_error_tractive_silent: heard.pcc_tractive_silent,
                    pcc_error_no_discharge: false,
                    pcc_error_too_slow: false,
                    pcc_error_bms_timeout: false,
                    pcc_error_shutdown: false,
                    pcc_error_undefined_state: false,
                    pcc_accumulator_voltage: 392.0,
                    pcc_tractive_voltage: heard.pcc_tractive_v,
                    pcc_precharge_progress: 100.0,
                }
                .encode(&mut data)
                .unwrap();
                bench.vehicle_frame(now, PccStatus::ID, false, &data);
            }
        }
        if now % 100 == 7 {
            DtiTemperatures {
                dti_controller_temp: 25.0,
                dti_motor_temp: 25.0,
                dti_fault_code: heard.fault,
            }
            .encode(&mut data)
            .unwrap();
            bench.frame(now, DtiTemperatures::ID, true, &data);
        }
        if let Some((timeout, frames)) = bench.poll(now) {
            sent.ended.push(timeout.to_string());
            record(frames.expect("encodes"), now, sent);
        }
    }
}

/// Records the drive-enable commands among `frames`, sent at `now`; every other command must
/// ask for 0 A.
fn record(frames: aer_ccm::OutFrames, now: u32, sent: &mut Sent) {
    use aer::can::{AnyMessage, DtiDriveEnable};
    for frame in frames.iter() {
        match AnyMessage::decode(frame.id, frame.extended, frame.data()).unwrap() {
            AnyMessage::DtiSetCurrent(current) => assert_eq!(current.dti_current_cmd, 0.0),
            AnyMessage::DtiSetMaxCurrentDc(limit) => assert_eq!(limit.dti_max_current_dc_cmd, 0.0),
            AnyMessage::DtiSetDriveEnable(enable) => {
                if enable.dti_drive_enable_cmd == DtiDriveEnable::Enabled {
                    sent.enables.push(now);
                } else {
                    sent.disables.push(now);
                }
            }
            _ => {}
        }
    }
}

/// The bring-up's `dti enable` below 60 V: 0 A and drive enable every command period for one
/// second, then silence; the timeout measurement follows packet 0x24.
#[test]
fn the_bench_times_the_dtis_command_timeout_from_packet_0x24() {
    use aer_ccm::console::dti::{DtiBench, EnableTest, Path, TimeoutResult};
    let mut bench = DtiBench::default();
    assert_eq!(
        bench.timeout.to_string(),
        "DTI command timeout: NOT MEASURED (`confirm hv-disconnected`, then `dti enable`, or drive enable from a CAN adapter, then silence): no spin until it reads PASS"
    );
    let heard = Heard::low_voltage();
    let mut sent = Sent::default();
    run(&mut bench, &heard, &mut sent, 0, 1_000);
    bench
        .guard
        .confirm_hv_disconnected(1_000, &bench.evidence)
        .expect("the DTI reads 0 V");
    assert_eq!(bench.enable(1_000), Ok(Path::LowVoltage));
    run(
        &mut bench,
        &heard,
        &mut sent,
        1_000,
        1_000 + EnableTest::DURATION_MS + 500,
    );
    assert_eq!(sent.enables.len(), 100, "every 10 ms for one second");
    assert!(sent.stopped.is_empty(), "{:?}", sent.stopped);
    assert!(!bench.test.active());
    let Some(TimeoutResult::Dropped(ms)) = bench.timeout.result() else {
        panic!("{:?}", bench.timeout.result());
    };
    assert!((80..=90).contains(&ms), "{ms} ms");
    assert!(bench.timeout.passed());
    // Measured on silence; the drive disable goes out once the result is in, not before.
    let last_enable = *sent.enables.last().expect("enables");
    assert_eq!(sent.disables.len(), 1, "{:?}", sent.disables);
    assert!(sent.disables[0] >= last_enable + ms);
    assert_eq!(sent.ended.len(), 1);
    assert!(
        sent.ended[0].contains(&format!("PASS: drive enable dropped {ms} ms")),
        "{:?}",
        sent.ended
    );

    // A DTI without a timeout: still enabled a second after the last command.
    let mut stuck = DtiBench::default();
    let never = Heard {
        timeout_ms: None,
        ..Heard::low_voltage()
    };
    let mut sent = Sent::default();
    run(&mut stuck, &never, &mut sent, 0, 500);
    stuck
        .guard
        .confirm_hv_disconnected(500, &stuck.evidence)
        .expect("0 V");
    assert_eq!(stuck.enable(500), Ok(Path::LowVoltage));
    run(&mut stuck, &never, &mut sent, 500, 3_000);
    assert_eq!(stuck.timeout.result(), Some(TimeoutResult::NotDropped));
    assert!(!stuck.timeout.passed());
    assert!(
        stuck
            .timeout
            .to_string()
            .contains("FAIL: STILL ENABLED 1000 ms")
    );
    // Whatever the DTI answered, the bench disabled it when its wait ended.
    assert_eq!(sent.disables.len(), 1, "{:?}", sent.disables);
    assert!(sent.ended[0].starts_with("DTI command timeout: FAIL"));

    // Commands from a CAN adapter time the same way; an explicit disable is not a timeout.
    let mut adapter = DtiBench::default();
    let mut enable = [0u8; 1];
    aer::can::DtiSetDriveEnable {
        dti_drive_enable_cmd: aer::can::DtiDriveEnable::Enabled,
    }
    .encode(&mut enable)
    .unwrap();
    let flags = |enabled| {
        let mut data = [0u8; 8];
        aer::can::DtiFlags {
            dti_drive_enabled: if enabled {
                aer::can::DtiDriveEnable::Enabled
            } else {
                aer::can::DtiDriveEnable::Disabled
            },
            ..dti_flags()
        }
        .encode(&mut data)
        .unwrap();
        data
    };
    adapter.frame(0, aer::can::DtiSetDriveEnable::ID, true, &enable);
    adapter.frame(5, aer::can::DtiFlags::ID, true, &flags(true));
    let disable = [0u8; 1];
    adapter.frame(10, aer::can::DtiSetDriveEnable::ID, true, &disable);
    adapter.frame(15, aer::can::DtiFlags::ID, true, &flags(false));
    adapter.poll(2_000);
    assert_eq!(adapter.timeout.result(), None);
}

/// Below 60 V the guard needs `confirm hv-disconnected` and the DTI's own fresh DC link
/// reading; always a DTI heard without fault and a motor standing still. Silence, an old
/// reading or a fault is no evidence.
#[test]
fn dti_enable_below_60_v_needs_the_confirmation_and_live_readings() {
    use aer::can::DtiFaultCode;
    use aer_ccm::console::dti::{DtiBench, DtiRefusal};
    use aer_console::hv_gate::{HvRefusal, Unknown};
    let mut sent = Sent::default();

    let mut bench = DtiBench::default();
    run(&mut bench, &Heard::low_voltage(), &mut sent, 0, 300);
    assert_eq!(
        bench.enable(300),
        Err(DtiRefusal::Hv(HvRefusal::NotConfirmed)),
        "no confirmation"
    );

    // No packet 0x20 at all: the DC link is unknown, not 0 V.
    let mut silent = DtiBench::default();
    let no_dc_link = Heard {
        dc_link_v: None,
        ..Heard::low_voltage()
    };
    run(&mut silent, &no_dc_link, &mut sent, 0, 300);
    let refusal = silent
        .guard
        .confirm_hv_disconnected(300, &silent.evidence)
        .unwrap_err();
    assert!(matches!(
        refusal,
        HvRefusal::Unknown {
            why: Unknown::Silent(_),
            ..
        }
    ));
    assert_eq!(
        refusal.to_string(),
        "DTI DC link gives no reading: no packet 0x20 heard from the DTI: check its logic supply, CAN2 and its node id"
    );

    // Confirmed, then the DTI falls silent: the test stops at the first step past 20 ms.
    let mut bench = DtiBench::default();
    run(&mut bench, &Heard::low_voltage(), &mut sent, 0, 300);
    bench
        .guard
        .confirm_hv_disconnected(300, &bench.evidence)
        .expect("0 V");
    bench.enable(300).expect("allowed");
    let mut sent = Sent::default();
    run(&mut bench, &Heard::low_voltage(), &mut sent, 300, 500);
    run(&mut bench, &no_dc_link, &mut sent, 500, 600);
    assert!(!bench.test.active());
    assert_eq!(sent.disables.len(), 1, "stopped with an explicit disable");
    let stopped_at = sent.disables[0];
    assert!((510..=525).contains(&stopped_at), "{stopped_at}");
    assert!(
        sent.stopped[0].starts_with("DTI DC link's reading is 2"),
        "{:?}",
        sent.stopped
    );

    // A DTI with a fault, or a motor that turns, refuses it too.
    for (heard, expected) in [
        (
            Heard {
                fault: DtiFaultCode::Overvoltage,
                ..Heard::low_voltage()
            },
            DtiRefusal::Fault(DtiFaultCode::Overvoltage),
        ),
        (
            Heard {
                erpm: 900,
                ..Heard::low_voltage()
            },
            DtiRefusal::Turning(Some(900)),
        ),
        // The DTI reads below 60 V while the PCC reports ERROR and reads 392 V (the shutdown
        // circuit still closed): low voltage is not proven.
        (
            Heard {
                pcc: Some(aer::can::PrechargeState::Error),
                ..Heard::low_voltage()
            },
            DtiRefusal::PccReadsLive(392.0),
        ),
        // STANDBY, but the PCC's tractive converter fell silent after reading 60 V or more:
        // its last reading is not the voltage now, and low voltage is not proven.
        (
            Heard {
                pcc: Some(aer::can::PrechargeState::Standby),
                pcc_tractive_silent: true,
                ..Heard::low_voltage()
            },
            DtiRefusal::PccVoltageUnknown,
        ),
        // The DTI reads below 60 V while the PCC reports ONLINE: the DTI's HV input or its
        // measurement, not low voltage; the confirmation does not make it so.
        (
            Heard {
                pcc: Some(aer::can::PrechargeState::Online),
                ..Heard::low_voltage()
            },
            DtiRefusal::PccEnergised(aer::can::PrechargeState::Online),
        ),
    ] {
        let mut bench = DtiBench::default();
        run(&mut bench, &heard, &mut sent, 0, 300);
        bench
            .guard
            .confirm_hv_disconnected(300, &bench.evidence)
            .expect("0 V");
        assert_eq!(bench.enable(300), Err(expected));
    }
}

/// At 60 V or more `confirm hv-disconnected` is refused and `dti enable` needs `confirm
/// wheels-off-ground` with the PCC heard ONLINE; it stops with an explicit disable the step
/// the PCC leaves ONLINE, the DTI reports a fault or the motor turns.
#[test]
fn dti_enable_at_high_voltage_needs_wheels_off_the_ground_and_the_pcc_online() {
    use aer::can::{DtiFaultCode, PrechargeState};
    use aer_ccm::console::dti::{DtiBench, DtiRefusal, Path, TimeoutResult};
    use aer_console::hv_gate::HvRefusal;
    let mut sent = Sent::default();
    let mut bench = DtiBench::default();
    run(&mut bench, &Heard::high_voltage(), &mut sent, 0, 300);
    assert!(matches!(
        bench.guard.confirm_hv_disconnected(300, &bench.evidence),
        Err(HvRefusal::Live { .. })
    ));
    assert_eq!(bench.enable(300), Err(DtiRefusal::WheelsNotConfirmed));
    bench.guard.confirm_wheels_off_ground(300);
    for (heard, expected) in [
        (
            Heard {
                pcc: None,
                ..Heard::high_voltage()
            },
            DtiRefusal::PccNotOnline(None),
        ),
        (
            Heard {
                pcc: Some(PrechargeState::Precharge),
                ..Heard::high_voltage()
            },
            DtiRefusal::PccNotOnline(Some(PrechargeState::Precharge)),
        ),
        // ONLINE, but with its tractive converter's silence latched: a status the race CCM
        // calls a PCC error.
        (
            Heard {
                pcc_tractive_silent: true,
                ..Heard::high_voltage()
            },
            DtiRefusal::PccFault,
        ),
        // ONLINE, the PCC reading 300 V where the DTI reads 392 V: one of them is wrong.
        (
            Heard {
                pcc_tractive_v: 300.0,
                ..Heard::high_voltage()
            },
            DtiRefusal::Disagree {
                pcc_v: Some(300.0),
                dti_v: 392.0,
            },
        ),
    ] {
        let mut bench = DtiBench::default();
        run(&mut bench, &heard, &mut sent, 0, 300);
        bench.guard.confirm_wheels_off_ground(300);
        assert_eq!(bench.enable(300), Err(expected));
    }

    // Allowed: the whole second runs and the timeout is measured at high voltage.
    assert_eq!(bench.enable(300), Ok(Path::HighVoltage));
    let mut sent = Sent::default();
    run(&mut bench, &Heard::high_voltage(), &mut sent, 300, 2_000);
    assert_eq!(sent.enables.len(), 100);
    assert!(matches!(
        bench.timeout.result(),
        Some(TimeoutResult::Dropped(80..=90))
    ));

    // Each fault mid-test stops it within a step or two of being heard.
    for (name, fault) in [
        (
            "the PCC leaves ONLINE",
            Heard {
                pcc: Some(PrechargeState::Error),
                ..Heard::high_voltage()
            },
        ),
        (
            "the DTI reports a fault",
            Heard {
                fault: DtiFaultCode::MotorOvertemp,
                ..Heard::high_voltage()
            },
        ),
        (
            "the motor turns",
            Heard {
                erpm: -2_000,
                ..Heard::high_voltage()
            },
        ),
    ] {
        let mut bench = DtiBench::default();
        let mut sent = Sent::default();
        run(&mut bench, &Heard::high_voltage(), &mut sent, 0, 300);
        bench.guard.confirm_wheels_off_ground(300);
        assert_eq!(bench.enable(300), Ok(Path::HighVoltage), "{name}");
        run(&mut bench, &Heard::high_voltage(), &mut sent, 300, 600);
        run(&mut bench, &fault, &mut sent, 600, 800);
        assert!(!bench.test.active(), "{name}");
        assert_eq!(sent.disables.len(), 1, "{name}: an explicit disable");
        assert!(
            sent.disables[0] <= 710,
            "{name}: stopped at {}",
            sent.disables[0]
        );
        assert_eq!(
            bench.timeout.result(),
            None,
            "{name}: a stop is not a timeout"
        );
    }
}
