//! Each module's behaviour at its limits.

use aer::can::{AnyMessage, PccStatus, PrechargeState, Vcu1};
use aer::telemetry::Telemetry;
use aer_ccm::apps::Apps;
use aer_ccm::brakes::{Brakes, volts_for};
use aer_ccm::calibration::AppsCalibration;
use aer_ccm::calibration::{BrakeCalibration, Calibration};
use aer_ccm::faults::{Fault, FaultMap};
use aer_ccm::inverter::DriveCommand;
use aer_ccm::inverter::ifl100::Vcu1Builder;
use aer_ccm::thermal::cooling;
use aer_ccm::traction::TractionControl;
use aer_ccm::vehicle::{State, Vehicle, VehicleInputs};
use aer_ccm::{Ccm, DriverInputs, SensorSample};
use aer_flexcan::CanFrame;
use aer_isotp::{Config, Received, Receiver};
use embedded_can::{Frame, StandardId};

const CAL: AppsCalibration = AppsCalibration::DEFAULT;

/// Raw counts for a pedal travel on each sensor.
fn pedal(travel1: f32, travel2: f32) -> (f32, f32) {
    let raw = |(rest, full): (f32, f32), t: f32| rest + t * (full - rest);
    (raw(CAL.apps1, travel1), raw(CAL.apps2, travel2))
}

// --- APPS --------------------------------------------------------------------------------------

#[test]
fn apps_maps_the_calibration_to_0_1_and_takes_the_lower_sensor() {
    let mut apps = Apps::new(1);
    let (a, b) = pedal(0.5, 0.5);
    let reading = apps.update(&CAL, [Some(a), Some(b)], false, 0);
    assert!((reading.travel - 0.5).abs() < 1e-3, "{reading:?}");
    let (a, b) = pedal(1.3, -0.2);
    let mut clamped = Apps::new(1);
    let reading = clamped.update(&CAL, [Some(a), Some(b)], false, 0);
    assert_eq!((reading.apps1, reading.apps2), (1.0, 0.0));
}

#[test]
fn apps_range_fault_needs_more_than_100_ms() {
    let mut apps = Apps::new(1);
    // 0.2 V on APPS1: below 10 % of 3.3 V (an open wire pulls the signal low).
    let low = 0.2;
    let (_, b) = pedal(0.0, 0.0);
    for t in 0..=100 {
        assert!(
            !apps
                .update(&CAL, [Some(low), Some(b)], false, t)
                .out_of_range,
            "t = {t}"
        );
    }
    assert!(
        apps.update(&CAL, [Some(low), Some(b)], false, 101)
            .out_of_range
    );
    let (a, b) = pedal(0.0, 0.0);
    // The filter needs a few samples to come back; the fault clears with it.
    let cleared = (102..200).any(|t| !apps.update(&CAL, [Some(a), Some(b)], false, t).out_of_range);
    assert!(cleared);
}

#[test]
fn apps_disagreement_over_10_percent_for_over_100_ms_is_implausible() {
    let mut apps = Apps::new(1);
    let (a, b) = pedal(0.50, 0.39);
    for t in 0..=100 {
        apps.update(&CAL, [Some(a), Some(b)], false, t);
    }
    assert!(!apps.reading().implausible, "at 100 ms");
    assert!(
        apps.update(&CAL, [Some(a), Some(b)], false, 101)
            .implausible
    );

    let mut close = Apps::new(1);
    let (a, b) = pedal(0.50, 0.41);
    for t in 0..500 {
        close.update(&CAL, [Some(a), Some(b)], false, t);
    }
    assert!(!close.reading().implausible, "9 % apart is plausible");
}

#[test]
fn apps_brake_plausibility_latches_above_25_percent_and_resets_below_5() {
    let mut apps = Apps::new(1);
    let mut t = 0;
    let mut hold = |apps: &mut Apps, travel: f32, brake: bool| {
        let (a, b) = pedal(travel, travel);
        let mut reading = apps.update(&CAL, [Some(a), Some(b)], brake, t);
        for _ in 0..50 {
            t += 1;
            reading = apps.update(&CAL, [Some(a), Some(b)], brake, t);
        }
        reading
    };
    assert!(
        !hold(&mut apps, 0.24, true).brake_plausibility,
        "24 % with brake"
    );
    assert!(
        hold(&mut apps, 0.26, true).brake_plausibility,
        "26 % with brake"
    );
    assert!(
        hold(&mut apps, 0.26, false).brake_plausibility,
        "latched without brake"
    );
    assert!(
        hold(&mut apps, 0.06, false).brake_plausibility,
        "6 %: still latched"
    );
    assert!(
        !hold(&mut apps, 0.04, false).brake_plausibility,
        "4 %: reset"
    );
}

