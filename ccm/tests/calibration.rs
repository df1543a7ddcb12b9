//! The sensor calibration: the bands it is checked against, the committed
//! `ccm/calibration.toml` the firmware images start with, the bench's recorder, and the brake
//! sensors' zero in the pressure the CCM computes.

use aer_ccm::brakes::{Brakes, volts_for};
use aer_ccm::calibration::AppsCalibration;
use aer_ccm::calibration::bench::{NothingToSave, PedalResult};
use aer_ccm::calibration::{
    BenchPoint, BenchRecorder, BenchSample, BrakeCalibration, CALIBRATION_SAMPLES,
    CalibrationError, SensorCalibration, ShockCalibration, ShockEnd, measured,
};

#[test]
fn the_committed_calibration_passes_its_check() {
    if let Err(error) = measured::MEASURED.check() {
        panic!("ccm/calibration.toml ({}): {error}", measured::SOURCE);
    }
    assert_eq!(SensorCalibration::DEFAULT.check(), Ok(()));
}

fn with_pedals(apps1: (f32, f32), apps2: (f32, f32)) -> SensorCalibration {
    SensorCalibration {
        pedals: AppsCalibration { apps1, apps2 },
        ..SensorCalibration::DEFAULT
    }
}

#[test]
fn a_pedal_point_outside_its_sensors_valid_band_is_refused() {
    // APPS1 runs on 3.3 V: its band is 0.33-2.97 V; APPS2 on 5 V: 0.5-4.5 V.
    let low_rest = with_pedals((0.30, 2.8), (0.75, 4.2)).check();
    assert!(matches!(
        low_rest,
        Err(CalibrationError::PedalOutOfBand {
            sensor: "APPS1",
            point: "at rest",
            ..
        })
    ));
    assert_eq!(
        low_rest.unwrap_err().to_string(),
        "APPS1 at rest reads 0.300 V, outside its valid band 0.330-2.970 V (a sensor fault there)"
    );
    assert!(matches!(
        with_pedals((0.5, 2.8), (0.75, 4.6)).check(),
        Err(CalibrationError::PedalOutOfBand {
            sensor: "APPS2",
            point: "at full travel",
            ..
        })
    ));
    assert!(
        with_pedals((0.5, f32::NAN), (0.75, 4.2)).check().is_err(),
        "not a number is not inside any band"
    );
    assert_eq!(
        with_pedals((0.331, 2.969), (0.501, 4.499)).check(),
        Ok(()),
        "just inside the bands"
    );
}

#[test]
fn a_sensor_that_barely_moves_is_refused_in_either_direction() {
    assert_eq!(
        with_pedals((0.5, 0.9), (0.75, 4.2))
            .check()
            .unwrap_err()
            .to_string(),
        "APPS1 moves 0.400 V over the pedal's travel, less than 0.5 V"
    );
    assert_eq!(
        with_pedals((2.8, 0.5), (4.2, 0.75)).check(),
        Ok(()),
        "a sensor whose voltage falls with travel is fine"
    );
}

#[test]
fn a_brake_zero_outside_its_band_is_refused() {
    let with_zero = |front_zero_v, rear_zero_v| SensorCalibration {
        brakes: BrakeCalibration {
            front_zero_v,
            rear_zero_v,
        },
        ..SensorCalibration::DEFAULT
    };
    assert!(matches!(
        with_zero(0.49, 0.5).check(),
        Err(CalibrationError::BrakeZeroOutOfBand {
            circuit: "front (BSE1)",
            ..
        })
    ));
    assert!(matches!(
        with_zero(0.5, 0.8).check(),
        Err(CalibrationError::BrakeZeroOutOfBand {
            circuit: "rear (BSE2)",
            ..
        })
    ));
    assert_eq!(with_zero(0.52, 0.61).check(), Ok(()));
}

