//! The measured traffic of the bundled session (the comp car, recorded at the schema's cycle
//! times) against what the schema declares: every message at its cycle time on each bus, and
//! each bus's load at the build-time figure of `generated/docs/can.md`.

use aer::can::XcpRes;
use aer_host::decode::decode_log;
use aer_host::reports::status::{Problems, status};

const SESSION: &str = include_str!("../../raspi/data/session.log");
const CAN_DOC: &str = include_str!("../../generated/docs/can.md");

/// The build-time load of schema bus `bus` (kbit/s), from the doc's "Bus load" table.
fn declared_kbit_s(bus: &str) -> f64 {
    let row = CAN_DOC
        .lines()
        .find(|line| line.starts_with(&format!("| {bus} |")))
        .unwrap_or_else(|| panic!("no bus load row for {bus}"));
    let cells: Vec<&str> = row.split('|').map(str::trim).collect();
    cells[5].parse().expect("kbit/s")
}

#[test]
fn the_session_runs_at_the_declared_cycle_times_within_the_declared_load() {
    let decoded = decode_log(SESSION);
    let status = status("car1", &decoded.counters, Problems::default());

    // CCM_Status is sent on both buses: one rate on each.
    let rates = &status.message_rates;
    assert_eq!(rates.len(), 2, "{:?}", rates.keys());
    assert!(rates["can0"].contains_key("CCM_Status") && rates["can1"].contains_key("CCM_Status"));
    let mut checked = 0;
    for (bus, messages) in rates {
        for (name, rate) in messages {
            let declared = rate
                .declared_hz
                .expect("every recorded message is periodic");
            let measured = rate.measured_hz.expect("many frames each");
            assert!(
                (measured / declared - 1.0).abs() < 1e-3,
                "{name} on {bus}: {measured} Hz against {declared}"
            );
            checked += 1;
        }
    }
    // Every periodic message the schema declares on the comp car's buses came, whatever
    // their number: the status names none as never arrived.
    assert!(checked > 0, "no message rates");
    assert_eq!(
        status.problems.never_arrived, None,
        "the demo session leaves out a message the schema declares: record it again with \
         `cargo xtask session-log` (docs/schema.md, \"Changing the schema\", step 4)"
    );
    assert_eq!(
        status.fingerprint_match,
        Some(true),
        "the demo session's telemetry is of another schema: record it again with `cargo xtask \
         session-log` (docs/schema.md, \"Changing the schema\", step 4)"
    );

    // can0 is the vehicle bus (telemetry included), can1 the inverter's. The session records
    // every periodic message, so each bus carries nearly the build-time load, never more. The
    // inverter bus's figure includes the XCP slave's frame budget (XCP_Res, one frame per
    // cycle time at most), which a session without a calibration tool does not use: the
    // generator counts an 8-byte standard frame as 135 bits (worst-case stuffing, interframe
    // space included).
    let xcp_budget_kbit_s = 1_000.0 / f64::from(XcpRes::CYCLE_TIME_MS) * 135.0 / 1_000.0;
    for (interface, bus, unused) in [
        ("can0", "vehicle", 0.0),
        ("can1", "inverter", xcp_budget_kbit_s),
    ] {
        let measured = status.bus_traffic[interface].bits_per_s / 1_000.0;
        let declared = declared_kbit_s(bus) - unused;
        assert!(
            measured <= declared * 1.001 && measured >= declared * 0.95,
            "{interface}: {measured:.1} kbit/s measured, {declared} declared for {bus}"
        );
    }
}

/// A message the schema declares and the car never sends is named in the status, with the
/// telemetry fields that mirror it (which would otherwise read a plausible 0): the session
/// replayed without its DTI_Flags frames.
#[test]
fn a_declared_message_that_never_arrives_is_named_with_its_fields() {
    use aer::can::DtiFlags;
    let id = format!(" {:08X}#", DtiFlags::ID & 0x1FFF_FFFF);
    let without: String = SESSION
        .lines()
        .filter(|line| !line.contains(&id))
        .map(|line| format!("{line}\n"))
        .collect();
    assert!(
        without.len() < SESSION.len(),
        "the session carries DTI_Flags"
    );
    let decoded = decode_log(&without);
    let status = status("car1", &decoded.counters, Problems::default());
    let problem = status
        .problems
        .never_arrived
        .as_deref()
        .expect("DTI_Flags is named as never arrived");
    assert!(
        problem.contains("DTI_Flags (from DTI, every 10 ms)"),
        "{problem}"
    );
    let mirrored: Vec<&str> = aer::telemetry::Telemetry::FIELDS
        .iter()
        .zip(aer::telemetry::Telemetry::DISPLAY)
        .filter(|(_, display)| display.mirrors == Some(DtiFlags::META.name))
        .map(|(field, _)| field.name)
        .collect();
    assert!(!mirrored.is_empty(), "telemetry mirrors DTI_Flags");
    for field in mirrored {
        assert!(problem.contains(field), "{field} in {problem}");
    }
    assert!(
        status
            .problems
            .named()
            .iter()
            .any(|(part, _)| *part == "never arrived"),
        "the dashboard lists it with the other problems"
    );
}