// --- Brakes ------------------------------------------------------------------------------------

#[test]
fn brake_sensor_fault_light_and_circuits() {
    let mut brakes = Brakes::new(1);
    for t in 0..=100 {
        assert!(
            !brakes
                .update(&BrakeCalibration::DEFAULT, 4.6, volts_for(0.0), t)
                .sensor_fault,
            "t = {t}"
        );
    }
    assert!(
        brakes
            .update(&BrakeCalibration::DEFAULT, 4.6, volts_for(0.0), 101)
            .sensor_fault
    );

    let mut brakes = Brakes::new(1);
    let settle = |brakes: &mut Brakes, front: f32, rear: f32, from: u32| {
        (from..from + 50).for_each(|t| {
            brakes.update(
                &BrakeCalibration::DEFAULT,
                volts_for(front),
                volts_for(rear),
                t,
            );
        });
        brakes.reading()
    };
    assert!(
        !settle(&mut brakes, 25.0, 25.0, 0).engaged,
        "25 psi: not yet"
    );
    assert!(settle(&mut brakes, 35.0, 35.0, 50).engaged, "35 psi: on");
    assert!(
        settle(&mut brakes, 25.0, 25.0, 100).engaged,
        "hysteresis holds at 25 psi"
    );
    assert!(!settle(&mut brakes, 15.0, 15.0, 150).engaged, "15 psi: off");
    assert!(settle(&mut brakes, 60.0, 60.0, 200).engaged);

    // One circuit at 500 psi, the other empty, for over 500 ms.
    let mut brakes = Brakes::new(1);
    settle(&mut brakes, 500.0, 0.0, 0);
    for t in 50..=500 {
        brakes.update(
            &BrakeCalibration::DEFAULT,
            volts_for(500.0),
            volts_for(0.0),
            t,
        );
    }
    assert!(!brakes.reading().circuits_implausible);
    assert!(settle(&mut brakes, 500.0, 0.0, 560).circuits_implausible);
}

// --- Vehicle state machine ----------------------------------------------------------------------

struct Car {
    vehicle: Vehicle,
    inputs: VehicleInputs,
}

impl Car {
    fn new() -> Self {
        Self {
            vehicle: Vehicle::new(),
            inputs: VehicleInputs {
                now_ms: 0,
                pcc: None,
                rtm_button: false,
                brakes_engaged: false,
                faults: FaultMap::NONE,
            },
        }
    }

    /// Steps to `now` with the PCC's fresh status `pcc` (`None`: no fresh status).
    fn at(&mut self, now: u32, pcc: Option<PrechargeState>) -> State {
        self.inputs.now_ms = now;
        self.inputs.pcc = pcc;
        self.vehicle.step(&self.inputs).state
    }

    /// OFF -> STANDBY -> PRECHARGING -> IDLE, ending at `now` = 100.
    fn idle(&mut self) {
        assert_eq!(self.at(0, None), State::Off);
        assert_eq!(self.at(10, Some(PrechargeState::Standby)), State::Standby);
        assert_eq!(
            self.at(20, Some(PrechargeState::Precharge)),
            State::Precharging
        );
        assert_eq!(self.at(100, Some(PrechargeState::Online)), State::Idle);
    }

    /// Presses the button with the brake from `from`; returns when the sound started.
    fn press(&mut self, from: u32) -> u32 {
        self.inputs.rtm_button = true;
        self.inputs.brakes_engaged = true;
        let mut t = from;
        loop {
            self.at(t, Some(PrechargeState::Online));
            if self.vehicle.step(&self.inputs).rtd_sound {
                break;
            }
            t += 10;
        }
        self.inputs.rtm_button = false;
        t
    }
}