#[test]
fn a_brake_sensors_zero_is_where_its_pressure_starts() {
    // A sensor reading 0.58 V released is 40 psi on the nominal 0.5 V zero: the brakes would
    // count as engaged (30 psi) with nobody on the pedal. Calibrated, it reads 0 psi.
    let offset = BrakeCalibration {
        front_zero_v: 0.58,
        rear_zero_v: 0.58,
    };
    let mut nominal = Brakes::new(1);
    let mut calibrated = Brakes::new(1);
    for t in 0..200 {
        nominal.update(&BrakeCalibration::DEFAULT, 0.58, 0.58, t);
        calibrated.update(&offset, 0.58, 0.58, t);
    }
    assert!(nominal.reading().engaged);
    assert!(nominal.reading().front_psi > 30.0);
    assert!(!calibrated.reading().engaged);
    assert!(calibrated.reading().front_psi < 0.01);
    // The gain is the sensor's own: 4 V of span is full scale from either zero.
    let step = volts_for(500.0) - volts_for(0.0);
    for t in 200..400 {
        calibrated.update(&offset, 0.58 + step, 0.58 + step, t);
    }
    assert!((calibrated.reading().front_psi - 500.0).abs() < 1.0);
}

fn record(recorder: &mut BenchRecorder, point: BenchPoint, pedals: [f32; 2], brakes: [f32; 2]) {
    record_all(recorder, point, pedals, brakes, [4.2; 4]);
}

fn record_all(
    recorder: &mut BenchRecorder,
    point: BenchPoint,
    pedals: [f32; 2],
    brakes: [f32; 2],
    shocks: [f32; 4],
) {
    recorder.start(point);
    let mut step = 0u32;
    while recorder.recording() {
        // A little noise around the mean, and a missing pedal reading now and then.
        let wobble = (step % 5) as f32 * 0.002 - 0.004;
        let pedal_reading = if step % 97 == 0 {
            [None, Some(pedals[1])]
        } else {
            [Some(pedals[0] + wobble), Some(pedals[1] - wobble)]
        };
        let completed = recorder.sample(&BenchSample {
            pedals: pedal_reading,
            brakes: [brakes[0] + wobble, brakes[1]],
            shocks: shocks.map(|volts| volts + wobble),
        });
        step += 1;
        assert_eq!(
            completed.is_some(),
            !recorder.recording(),
            "the point is reported once, as it completes"
        );
    }
    if matches!(point, BenchPoint::Rest | BenchPoint::Full) {
        assert!(
            step > CALIBRATION_SAMPLES,
            "missing readings are not counted"
        );
    }
}

#[test]
fn the_bench_records_rest_and_full_and_prints_the_file_lines() {
    let mut recorder = BenchRecorder::default();
    assert_eq!(recorder.pedals(), PedalResult::Nothing);
    assert_eq!(recorder.measured(), Err(NothingToSave::NothingMeasured));
    record(
        &mut recorder,
        BenchPoint::Rest,
        [0.512, 0.771],
        [0.503, 0.508],
    );
    assert!(matches!(recorder.pedals(), PedalResult::RestOnly(_)));
    assert_eq!(recorder.measured(), Err(NothingToSave::NothingMeasured));
    record(&mut recorder, BenchPoint::Full, [2.793, 4.187], [1.9, 2.1]);
    let PedalResult::Complete(pedals, brakes, Ok(())) = recorder.pedals() else {
        panic!("{:?}", recorder.pedals());
    };
    let lines: Vec<String> = SensorCalibration {
        pedals,
        brakes,
        shocks: ShockCalibration::DEFAULT,
    }
    .pedal_toml_lines()
    .iter()
    .map(ToString::to_string)
    .collect();
    assert_eq!(
        lines,
        [
            "[pedals]",
            "apps1 = { rest_v = 0.512, full_v = 2.793 }",
            "apps2 = { rest_v = 0.771, full_v = 4.187 }",
            "[brakes]",
            "front_zero_v = 0.503",
            "rear_zero_v = 0.508",
        ]
    );
    let measured = recorder.measured().expect("pedals complete and checked");
    assert!(measured.shocks.is_none(), "shocks not measured");
    // Recording the rest point again with a sensor that sits too low: refused, with why, and
    // `cal save` refuses it too.
    record(
        &mut recorder,
        BenchPoint::Rest,
        [0.2, 0.771],
        [0.503, 0.508],
    );
    let PedalResult::Complete(_, _, Err(error)) = recorder.pedals() else {
        panic!("{:?}", recorder.pedals());
    };
    assert_eq!(
        recorder.pedals().to_string(),
        format!(
            "calibration: REFUSED, {error}; check the sensor and repeat (`cal save` and the firmware's build refuse these values too)"
        )
    );
    assert_eq!(recorder.measured(), Err(NothingToSave::Refused(error)));
}

