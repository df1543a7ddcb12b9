//! The generated calibration: the page round-trips, a value outside its limits never gets
//! through `from_page`, every byte of the page belongs to the parameter the table says, the
//! curve lookup stays between its values, and each change condition allows exactly what it
//! names.

use aer::calibration::{
    CALIBRATION_FINGERPRINT, Calibration, CalibrationError, ChangeWhen, PAGE_LEN, PARAMETERS,
    VehicleState, check_page, parameter_at,
};
use proptest::prelude::*;

#[test]
fn the_defaults_are_the_reference_page_and_round_trip() {
    let page = Calibration::DEFAULT.to_page();
    assert_eq!(check_page(&page), Ok(()));
    assert_eq!(Calibration::from_page(&page), Ok(Calibration::DEFAULT));
    assert_eq!(Calibration::default(), Calibration::DEFAULT);
    assert_ne!(CALIBRATION_FINGERPRINT, 0);
    // The schema's defaults, as the firmware has run them (team documentation).
    assert_eq!(Calibration::DEFAULT.launch_slip_target_at(3.0), 0.07);
    assert_eq!(Calibration::DEFAULT.traction_slip_threshold, 0.10);
    assert_eq!(Calibration::DEFAULT.apps1_v, [0.5, 2.8]);
}

#[test]
fn every_byte_of_the_page_belongs_to_one_parameter_or_to_padding() {
    let mut owner = [None; PAGE_LEN];
    for (index, p) in PARAMETERS.iter().enumerate() {
        assert!(
            !p.is_empty() && p.offset + p.len() <= PAGE_LEN,
            "{} fits",
            p.name
        );
        for byte in owner.iter_mut().skip(p.offset).take(p.len()) {
            assert_eq!(*byte, None, "{} overlaps", p.name);
            *byte = Some(index);
        }
    }
    for (offset, owner) in owner.iter().enumerate() {
        assert_eq!(
            parameter_at(offset).map(|p| p.name),
            owner.map(|i| PARAMETERS[i].name),
            "offset {offset}"
        );
    }
    assert_eq!(parameter_at(PAGE_LEN), None);
    assert_eq!(parameter_at(usize::MAX), None);
}

/// `page` with element `index` of `PARAMETERS[parameter]` set to `value` (f32 elements).
fn with_element(
    mut page: [u8; PAGE_LEN],
    parameter: usize,
    index: usize,
    value: f32,
) -> [u8; PAGE_LEN] {
    let p = &PARAMETERS[parameter];
    let at = p.offset + index * p.element.size();
    page[at..at + 4].copy_from_slice(&value.to_le_bytes());
    page
}

#[test]
fn a_value_outside_its_limits_or_not_a_number_is_refused_by_name() {
    let defaults = Calibration::DEFAULT.to_page();
    for (parameter, p) in PARAMETERS.iter().enumerate() {
        for index in 0..p.count {
            let below = (p.min as f32) - (p.min.abs() as f32).max(1.0) * 0.01;
            let above = (p.max as f32) + (p.max.abs() as f32).max(1.0) * 0.01;
            for value in [below, above, f32::NAN, f32::INFINITY] {
                let page = with_element(defaults, parameter, index, value);
                let refused = Calibration::from_page(&page);
                assert!(
                    matches!(
                        refused,
                        Err(CalibrationError::OutOfRange { parameter, index: i, .. })
                            if parameter == p.name && i == index
                    ),
                    "{}[{index}] = {value}: {refused:?}",
                    p.name
                );
            }
        }
    }
}

#[test]
fn an_increasing_pair_in_the_wrong_order_is_refused() {
    let parameter = PARAMETERS
        .iter()
        .position(|p| p.name == "fan_ramp_degc")
        .expect("fan ramp");
    let p = &PARAMETERS[parameter];
    assert!(p.increasing);
    let page = with_element(Calibration::DEFAULT.to_page(), parameter, 0, p.max as f32);
    let refused = Calibration::from_page(&page);
    assert_eq!(
        refused,
        Err(CalibrationError::NotIncreasing {
            parameter: "fan_ramp_degc",
            index: 1
        })
    );
    assert!(
        refused
            .err()
            .is_some_and(|e| e.to_string().contains("fan_ramp_degc[1]"))
    );
}

#[test]
fn each_change_condition_allows_what_it_names() {
    let state = |moving, tractive_live| VehicleState {
        moving,
        tractive_live,
    };
    for (moving, live) in [(false, false), (false, true), (true, false), (true, true)] {
        let now = state(moving, live);
        assert!(ChangeWhen::Driving.allows(now));
        assert_eq!(ChangeWhen::Standstill.allows(now), !moving);
        assert_eq!(ChangeWhen::TractiveOff.allows(now), !moving && !live);
    }
}

/// A page with every element drawn within its limits (increasing where it must be).
fn page_within_limits() -> impl Strategy<Value = [u8; PAGE_LEN]> {
    proptest::collection::vec(
        0.0f64..=1.0,
        PARAMETERS.iter().map(|p| p.count).sum::<usize>(),
    )
    .prop_map(|shares| {
        let mut page = [0; PAGE_LEN];
        let mut shares = shares.into_iter();
        for p in &PARAMETERS {
            let mut values: Vec<f64> = shares
                .by_ref()
                .take(p.count)
                .map(|s| p.min + s * (p.max - p.min))
                .collect();
            if p.increasing {
                // Spread evenly from the lowest drawn to the top, strictly increasing.
                values.sort_by(f64::total_cmp);
                let low = values.first().copied().unwrap_or(p.min).min(p.max - 1.0);
                let step = (p.max - low) / p.count as f64;
                values = (0..p.count).map(|i| low + step * i as f64).collect();
            }
            for (index, value) in values.into_iter().enumerate() {
                let at = p.offset + index * p.element.size();
                page[at..at + 4].copy_from_slice(&(value as f32).to_le_bytes());
            }
        }
        page
    })
}

proptest! {
    #[test]
    fn a_page_within_the_limits_round_trips(page in page_within_limits()) {
        let calibration = Calibration::from_page(&page);
        prop_assert!(calibration.is_ok(), "{calibration:?}");
        let calibration = calibration.unwrap_or_default();
        prop_assert_eq!(calibration.to_page(), page);
    }

    #[test]
    fn the_launch_curve_stays_between_its_values(
        values in proptest::array::uniform4(0.02f32..=0.25),
        speed in -10.0f32..40.0,
    ) {
        let calibration = Calibration { launch_slip_target: values, ..Calibration::DEFAULT };
        let slip = calibration.launch_slip_target_at(speed);
        let low = values.iter().copied().fold(f32::INFINITY, f32::min);
        let high = values.iter().copied().fold(f32::NEG_INFINITY, f32::max);
        prop_assert!((low..=high).contains(&slip), "{slip} outside {low}..={high}");
        for (point, value) in aer::calibration::LAUNCH_SLIP_TARGET_AXIS.iter().zip(values) {
            prop_assert_eq!(calibration.launch_slip_target_at(*point), value);
        }
        prop_assert_eq!(calibration.launch_slip_target_at(f32::NAN), values[0]);
    }
}