#[test]
fn driving_needs_button_brake_and_the_full_ready_to_drive_sound() {
    let mut car = Car::new();
    car.idle();
    // Button without brake: nothing.
    car.inputs.rtm_button = true;
    for t in (110..500).step_by(10) {
        assert_eq!(car.at(t, Some(PrechargeState::Online)), State::Idle);
    }
    car.inputs.rtm_button = false;
    car.at(510, Some(PrechargeState::Online));

    let started = car.press(520);
    assert!(started - 520 >= 200, "debounced: {started}");
    let outputs = car.vehicle.step(&car.inputs);
    assert!(outputs.rtd_sound && !outputs.torque_enabled);
    assert_eq!(
        car.at(started + 1_999, Some(PrechargeState::Online)),
        State::Idle
    );
    assert_eq!(
        car.at(started + 2_000, Some(PrechargeState::Online)),
        State::Driving
    );
    let outputs = car.vehicle.step(&car.inputs);
    assert!(outputs.torque_enabled && !outputs.rtd_sound);
}

#[test]
fn a_stale_or_lost_precharge_leaves_driving_at_once() {
    let mut car = Car::new();
    car.idle();
    let started = car.press(200);
    let driving_at = started + 2_000;
    assert_eq!(
        car.at(driving_at, Some(PrechargeState::Online)),
        State::Driving
    );
    // The bus layer stops vouching for a status older than 100 ms (tested in `bus`).
    assert_eq!(car.at(driving_at + 10, None), State::Standby);
}

#[test]
fn faults_stop_the_vehicle_and_clear_to_standby() {
    let mut car = Car::new();
    car.idle();
    let started = car.press(200);
    car.at(started + 2_000, Some(PrechargeState::Online));
    let mut faults = FaultMap::NONE;
    faults.set(Fault::Bse, true);
    car.inputs.faults = faults;
    assert_eq!(
        car.at(started + 2_010, Some(PrechargeState::Online)),
        State::Fault
    );
    car.inputs.faults = FaultMap::NONE;
    assert_eq!(
        car.at(started + 2_020, Some(PrechargeState::Online)),
        State::Standby
    );
    assert_eq!(
        car.at(started + 2_030, Some(PrechargeState::Online)),
        State::Idle,
        "needs the button again"
    );

    // The plausibility fault cuts torque (elsewhere) but keeps DRIVING.
    let mut plausibility = FaultMap::NONE;
    plausibility.set(Fault::AppsBrakePlausibility, true);
    assert!(!plausibility.stops_the_vehicle());
    // A PCC error is a fault too (the fault monitor raises it; here, as the state machine
    // receives it).
    let mut pcc_error = FaultMap::NONE;
    pcc_error.set(Fault::PccError, true);
    car.inputs.faults = pcc_error;
    assert_eq!(
        car.at(started + 2_040, Some(PrechargeState::Error)),
        State::Fault
    );
}

#[test]
fn a_second_press_leaves_driving() {
    let mut car = Car::new();
    car.idle();
    let started = car.press(200);
    car.at(started + 2_000, Some(PrechargeState::Online));
    car.inputs.rtm_button = false;
    car.at(started + 2_010, Some(PrechargeState::Online));
    car.inputs.rtm_button = true;
    let left = (started + 2_020..started + 3_000)
        .step_by(10)
        .find(|t| car.at(*t, Some(PrechargeState::Online)) == State::Idle);
    assert!(left.is_some());
}

// --- Inverter frames -----------------------------------------------------------------------------

#[test]
fn vcu1_counts_and_carries_a_valid_checksum() {
    let mut builder = Vcu1Builder::default();
    let command = DriveCommand {
        torque_nm: 101.92,
        drive: true,
        main_relay: true,
        precharging: false,
        brakes_engaged: false,
        discharge_limit_a: 300.0,
    };
    for expected_counter in (0..16).chain(0..4) {
        let (_, data) = builder.next_frame(&command).unwrap();
        let vcu1 = Vcu1::decode(&data).unwrap();
        assert_eq!(vcu1.vcu_rolling_counter, expected_counter);
        assert_eq!(
            data[7],
            data[..7].iter().fold(0u8, |sum, b| sum.wrapping_add(*b)) ^ 0xFF,
            "byte 7 = (sum of bytes 0..6) ^ 0xFF"
        );
        assert!(
            (vcu1.vcu_torque_req - 101.92).abs() < 1e-9,
            "100 raw = 101.92 Nm"
        );
        assert_eq!(data[0], 100);
    }
    let (_, over) = builder
        .next_frame(&DriveCommand {
            torque_nm: 400.0,
            ..command
        })
        .unwrap();
    assert_eq!(over[0], 255, "clamped to the frame's 259.9 Nm");
    let (_, nan) = builder
        .next_frame(&DriveCommand {
            torque_nm: f32::NAN,
            ..command
        })
        .unwrap();
    assert_eq!(nan[0], 0);
}

