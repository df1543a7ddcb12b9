//! The behaviours an inspection found wrong (issue 12), each through the public `Ccm` API.
//! Every test here failed on the code before the fix (the numbers in the comments are what
//! it did then). The power limit in closed loop is in `car-model/tests/power_limit.rs`, the
//! PCC's failure modes in `pcc/tests/failure_modes.rs`.

mod rig;

use aer_ccm::constants::{BMS_PACK_TIMEOUT_MS, PEDAL_CONVERSION_TIMEOUT_MS};
use aer_ccm::faults::Fault;
use aer_ccm::launch::LaunchState;
use aer_ccm::vehicle::State;
use aer_ccm::{BusHealth, DriverCounters};
use rig::{INVERTERS, Inverter, Rig, Tick};

/// Ticks (10 ms each) until `done`, at most `limit`; returns how many it took.
fn ticks_until(
    rig: &mut Rig,
    tick: &Tick,
    limit: u32,
    done: impl Fn(&aer_ccm::ControlOutputs) -> bool,
) -> Option<u32> {
    (1..=limit).find(|_| done(&rig.tick(tick)))
}

#[test]
fn launch_control_never_pushes_the_car_once_the_pedal_is_released() {
    // Before: 23 Nm rising to 74 Nm with the pedal released, for 10 s, still DRIVING.
    let mut rig = Rig::new();
    rig.drive_away();
    // On the line: stopped, brakes held, launch button.
    rig.tick(
        &Tick {
            launch: true,
            ..Tick::driving(0.0, 0.0)
        }
        .with_brakes(100.0),
    );
    rig.tick(&Tick::driving(0.0, 0.0));
    // Full pedal: launch active; the front wheels roll with the motor (no slip).
    let launched = rig.hold(&Tick::driving(1.0, 875.0), 100);
    assert_eq!(launched.torque.launch, LaunchState::Active);
    // Pedal released: within one control step launch ends and torque is zero, and stays so.
    let released = Tick::driving(0.0, 875.0);
    let first = rig.tick(&released);
    assert_eq!(first.torque.launch, LaunchState::Off);
    for _ in 0..1_000 {
        let outputs = rig.tick(&released);
        assert_eq!(outputs.torque.torque_nm, 0.0, "{:?}", outputs.torque);
    }
}

#[test]
fn launch_control_only_ever_takes_torque_away() {
    let mut rig = Rig::new();
    rig.drive_away();
    rig.tick(
        &Tick {
            launch: true,
            ..Tick::driving(0.0, 0.0)
        }
        .with_brakes(100.0),
    );
    rig.tick(&Tick::driving(0.0, 0.0));
    for pedal in [0.3, 0.6, 0.9] {
        let outputs = rig.hold(&Tick::driving(pedal, 875.0), 50);
        let request = aer_ccm::torque_path::torque_request(pedal);
        assert!(
            outputs.torque.torque_nm <= request + 0.5,
            "{pedal}: {:?}",
            outputs.torque
        );
    }
}

#[test]
fn a_dead_pedal_converter_is_an_apps_fault_with_zero_torque_within_100_ms() {
    // Before: the driver repeated the last good counts; 156 Nm for 3 s and more, no fault.
    let mut rig = Rig::new();
    rig.drive_away();
    let driving = rig.hold(&Tick::driving(0.6, 1_000.0), 20);
    assert!(driving.torque.torque_nm > 100.0);
    let dead = Tick {
        converter: false,
        ..Tick::driving(0.0, 1_000.0)
    };
    let ticks = ticks_until(&mut rig, &dead, 100, |outputs| {
        outputs.torque.torque_nm == 0.0 && outputs.faults.has(Fault::PedalSignalLost)
    })
    .expect("torque cut");
    let ms = ticks * 10;
    assert!(ms <= PEDAL_CONVERSION_TIMEOUT_MS + 10, "{ms} ms");
    assert!(ms <= 100, "T.4.2.10: {ms} ms");
    let outputs = rig.hold(&dead, 300);
    assert_eq!(outputs.torque.torque_nm, 0.0);
    assert_eq!(outputs.vehicle.state, State::Fault);
}