fn shock(sensors: [bool; 4], end: ShockEnd) -> BenchPoint {
    BenchPoint::Shock { sensors, end }
}

#[test]
fn the_bench_records_each_shock_sensors_ends_and_the_file_lines() {
    let mut recorder = BenchRecorder::default();
    let all = [true; 4];
    let extended = [4.981, 4.975, 4.990, 4.968];
    record_all(
        &mut recorder,
        shock(all, ShockEnd::Extended),
        [0.5; 2],
        [0.5; 2],
        extended,
    );
    assert_eq!(
        recorder.shocks().to_string(),
        "shocks: fl 4.981 V / -, fr 4.975 V / -, rl 4.990 V / -, rr 4.968 V / - (extended / compressed); each still `-` needs its `cal shock`"
    );
    // One corner at a time: only that sensor's end is taken.
    let compressed = [4.842, 4.851, 4.839, 4.830];
    for corner in 0..4 {
        let mut sensors = [false; 4];
        sensors[corner] = true;
        // The other sensors read anything meanwhile (their dampers are not moved).
        let mut volts = [1.0; 4];
        volts[corner] = compressed[corner];
        record_all(
            &mut recorder,
            shock(sensors, ShockEnd::Compressed),
            [0.5; 2],
            [0.5; 2],
            volts,
        );
    }
    let Some((shocks, Ok(()))) = recorder.shocks().complete() else {
        panic!("{:?}", recorder.shocks());
    };
    for (got, want) in shocks.extended_v.iter().zip(extended) {
        assert!((got - want).abs() < 1e-3, "{got} {want}");
    }
    for (got, want) in shocks.compressed_v.iter().zip(compressed) {
        assert!((got - want).abs() < 1e-3, "{got} {want}");
    }
    let lines: Vec<String> = shocks
        .toml_lines()
        .iter()
        .map(ToString::to_string)
        .collect();
    assert_eq!(lines[0], "[shocks]");
    assert_eq!(
        lines[1],
        "fl = { extended_v = 4.981, compressed_v = 4.842 }"
    );
    assert_eq!(lines.len(), 5);
    let measured = recorder.measured().expect("shocks complete");
    assert!(measured.pedals.is_none() && measured.shocks.is_some());
    // A damper that was not really moved: refused.
    record_all(
        &mut recorder,
        shock([false, false, false, true], ShockEnd::Compressed),
        [0.5; 2],
        [0.5; 2],
        [0.0, 0.0, 0.0, 4.95],
    );
    let Some((_, Err(error))) = recorder.shocks().complete() else {
        panic!("{:?}", recorder.shocks());
    };
    assert_eq!(
        error.to_string(),
        "the rr shock sensor moves 0.018 V from extended to compressed, less than 0.05 V (was the damper really moved end to end?)"
    );
    assert_eq!(recorder.measured(), Err(NothingToSave::Refused(error)));
}

#[test]
fn shock_ends_outside_their_band_or_too_close_are_refused_either_way_round() {
    let with = |extended_v: [f32; 4], compressed_v: [f32; 4]| SensorCalibration {
        shocks: ShockCalibration {
            extended_v,
            compressed_v,
        },
        ..SensorCalibration::DEFAULT
    };
    assert_eq!(
        with([1.0; 4], [4.0; 4]).check(),
        Ok(()),
        "rising with compression"
    );
    assert!(matches!(
        with([5.0, 5.0, 0.1, 5.0], [4.86; 4]).check(),
        Err(CalibrationError::ShockOutOfBand {
            corner: "rl",
            point: "extended",
            ..
        })
    ));
    assert!(matches!(
        with([5.0; 4], [4.86, 4.98, 4.86, 4.86]).check(),
        Err(CalibrationError::ShockTooLittleTravel { corner: "fr", .. })
    ));
    assert!(with([f32::NAN; 4], [4.86; 4]).check().is_err());
}