/// The schema's power trim gain.
const GAIN: f32 = Calibration::DEFAULT.power_trim_gain;

// --- Cooling, traction ---------------------------------------------------------------------------

#[test]
fn cooling_ramps_with_temperature() {
    assert_eq!(cooling(&Calibration::DEFAULT, false, 20.0, 20.0).pump, 0.0);
    assert_eq!(cooling(&Calibration::DEFAULT, true, 20.0, 20.0).pump, 0.3);
    assert_eq!(cooling(&Calibration::DEFAULT, true, 60.0, 20.0).pump, 1.0);
    assert_eq!(cooling(&Calibration::DEFAULT, true, 20.0, 20.0).fan, 0.0);
    assert!((cooling(&Calibration::DEFAULT, true, 20.0, 57.5).fan - 0.5).abs() < 1e-6);
    assert_eq!(
        cooling(&Calibration::DEFAULT, true, f32::NAN, 20.0).fan,
        1.0
    );
}

#[test]
fn traction_control_only_removes_torque_and_returns_it() {
    let mut traction = TractionControl::new(10);
    for _ in 0..100 {
        assert_eq!(
            traction.step(&Calibration::DEFAULT, 50.0, 52.0, 200.0),
            200.0,
            "4 % slip: untouched"
        );
    }
    let mut reduced = 200.0;
    for _ in 0..20 {
        reduced = traction.step(&Calibration::DEFAULT, 50.0, 70.0, 200.0);
    }
    assert!(reduced < 150.0, "40 % slip: {reduced}");
    let mut recovered = reduced;
    for _ in 0..300 {
        recovered = traction.step(&Calibration::DEFAULT, 50.0, 51.0, 200.0);
    }
    assert_eq!(recovered, 200.0);
    let mut rolling_off = TractionControl::new(10);
    assert_eq!(
        rolling_off.step(&Calibration::DEFAULT, 1.0, 30.0, 120.0),
        120.0,
        "below 3 rad/s slip is undefined"
    );
}

// --- The whole CCM: bus intake and telemetry over ISO-TP ----------------------------------------

fn frame(id: u16, data: &[u8]) -> CanFrame {
    CanFrame::new(StandardId::new(id).unwrap(), data).unwrap()
}

#[test]
fn bus_frames_fill_the_mirror_and_bad_ones_are_counted() {
    let mut ccm = Ccm::new(Calibration::DEFAULT);
    let status = PccStatus {
        pcc_state: PrechargeState::Online,
        pcc_error_too_fast: false,
        pcc_error_air_plus_open: false,
        pcc_error_converters_disagree: false,
        pcc_error_bypassed: false,
        pcc_error_resistor_hot: false,
        pcc_accumulator_no_pulses: false,
        pcc_tractive_no_pulses: false,
        pcc_error_accumulator_silent: false,
        pcc_error_tractive_silent: false,
        pcc_error_no_discharge: false,
        pcc_error_too_slow: false,
        pcc_error_bms_timeout: false,
        pcc_error_shutdown: false,
        pcc_error_undefined_state: false,
        pcc_accumulator_voltage: 398.0,
        pcc_tractive_voltage: 397.0,
        pcc_precharge_progress: 99.7,
    };
    let mut data = [0u8; 8];
    status.encode(&mut data).unwrap();
    ccm.on_frame(&frame(0x222, &data), 5);
    assert_eq!(
        ccm.bus().pcc.fresh(5, 0).map(|status| status.pcc_state),
        Some(PrechargeState::Online)
    );
    ccm.on_frame(&frame(0x222, &data[..4]), 6);
    ccm.on_frame(&frame(0x123, &data), 7);
    assert_eq!(ccm.bus().decode_errors, 1);
    assert_eq!(ccm.bus().unknown_ids, 1);
    // Every drop reaches the Pi in telemetry.
    ccm.set_driver_counters(aer_ccm::DriverCounters {
        rx_dropped: 3,
        tx_dropped: 257,
        ..aer_ccm::DriverCounters::default()
    });
    let snapshot = ccm.snapshot();
    assert_eq!(snapshot.can_decode_errors, 2);
    assert_eq!(snapshot.can_rx_dropped, 3);
    assert_eq!(snapshot.can_tx_dropped, 1, "wraps at 256");
}