#[test]
fn bms_silence_stops_torque_and_names_the_fault() {
    // Before: 5 s of BMS silence, still DRIVING at 130 Nm, no fault.
    let mut rig = Rig::new();
    rig.drive_away();
    rig.hold(&Tick::driving(0.5, 1_000.0), 10);
    let silent = Tick {
        bms: None,
        ..Tick::driving(0.5, 1_000.0)
    };
    let ticks = ticks_until(&mut rig, &silent, 500, |outputs| {
        outputs.torque.torque_nm == 0.0 && outputs.faults.has(Fault::BmsTimeout)
    })
    .expect("torque cut");
    assert!(ticks * 10 <= BMS_PACK_TIMEOUT_MS + 10, "{} ms", ticks * 10);
    assert_eq!(rig.hold(&silent, 500).vehicle.state, State::Fault);
    assert!(rig.ccm.status().ccm_fault_bms_timeout, "visible on the bus");
    assert!(rig.ccm.snapshot().fault_bms_timeout, "and in telemetry");
}

#[test]
fn inverter_silence_stops_torque_and_names_the_fault() {
    for inverter in INVERTERS {
        let mut rig = Rig::with_inverter(inverter);
        rig.drive_away();
        rig.hold(&Tick::driving(0.5, 1_000.0), 10);
        let silent = Tick {
            inverter: None,
            ..Tick::driving(0.5, 1_000.0)
        };
        let ticks = ticks_until(&mut rig, &silent, 100, |outputs| {
            outputs.torque.torque_nm == 0.0 && outputs.faults.has(Fault::InverterTimeout)
        })
        .expect("torque cut");
        let limit = inverter.status_timeout_ms();
        assert!(ticks * 10 <= limit + 10, "{inverter:?}: {} ms", ticks * 10);
        assert!(rig.ccm.snapshot().fault_inverter_timeout);
    }
}

#[test]
fn the_inverters_own_fault_bits_reach_the_fault_map() {
    // Before: MCU2's fault bits never reached the fault map.
    for inverter in INVERTERS {
        let mut rig = Rig::with_inverter(inverter);
        rig.drive_away();
        rig.hold(&Tick::driving(0.5, 1_000.0), 10);
        let faulty = Tick {
            inverter: Some(Inverter {
                rpm: 1_000.0,
                dc: (380.0, 2.0),
                fault: true,
            }),
            ..Tick::driving(0.5, 1_000.0)
        };
        let outputs = rig.tick(&faulty);
        assert!(outputs.faults.has(Fault::InverterFault), "{inverter:?}");
        assert_eq!(outputs.torque.torque_nm, 0.0);
        assert_eq!(outputs.vehicle.state, State::Fault);
        assert!(rig.ccm.status().ccm_fault_inverter_fault);
    }
}

#[test]
fn brakes_engaged_means_the_same_to_the_brake_light_and_the_plausibility_check() {
    // Before: at 40 psi with 40 % pedal the brake light was on and the car made 104 Nm.
    for psi in [25.0, 31.0, 40.0, 60.0] {
        let mut rig = Rig::new();
        rig.drive_away();
        rig.hold(&Tick::driving(0.0, 500.0), 5);
        let outputs = rig.hold(&Tick::driving(0.4, 500.0).with_brakes(psi), 10);
        assert_eq!(
            outputs.brake_light,
            rig.ccm.apps().brake_plausibility,
            "{psi} psi: light {} but plausibility {}",
            outputs.brake_light,
            rig.ccm.apps().brake_plausibility
        );
        if outputs.brake_light {
            assert_eq!(outputs.torque.torque_nm, 0.0, "{psi} psi");
        }
    }
}

