//! What the CCM does with PCC statuses no working PCC sends (a faulty PCC, a garbled frame
//! that still decodes): the race CCM's fault check calls them a PCC error, and `dti enable`
//! at high voltage does not take them for the PCC ONLINE.

use aer::can::{DtiFaultCode, PccStatus, PrechargeState};
use aer_ccm::console::dti::{DtiRefusal, Path};
use aer_ccm::faults::pcc_reports_error;

/// A named change to a good status.
type Case = (&'static str, fn(&mut PccStatus));

fn online() -> PccStatus {
    PccStatus {
        pcc_state: PrechargeState::Online,
        pcc_error_air_plus_open: false,
        pcc_error_converters_disagree: false,
        pcc_error_bypassed: false,
        pcc_error_resistor_hot: false,
        pcc_accumulator_no_pulses: false,
        pcc_tractive_no_pulses: false,
        pcc_error_too_fast: false,
        pcc_error_too_slow: false,
        pcc_error_bms_timeout: false,
        pcc_error_shutdown: false,
        pcc_error_accumulator_silent: false,
        pcc_error_tractive_silent: false,
        pcc_error_no_discharge: false,
        pcc_error_undefined_state: false,
        pcc_accumulator_voltage: 400.0,
        pcc_tractive_voltage: 398.0,
        pcc_precharge_progress: 99.5,
    }
}

/// The DTI at high voltage, still, no fault, everything fresh at `now`; the PCC's status
/// fed through the bench's own frame path.
fn guard_with(status: &PccStatus, dc_link_v: f32) -> Result<Path, DtiRefusal> {
    let now = 10_000u32;
    let mut bench = aer_ccm::console::dti::DtiBench::default();
    let mut data = [0u8; 8];
    // States the codec will not encode (7) are patched into the low three bits of byte 0.
    let raw_state = match status.pcc_state {
        PrechargeState::Unknown(raw) => Some(raw),
        _ => None,
    };
    let mut encodable = *status;
    if raw_state.is_some() {
        encodable.pcc_state = PrechargeState::Standby;
    }
    let len = encodable.encode(&mut data).expect("encodes");
    if let Some(raw) = raw_state {
        data[0] = (data[0] & 0xF8) | (raw & 0x07);
    }
    bench.vehicle_frame(now, PccStatus::ID, false, &data[..len]);
    bench.evidence.dc_link = Some((dc_link_v, now));
    bench.evidence.erpm = Some((0, now));
    bench.evidence.fault = Some((DtiFaultCode::None, now));
    bench.guard.confirm_wheels_off_ground(now);
    let _ = bench.guard.confirm_hv_disconnected(now, &bench.evidence);
    bench.guard.allows(now, &bench.evidence)
}

/// Contradictory ONLINE statuses: the race CCM's `pcc_reports_error` calls most of these a PCC
/// error; `dti enable` at high voltage must not take them as "the PCC ONLINE" either.
#[test]
fn dti_guard_refuses_online_statuses_the_race_ccm_calls_errors() {
    let cases: [Case; 7] = [
        ("tractive no pulses", |s| s.pcc_tractive_no_pulses = true),
        ("accumulator no pulses", |s| {
            s.pcc_accumulator_no_pulses = true
        }),
        ("bypassed latched", |s| {
            s.pcc_error_bypassed = true;
            s.pcc_error_too_fast = true
        }),
        ("tractive silent latched", |s| {
            s.pcc_error_tractive_silent = true
        }),
        ("no-discharge latched", |s| s.pcc_error_no_discharge = true),
        ("undefined-state latched", |s| {
            s.pcc_error_undefined_state = true
        }),
        ("resistor hot latched", |s| s.pcc_error_resistor_hot = true),
    ];
    let mut accepted = Vec::new();
    for (name, set) in cases {
        let mut status = online();
        set(&mut status);
        assert!(
            pcc_reports_error(&status),
            "{name}: the race CCM calls it an error"
        );
        if let Ok(path) = guard_with(&status, 400.0) {
            accepted.push((name, path));
        }
    }
    assert!(
        accepted.is_empty(),
        "`dti enable` at 400 V accepted ONLINE with: {accepted:?}"
    );
}

/// ONLINE whose own numbers say AIR+ cannot be closed onto a precharged DC link (tractive 0 V,
/// progress 0 %), or with the DTI's DC link far from the PCC's reading.
#[test]
fn dti_guard_refuses_online_with_voltages_that_contradict_it() {
    let mut dead = online();
    dead.pcc_tractive_voltage = 0.0;
    dead.pcc_precharge_progress = 0.0;
    assert!(
        guard_with(&dead, 400.0).is_err(),
        "ONLINE at 0 V / 0 % accepted"
    );
}

/// Latched causes the PCC's ERROR needs a power cycle for (needs_reset: too-fast, too-slow,
/// bms-timeout) in a status that says ONLINE: no working PCC sends it. The docs: the CCM takes
/// "any latched cause in any state" as a PCC error.
#[test]
fn race_ccm_calls_every_latched_cause_in_online_an_error() {
    let cases: [Case; 4] = [
        ("too-fast", |s| s.pcc_error_too_fast = true),
        ("too-slow", |s| s.pcc_error_too_slow = true),
        ("bms-timeout", |s| s.pcc_error_bms_timeout = true),
        ("shutdown", |s| s.pcc_error_shutdown = true),
    ];
    let mut missed = Vec::new();
    for (name, set) in cases {
        let mut status = online();
        set(&mut status);
        if !pcc_reports_error(&status) {
            missed.push(name);
        }
    }
    assert!(
        missed.is_empty(),
        "ONLINE with these latched causes drives on: {missed:?}"
    );
}

/// The race CCM: ONLINE with voltages that contradict it.
#[test]
fn race_ccm_calls_online_at_zero_volts_an_error() {
    let mut dead = online();
    dead.pcc_tractive_voltage = 0.0;
    dead.pcc_accumulator_voltage = 0.0;
    dead.pcc_precharge_progress = 0.0;
    assert!(
        pcc_reports_error(&dead),
        "ONLINE with both converters at 0 V drives on"
    );
}

/// Unknown state values and STANDBY/ERROR at 400 V: refused (these hold).
#[test]
fn unknown_states_and_live_standby_are_refused() {
    for raw in 6u8..8 {
        let mut status = online();
        status.pcc_state = PrechargeState::from_raw(raw);
        assert!(pcc_reports_error(&status), "raw {raw}");
        assert!(guard_with(&status, 400.0).is_err(), "raw {raw} at HV");
        assert!(guard_with(&status, 0.0).is_err(), "raw {raw} at LV");
    }
    for state in [PrechargeState::Standby, PrechargeState::Error] {
        let mut status = online();
        status.pcc_state = state;
        status.pcc_tractive_voltage = 400.0;
        assert!(
            guard_with(&status, 0.0).is_err(),
            "{state:?} at 400 V, DTI 0 V"
        );
        assert!(
            guard_with(&status, 400.0).is_err(),
            "{state:?} at 400 V, DTI 400 V"
        );
        status.pcc_tractive_voltage = 655.35;
        assert!(guard_with(&status, 0.0).is_err());
        status.pcc_tractive_voltage = 59.99;
        status.pcc_error_tractive_silent = true;
        assert!(guard_with(&status, 0.0).is_err(), "silent latched");
    }
    // DTI DC link at the plausibility limits.
    for volts in [-10.5f32, 650.5, f32::NAN] {
        assert!(guard_with(&online(), volts).is_err(), "{volts}");
    }
}