#[test]
fn the_telemetry_packet_reaches_an_iso_tp_receiver_intact() {
    let mut ccm = Ccm::new(Calibration::DEFAULT);
    let (a, b) = pedal(0.4, 0.4);
    for t in 0..20 {
        ccm.sample(
            &SensorSample {
                apps_v: [Some(a), Some(b)],
                brake_v: (volts_for(10.0), volts_for(10.0)),
                shock_raw: [4095, 4081, 4067, 4053],
            },
            t,
        );
    }
    ccm.control(DriverInputs::default(), 20, 20_000);
    let expected = ccm.snapshot();
    ccm.send_telemetry(30_000);

    let mut receiver: Receiver<128> = Receiver::new(Config::CAR);
    let mut now = 30_000;
    let mut delivered = None;
    while delivered.is_none() {
        let Some(out) = ccm.link().poll(now) else {
            panic!("the sender stalled");
        };
        ccm.link().sent(now);
        match receiver.on_frame(out.as_slice(), now).unwrap() {
            Received::FlowControl(reply) => ccm.link().on_flow_control(reply.as_slice(), now),
            Received::Message(message) => delivered = Some(message.to_vec()),
            Received::Nothing => {}
        }
        now += 250;
    }
    let (header, telemetry) = Telemetry::unpack(&delivered.unwrap()).unwrap();
    assert_eq!(header.timestamp_us, 30_000);
    assert_eq!(telemetry.vehicle_state, aer::can::VehicleState::Off);
    assert!((telemetry.apps_travel - expected.apps_travel).abs() <= 0.2);
    assert!((telemetry.shocktravel2 - expected.shocktravel2).abs() <= 0.005);
    assert_eq!(ccm.link().counters().sent, 1);
    // The mirror is the generated apply(): a CCM_Status decoded elsewhere reads the same.
    let status = ccm.status();
    let mut from_status = aer::telemetry::TelemetryMirror::EMPTY;
    from_status.apply(&AnyMessage::CcmStatus(status));
    assert_eq!(from_status.vehicle_state, telemetry.vehicle_state);
}

// --- Freshness, torque monitor, power limiter --------------------------------------------------

#[test]
fn a_received_value_is_fresh_up_to_its_limit_and_lost_after_it_or_after_the_grace_period() {
    use aer_ccm::bus::Received;
    use aer_ccm::constants::START_UP_GRACE_MS;
    let mut received: Received<u8> = Received::default();
    assert!(
        !received.lost(START_UP_GRACE_MS, 100, 0),
        "within the start-up grace"
    );
    assert!(
        received.lost(START_UP_GRACE_MS + 1, 100, 0),
        "never heard after it"
    );
    received.store(7, 1_000);
    assert_eq!(received.fresh(1_100, 100), Some(7));
    assert!(!received.lost(1_100, 100, 0));
    assert_eq!(received.fresh(1_101, 100), None);
    assert!(received.lost(1_101, 100, 0));
    // The millisecond clock wraps.
    received.store(8, u32::MAX - 10);
    assert_eq!(received.fresh(20, 100), Some(8));
}

const CAR: aer_ccm::power::PowerLimits = aer_ccm::power::PowerLimits::CAR;