#[test]
fn ccm_status_counter_advances_by_one_per_frame_sent() {
    // Before: `status()` advanced the counter and `snapshot()` called it every 10 ms, so
    // frames sent every 100 ms counted 1, 12, 7, 2, 13.
    let mut rig = Rig::new();
    rig.drive_away();
    let mut counters = Vec::new();
    for step in 0..50 {
        rig.tick(&Tick::driving(0.2, 500.0));
        let _ = rig.ccm.snapshot();
        assert_eq!(
            rig.ccm.status(),
            rig.ccm.status(),
            "reading changes nothing"
        );
        if step % 10 == 0 {
            counters.push(rig.ccm.next_status().ccm_rolling_counter);
        }
    }
    for pair in counters.windows(2) {
        assert_eq!((pair[0] + 1) & 0x0F, pair[1], "{counters:?}");
    }
}

#[test]
fn can_controller_health_and_drops_reach_telemetry() {
    // Before: bus-off and error-passive were never reported; encode failures never read.
    let mut rig = Rig::new();
    rig.ccm.set_driver_counters(DriverCounters {
        rx_dropped: 1,
        tx_dropped: 4,
        pedal_bus_errors: 300,
        buses: [
            BusHealth {
                error_passive: true,
                bus_off: false,
                bus_off_events: 1,
            },
            BusHealth {
                error_passive: false,
                bus_off: true,
                bus_off_events: 2,
            },
        ],
    });
    let snapshot = rig.ccm.snapshot();
    assert!(snapshot.vehicle_bus_error_passive && !snapshot.vehicle_bus_bus_off);
    assert!(snapshot.inverter_bus_bus_off && !snapshot.inverter_bus_error_passive);
    assert_eq!(snapshot.can_bus_off_events, 3);
    assert_eq!(snapshot.can_tx_dropped, 4);
    assert_eq!(snapshot.pedal_bus_errors, 44, "300 wraps at 256");
}

#[test]
fn a_stuck_inverter_repeating_its_frames_stops_torque_like_a_silent_one() {
    // Before: the CCM ignored MCU1's and MCU2's counters, so an inverter that kept repeating
    // its last frames was taken as fresh data (speed, available torque, temperatures).
    use aer::can::{Mcu1, Mcu2, Mcu3};
    use aer::runtime::CounterSender;
    use aer_ccm::InverterKind;
    use embedded_can::{Frame, StandardId};
    let mut rig = Rig::with_inverter(InverterKind::Ifl100);
    rig.drive_away();
    rig.hold(&Tick::driving(0.5, 1_000.0), 10);
    let frozen = |id: u32, encode: &dyn Fn(&mut [u8; 8])| {
        let mut data = [0u8; 8];
        encode(&mut data);
        if let Some(meta) = aer::can::message_meta(id, false) {
            meta.seal(&mut CounterSender::default(), &mut data);
        }
        aer_flexcan::CanFrame::new(StandardId::new(id as u16).unwrap(), &data).unwrap()
    };
    let mcu1 = frozen(Mcu1::ID, &|d| {
        rig::mcu1().encode(d).unwrap();
    });
    let mcu2 = frozen(Mcu2::ID, &|d| {
        rig::quiet_mcu2().encode(d).unwrap();
    });
    let mcu3 = frozen(Mcu3::ID, &|d| {
        Mcu3 {
            mcu_dc_voltage: 380.0,
            mcu_dc_current: 2.0,
            mcu_phase_current: 0.0,
        }
        .encode(d)
        .unwrap();
    });
    let stuck = Tick {
        inverter: None,
        ..Tick::driving(0.5, 1_000.0)
    };
    let refused_before = rig.ccm.bus().integrity_errors;
    let mut cut_after = None;
    for tick in 1..=20u32 {
        for frame in [&mcu1, &mcu2, &mcu3] {
            rig.ccm.on_frame(frame, rig.now_ms);
        }
        let outputs = rig.tick(&stuck);
        if outputs.torque.torque_nm == 0.0 && outputs.faults.has(Fault::InverterTimeout) {
            cut_after = Some(tick * 10);
            break;
        }
    }
    let cut = cut_after.expect("a stuck inverter stops torque");
    assert!(
        cut <= InverterKind::Ifl100.status_timeout_ms() + 10,
        "{cut} ms"
    );
    // Every repeat after the first was refused and counted (and reaches telemetry).
    assert!(rig.ccm.bus().integrity_errors > refused_before + 5);
    assert!(rig.ccm.snapshot().can_decode_errors > 0);
}
