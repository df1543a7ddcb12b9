//! The live calibration: a change is checked whole and applied whole or not at all; what may
//! change depends on the vehicle's state; the reference page is the defaults; and
//! CCM_Calibration reports the checksum, the page, unsaved changes and the counts.

use aer::calibration::{PAGE_LEN, PARAMETERS, VehicleState};
use aer::can::{CcmCalibrationCcmCalPage, CcmCalibrationCcmCalStartup};
use aer_ccm::calibration::Calibration;
use aer_ccm::calibration::state::{CalibrationState, Page, Refused};
use aer_ccm::calibration::store::{Slot, Startup, crc32};

const PARKED: VehicleState = VehicleState {
    moving: false,
    tractive_live: false,
};
const DRIVING: VehicleState = VehicleState {
    moving: true,
    tractive_live: true,
};

fn offset_of(name: &str) -> usize {
    PARAMETERS
        .iter()
        .find(|p| p.name == name)
        .map(|p| p.offset)
        .unwrap_or_else(|| panic!("no parameter {name}"))
}

fn fresh() -> CalibrationState {
    CalibrationState::new(Calibration::DEFAULT, Startup::NoneSaved)
}

#[test]
fn a_gain_changes_while_driving_and_the_control_step_sees_it() {
    let mut state = fresh();
    let at = offset_of("traction_kp");
    assert_eq!(state.write(at, &650.0f32.to_le_bytes(), DRIVING), Ok(()));
    assert_eq!(state.active().traction_kp, 650.0);
    let status = state.status();
    assert_eq!(status.ccm_cal_changes, 1);
    assert!(status.ccm_cal_unsaved);
    assert_eq!(status.ccm_cal_checksum, crc32(state.page(Page::Working)));
    assert_ne!(
        status.ccm_cal_checksum,
        crc32(&Calibration::DEFAULT.to_page())
    );
}

#[test]
fn a_value_outside_its_limits_is_refused_and_nothing_changes() {
    let mut state = fresh();
    let before = state.clone();
    let at = offset_of("launch_kp");
    assert_eq!(
        state.write(at, &f32::NAN.to_le_bytes(), PARKED),
        Err(Refused::OutOfRange)
    );
    assert_eq!(
        state.write(at, &1.0e9f32.to_le_bytes(), PARKED),
        Err(Refused::OutOfRange)
    );
    assert_eq!(state.page(Page::Working), before.page(Page::Working));
    assert_eq!(state.active(), before.active());
    assert_eq!(state.status().ccm_cal_refusals, 2);
    assert_eq!(state.status().ccm_cal_changes, 0);
}

#[test]
fn a_standstill_parameter_is_refused_while_moving_and_accepted_when_stopped() {
    let mut state = fresh();
    let at = offset_of("launch_kp");
    let moving = VehicleState {
        moving: true,
        tractive_live: true,
    };
    assert_eq!(
        state.write(at, &150.0f32.to_le_bytes(), moving),
        Err(Refused::NotNow)
    );
    assert_eq!(state.active().launch_kp, Calibration::DEFAULT.launch_kp);
    let stopped_live = VehicleState {
        moving: false,
        tractive_live: true,
    };
    assert_eq!(
        state.write(at, &150.0f32.to_le_bytes(), stopped_live),
        Ok(())
    );
    assert_eq!(state.active().launch_kp, 150.0);
}

#[test]
fn a_pedal_pair_changes_in_one_transaction_or_not_at_all() {
    let mut state = fresh();
    let at = offset_of("apps1_v");
    // Rest and full travel together: 0.6 V and 2.7 V.
    let mut pair = [0u8; 8];
    pair[..4].copy_from_slice(&0.6f32.to_le_bytes());
    pair[4..].copy_from_slice(&2.7f32.to_le_bytes());
    let tractive_live = VehicleState {
        moving: false,
        tractive_live: true,
    };
    assert_eq!(state.write(at, &pair, tractive_live), Err(Refused::NotNow));
    assert_eq!(state.write(at, &pair, PARKED), Ok(()));
    assert_eq!(state.active().apps1_v, [0.6, 2.7]);
    // A full travel barely above rest: each value within its limits, the pair refused by the
    // sensor check.
    pair[4..].copy_from_slice(&0.62f32.to_le_bytes());
    assert_eq!(state.write(at, &pair, PARKED), Err(Refused::OutOfRange));
    assert_eq!(state.active().apps1_v, [0.6, 2.7]);
}

#[test]
fn bytes_outside_the_page_are_refused() {
    let mut state = fresh();
    assert_eq!(
        state.write(PAGE_LEN - 2, &[0; 4], PARKED),
        Err(Refused::NotMapped)
    );
    assert_eq!(
        state.write(usize::MAX, &[0; 4], PARKED),
        Err(Refused::NotMapped)
    );
}

#[test]
fn the_reference_page_is_the_defaults_and_switching_to_it_obeys_the_change_conditions() {
    let mut state = fresh();
    let launch = offset_of("launch_kp");
    assert_eq!(state.write(launch, &150.0f32.to_le_bytes(), PARKED), Ok(()));
    assert_eq!(state.page(Page::Reference), &Calibration::DEFAULT.to_page());
    // The launch gain differs between the pages: not while moving.
    assert_eq!(state.select(Page::Reference, DRIVING), Err(Refused::NotNow));
    assert_eq!(state.ecu_page(), Page::Working);
    assert_eq!(state.select(Page::Reference, PARKED), Ok(()));
    assert_eq!(*state.active(), Calibration::DEFAULT);
    let status = state.status();
    assert_eq!(status.ccm_cal_page, CcmCalibrationCcmCalPage::Reference);
    assert_eq!(
        status.ccm_cal_checksum,
        crc32(&Calibration::DEFAULT.to_page())
    );
    // Tuning the working page meanwhile does not touch the car until it is selected again.
    assert_eq!(
        state.write(launch, &120.0f32.to_le_bytes(), DRIVING),
        Ok(())
    );
    assert_eq!(*state.active(), Calibration::DEFAULT);
    assert_eq!(state.select(Page::Working, PARKED), Ok(()));
    assert_eq!(state.active().launch_kp, 120.0);
}

#[test]
fn reverting_copies_the_defaults_over_the_working_page() {
    let mut state = fresh();
    let traction = offset_of("traction_kp");
    assert_eq!(
        state.write(traction, &650.0f32.to_le_bytes(), DRIVING),
        Ok(())
    );
    assert_eq!(state.revert_to_reference(DRIVING), Ok(()));
    assert_eq!(*state.active(), Calibration::DEFAULT);
    assert!(!state.status().ccm_cal_unsaved);
}

#[test]
fn a_save_clears_unsaved_and_reports_where_it_went() {
    let mut state = fresh();
    let traction = offset_of("traction_kp");
    assert_eq!(
        state.write(traction, &650.0f32.to_le_bytes(), PARKED),
        Ok(())
    );
    assert!(state.status().ccm_cal_unsaved);
    state.saved(Startup::Saved {
        slot: Slot::B,
        generation: 7,
    });
    let status = state.status();
    assert!(!status.ccm_cal_unsaved);
    assert_eq!(status.ccm_cal_startup, CcmCalibrationCcmCalStartup::Saved);
}