/// The monitor bounds the accumulator's power by the rule on its own: at the efficiency the
/// readings show, less its small margin; a lowered limit (an endurance cap) moves the bound
/// with it.
#[test]
fn the_monitor_bounds_the_rules_power_at_its_efficiency() {
    use aer_ccm::constants::{DRIVETRAIN_EFFICIENCY, MONITOR_MARGIN};
    use aer_ccm::monitor::{MonitorInputs, allowed_torque};
    use aer_ccm::power::PowerLimits;
    let omega = 500.0;
    let at = |efficiency: f32, limits: &PowerLimits| {
        allowed_torque(
            &MonitorInputs {
                motor_rad_s: Some(omega),
                efficiency,
                ..monitor_inputs()
            },
            limits,
        )
    };
    let close = |got: f32, want: f32| (got - want).abs() < 0.01;
    let bounded = 80_000.0 * (1.0 - MONITOR_MARGIN);
    assert!(close(at(0.88, &CAR), 0.88 * bounded / omega));
    // An efficiency outside the drivetrain's range is taken at its edge.
    let (lowest, highest) = DRIVETRAIN_EFFICIENCY;
    assert!(close(at(1.5, &CAR), highest * bounded / omega));
    assert!(close(at(0.1, &CAR), lowest * bounded / omega));
    // An endurance cap of 70 kW: the monitor's bound follows the limit, and so does the
    // limiter's target.
    let capped = PowerLimits::for_rule(70_000.0);
    assert!(close(at(0.88, &capped), 0.88 * 0.99 * 70_000.0 / omega));
    assert!((capped.power_target_w - 68_250.0).abs() < 0.5);
}

/// The monitor's efficiency comes from the readings, never from the limiter: it starts at
/// the lowest, falls at once with a lower reading, rises only once the DC reading has caught
/// up with the torque (the readings lag) and then step by step, and returns to the lowest
/// while the power is too small to measure it.
#[test]
fn the_monitors_efficiency_trusts_a_reading_only_once_it_settled() {
    use aer_ccm::constants::{DRIVETRAIN_EFFICIENCY, EFFICIENCY_RISE_PER_STEP};
    use aer_ccm::monitor::EfficiencyBound;
    let (lowest, highest) = DRIVETRAIN_EFFICIENCY;
    let mut bound = EfficiencyBound::new(10);
    assert_eq!(bound.efficiency(), lowest);
    // Torque rose; the DC reading is still catching up: shaft over DC reads 1.2, untrusted.
    for dc in [30_000.0, 45_000.0, 55_000.0] {
        assert_eq!(bound.update(Some(66_000.0), Some(dc), &CAR), lowest, "{dc}");
    }
    // Settled at 0.94: rises step by step, never past the reading.
    let mut last = lowest;
    for _ in 0..100 {
        let now = bound.update(Some(65_800.0), Some(70_000.0), &CAR);
        assert!(
            now - last <= EFFICIENCY_RISE_PER_STEP + 1e-6,
            "{last} -> {now}"
        );
        last = now;
    }
    assert!((last - 0.94).abs() < 1e-4, "{last}");
    // A lower reading lowers it at once, settled or not.
    assert!(
        (bound.update(Some(61_600.0), Some(80_000.0), &CAR) - 0.77f32.max(lowest)).abs() < 1e-4
    );
    // A reading above the highest efficiency is cut to it.
    for _ in 0..100 {
        bound.update(Some(79_000.0), Some(70_000.0), &CAR);
    }
    assert_eq!(bound.efficiency(), highest);
    // Too little power to measure: back towards the lowest.
    for _ in 0..300 {
        bound.update(Some(1_000.0), Some(1_100.0), &CAR);
    }
    assert!(bound.efficiency() - lowest < 1e-3);
    // No reading at all: the same.
    assert!(bound.update(None, None, &CAR) - lowest < 1e-3);
}

fn monitor_inputs() -> aer_ccm::monitor::MonitorInputs {
    aer_ccm::monitor::MonitorInputs {
        torque_enabled: true,
        faults: FaultMap::NONE,
        apps: aer_ccm::apps::AppsReading {
            travel: 1.0,
            apps1: 1.0,
            apps2: 1.0,
            ..Default::default()
        },
        sensors_fresh: true,
        motor_rad_s: Some(100.0),
        soc: Some(0.8),
        inverter_max_nm: Some(259.896),
        dc_power_w: Some(20_000.0),
        efficiency: 0.94,
    }
}

