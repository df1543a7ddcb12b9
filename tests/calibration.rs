//! The generated calibration: the page round-trips, a value outside its limits never gets
//! through `from_page`, every byte of the page belongs to the parameter the table says, the
//! curve lookup stays between its values, each change condition allows exactly what it
//! names, the internals' block is laid out as its table says and the XCP settings agree with
//! the DBC and the fingerprints.

use aer::calibration::{
    CALIBRATION_FINGERPRINT, Calibration, CalibrationError, ChangeWhen, PAGE_LEN, PARAMETERS,
    VehicleState, check_page, parameter_at,
};
use aer::calibration::{INTERNALS, Internals, xcp};
use aer::can::{XcpCmd, XcpRes};
use aer::telemetry::{TELEMETRY_FINGERPRINT, Telemetry};
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
        first in 0.0f32..10.0,
        gaps in proptest::array::uniform3(0.1f32..10.0),
        speed in -10.0f32..40.0,
    ) {
        // A tuned axis: any strictly increasing points the limits admit.
        let axis = [first, first + gaps[0], first + gaps[0] + gaps[1], first + gaps.iter().sum::<f32>()];
        let calibration = Calibration {
            launch_slip_target: values,
            launch_slip_target_axis: axis,
            ..Calibration::DEFAULT
        };
        prop_assert!(Calibration::from_page(&calibration.to_page()).is_ok());
        let slip = calibration.launch_slip_target_at(speed);
        let low = values.iter().copied().fold(f32::INFINITY, f32::min);
        let high = values.iter().copied().fold(f32::NEG_INFINITY, f32::max);
        prop_assert!((low..=high).contains(&slip), "{slip} outside {low}..={high}");
        for (point, value) in axis.iter().zip(values) {
            prop_assert_eq!(calibration.launch_slip_target_at(*point), value);
        }
        prop_assert_eq!(calibration.launch_slip_target_at(f32::NAN), values[0]);
    }
}

#[test]
fn the_internals_block_is_every_value_in_declared_order() {
    assert_eq!(Internals::LEN, INTERNALS.len() * 4);
    assert_eq!(Internals::default().to_bytes(), [0; Internals::LEN]);
    for (index, i) in INTERNALS.iter().enumerate() {
        assert_eq!(i.offset, index * 4, "{}", i.name);
        assert!(i.min < i.max && !i.unit.is_empty() && !i.description.is_empty());
    }
    let internals = Internals {
        driver_torque_nm: 120.5,
        slip_ratio: -0.25,
        torque_command_nm: -42.0,
        ..Internals::default()
    };
    let bytes = internals.to_bytes();
    let at = |name: &str| {
        let i = INTERNALS.iter().find(|i| i.name == name).expect(name);
        f32::from_le_bytes(bytes[i.offset..i.offset + 4].try_into().expect("4 bytes"))
    };
    assert_eq!(at("driver_torque_nm"), 120.5);
    assert_eq!(at("slip_ratio"), -0.25);
    assert_eq!(at("torque_command_nm"), -42.0);
    assert_eq!(at("power_efficiency"), 0.0);
}

#[test]
fn the_xcp_settings_agree_with_the_dbc_and_name_the_schema() {
    // The messages, the bit rate and the frame budget come from the DBC.
    assert_eq!(xcp::CAN_ID_MASTER, XcpCmd::ID);
    assert_eq!(xcp::CAN_ID_SLAVE, XcpRes::ID);
    const { assert!(!XcpCmd::EXTENDED && !XcpRes::EXTENDED) };
    assert_eq!((XcpCmd::LEN, XcpRes::LEN), (8, 8));
    let cycle = XcpRes::META.cycle_time_ms.expect("XCP_Res's frame budget");
    assert_eq!(xcp::DAQ_FRAMES_PER_S, 1000 / cycle);
    assert_eq!(xcp::BIT_RATE, 500_000);
    // The address map: four areas, apart, each holding what it names.
    let areas = [
        (xcp::CALIBRATION_ADDRESS, xcp::CALIBRATION_LEN),
        (xcp::TELEMETRY_ADDRESS, xcp::TELEMETRY_LEN),
        (xcp::INTERNALS_ADDRESS, xcp::INTERNALS_LEN),
        (xcp::EPK_ADDRESS, xcp::EPK.len()),
    ];
    for pair in areas.windows(2) {
        let [(a, len), (b, _)] = pair else { continue };
        assert!(*a as usize + len <= *b as usize, "{a:#x} overlaps {b:#x}");
    }
    assert_eq!(xcp::CALIBRATION_LEN, PAGE_LEN);
    assert_eq!(xcp::TELEMETRY_LEN, Telemetry::LEN);
    assert_eq!(xcp::INTERNALS_LEN, Internals::LEN);
    // The EPK names both fingerprints, so it changes with any layout.
    assert_eq!(
        xcp::EPK,
        format!("AER {TELEMETRY_FINGERPRINT:08X} {CALIBRATION_FINGERPRINT:08X}")
    );
    assert!(xcp::EPK.is_ascii());
    // One frame per packet; a block of DOWNLOAD_NEXTs holds the whole page; an ODT entry
    // holds an f32 and fits a DAQ packet after its PID.
    assert_eq!((xcp::MAX_CTO, xcp::MAX_DTO), (8, 8));
    assert!(usize::from(xcp::MAX_BS) * 6 >= PAGE_LEN);
    assert!((4..xcp::MAX_DTO).contains(&u16::from(xcp::MAX_ODT_ENTRY_SIZE)));
    const { assert!(xcp::ODT_ENTRIES >= xcp::MAX_DAQ) };
    // The events, numbered in order.
    assert_eq!(xcp::EVENTS.len(), 2);
    assert_eq!(xcp::EVENTS[usize::from(xcp::EVENT_CONTROL)].name, "control");
    assert_eq!(
        xcp::EVENTS[usize::from(xcp::EVENT_CONTROL)].period_us,
        10_000
    );
    assert_eq!(xcp::EVENTS[usize::from(xcp::EVENT_SENSORS)].name, "sensors");
    assert_eq!(
        xcp::EVENTS[usize::from(xcp::EVENT_SENSORS)].period_us,
        1_000
    );
}
