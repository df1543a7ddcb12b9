//! Firmware code written before `shocktravel4` joined the schema: it fills every other field the
//! CCM owns. Once the schema has the field, this no longer compiles (a forgotten field cannot
//! default). `tests/lockstep.rs` also shows the CCM itself failing on a new field.

fn main() {
    let mirror = aer::telemetry::TelemetryMirror::EMPTY;
    let _snapshot = aer::telemetry::Telemetry::from_parts(
        &mirror,
        aer::telemetry::TelemetryOwnFields {
            apps_travel: 0.0,
            bse_front: 0.0,
            bse_rear: 0.0,
            shocktravel1: 0.0,
            shocktravel2: 0.0,
            shocktravel3: 0.0,
            can_rx_dropped: 0,
            can_tx_dropped: 0,
            can_decode_errors: 0,
            telemetry_superseded: 0,
            pedal_bus_errors: 0,
            can_bus_off_events: 0,
            vehicle_bus_error_passive: false,
            vehicle_bus_bus_off: false,
            inverter_bus_error_passive: false,
            inverter_bus_bus_off: false,
        },
    );
}