#[test]
fn the_monitor_allows_the_least_of_pedal_power_soc_motor_and_inverter() {
    use aer_ccm::monitor::{MonitorInputs, allowed_torque};
    let full = monitor_inputs();
    assert!(
        (allowed_torque(&full, &CAR) - 259.896).abs() < 1e-3,
        "inverter maximum"
    );
    // The rule's 80 kW less the monitor's 1 % out of the accumulator at its efficiency
    // (0.94) at 400 rad/s: 186.1 Nm.
    let fast = MonitorInputs {
        motor_rad_s: Some(400.0),
        ..full
    };
    assert!(
        (allowed_torque(&fast, &CAR) - 0.94 * 79_200.0 / 400.0).abs() < 0.01,
        "{}",
        allowed_torque(&fast, &CAR)
    );
    let low_soc = MonitorInputs {
        soc: Some(0.125),
        ..full
    };
    assert!((allowed_torque(&low_soc, &CAR) - 130.0).abs() < 0.01);
    // One sensor failing high cannot raise the request above the other.
    let mut apps = full.apps;
    apps.apps1 = 1.0;
    apps.apps2 = 0.3;
    apps.travel = 0.65;
    let split = MonitorInputs { apps, ..full };
    let bound = (0.3 - 0.02) / 0.98 * 260.0;
    assert!(
        (allowed_torque(&split, &CAR) - bound).abs() < 0.01,
        "{}",
        allowed_torque(&split, &CAR)
    );
}

#[test]
fn the_monitor_allows_nothing_without_fresh_inputs_or_with_a_stopping_fault() {
    use aer_ccm::monitor::{MonitorInputs, allowed_torque};
    let full = monitor_inputs();
    for stale in [
        MonitorInputs {
            motor_rad_s: None,
            ..full
        },
        MonitorInputs { soc: None, ..full },
        MonitorInputs {
            inverter_max_nm: None,
            ..full
        },
        MonitorInputs {
            dc_power_w: None,
            ..full
        },
        MonitorInputs {
            sensors_fresh: false,
            ..full
        },
        MonitorInputs {
            torque_enabled: false,
            ..full
        },
        MonitorInputs {
            soc: Some(f32::NAN),
            ..full
        },
        MonitorInputs {
            motor_rad_s: Some(f32::NAN),
            ..full
        },
    ] {
        assert_eq!(allowed_torque(&stale, &CAR), 0.0, "{stale:?}");
    }
    for fault in Fault::ALL {
        let mut faults = FaultMap::NONE;
        faults.set(fault, true);
        let allowed = allowed_torque(&MonitorInputs { faults, ..full }, &CAR);
        if fault.reaction() == aer_ccm::faults::Reaction::Warn {
            assert!(allowed > 0.0, "{fault:?} is a warning");
        } else {
            assert_eq!(allowed, 0.0, "{fault:?}");
        }
    }
}

#[test]
fn the_power_ceiling_starts_safe_trims_up_only_when_settled_and_down_at_once() {
    use aer_ccm::constants::DRIVETRAIN_EFFICIENCY;
    use aer_ccm::power::{PowerLimiter, PowerLimits};
    let (lowest, highest) = DRIVETRAIN_EFFICIENCY;
    let target = PowerLimits::CAR.power_target_w;
    let mut limiter = PowerLimiter::new(10, target);
    let omega = 350.0;
    let first = limiter.step(GAIN, omega, 0.0, 260.0);
    assert!((first - lowest * target / omega).abs() < 0.5, "{first}");
    // The measurement still rising: no trim up.
    for measured in [10_000.0, 30_000.0, 50_000.0, 65_000.0] {
        limiter.step(GAIN, omega, measured, 260.0);
        assert_eq!(
            limiter.efficiency(),
            lowest,
            "while the measurement catches up"
        );
    }
    // Settled below the target: trims up, towards (not past) the highest efficiency.
    for _ in 0..200 {
        limiter.step(GAIN, omega, 70_000.0, 260.0);
    }
    assert_eq!(limiter.efficiency(), highest);
    // Above the target: down at once, settled or not.
    let before = limiter.efficiency();
    limiter.step(GAIN, omega, 90_000.0, 260.0);
    assert!(limiter.efficiency() < before);
    // Not binding: back to the lowest efficiency.
    for _ in 0..500 {
        limiter.step(GAIN, omega, 20_000.0, 10.0);
    }
    assert!(limiter.efficiency() - lowest < 1e-3);
}

#[test]
fn the_torque_request_has_a_rest_deadband_and_reaches_the_maximum() {
    use aer_ccm::torque_path::torque_request;
    assert_eq!(torque_request(0.0), 0.0);
    assert_eq!(
        torque_request(0.019),
        0.0,
        "sensor noise at rest asks for nothing"
    );
    assert_eq!(torque_request(1.0), 260.0);
    assert_eq!(torque_request(f32::NAN), 0.0);
    assert!(torque_request(0.51) > torque_request(0.5));
}

#[test]
fn inverter_fault_bits_stop_the_car_and_warnings_are_reported() {
    use aer::can::{Mcu2, McuWarningLevel};
    use aer_ccm::inverter::ifl100::condition as inverter_condition;
    let quiet = aer_m7_check_free_quiet_mcu2();
    assert_eq!(inverter_condition(&quiet), (false, false));
    let stall = Mcu2 {
        mcu_motor_stall_fault: true,
        ..quiet
    };
    assert_eq!(inverter_condition(&stall), (true, false));
    let high = Mcu2 {
        mcu_warning_level: McuWarningLevel::High,
        ..quiet
    };
    assert_eq!(inverter_condition(&high), (true, false));
    let unknown = Mcu2 {
        mcu_warning_level: McuWarningLevel::Unknown(7),
        ..quiet
    };
    assert_eq!(inverter_condition(&unknown), (true, false));
    let low_12v = Mcu2 {
        mcu_12v_low_volt_warning: true,
        ..quiet
    };
    assert_eq!(inverter_condition(&low_12v), (false, true));
    let medium = Mcu2 {
        mcu_warning_level: McuWarningLevel::Medium,
        ..quiet
    };
    assert_eq!(inverter_condition(&medium), (false, true));
}

fn aer_m7_check_free_quiet_mcu2() -> aer::can::Mcu2 {
    aer::can::Mcu2 {
        mcu_motor_temp: 40,
        mcu_inverter_temp: 35,
        mcu_dc_main_wire_over_curr_fault: false,
        mcu_motor_phase_curr_fault: false,
        mcu_over_hot_fault: false,
        mcu_resolver_fault: false,
        mcu_phase_curr_sensor_fault: false,
        mcu_motor_over_spd_fault: false,
        mcu_drv_motor_over_hot_fault: false,
        mcu_dc_main_wire_over_volt_fault: false,
        mcu_drv_motor_over_cool_fault: false,
        mcu_motor_system_state: false,
        mcu_temp_sensor_state: false,
        mcu_motor_temp_sensor_state: false,
        mcu_dc_volt_sensor_state: false,
        mcu_dc_low_volt_warning: false,
        mcu_12v_low_volt_warning: false,
        mcu2_rolling_counter: 0,
        mcu_warning_level: aer::can::McuWarningLevel::None,
        mcu_motor_open_phase_fault: false,
        mcu_motor_stall_fault: false,
    }
}

proptest::proptest! {
    /// The lock-free timers the edge interrupt writes give the control step exactly the
    /// speed the plain sensor computes from the same pulses.
    #[test]
    fn pulse_timers_read_what_the_pulses_say(
        gaps in proptest::collection::vec(1u32..200_000, 0..20),
        start in proptest::prelude::any::<u32>(),
        later in 0u32..1_000_000,
    ) {
        use aer_ccm::chassis::{PulseTimer, WheelSpeed};
        let timer = PulseTimer::new();
        let mut plain = WheelSpeed::new(24);
        let mut now = start;
        for gap in gaps {
            now = now.wrapping_add(gap);
            timer.on_pulse(now);
            plain.on_pulse(now);
        }
        let read = timer.speed(24);
        proptest::prop_assert_eq!(read, plain);
        let at = now.wrapping_add(later);
        proptest::prop_assert_eq!(read.rpm(at).to_bits(), plain.rpm(at).to_bits());
        proptest::prop_assert_eq!(timer.clone().speed(24), plain);
    }
}
