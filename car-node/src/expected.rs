//! What the scenario script is told about the schema, from the generated crate: the EPK, the
//! A2L, the address map, every parameter (address, elements, defaults, limits, when it may
//! change) and the internals. The script checks the slave against this, and this against the
//! A2L, so all three must agree.

use aer::calibration::xcp::{CALIBRATION_ADDRESS, EPK, INTERNALS_ADDRESS, TELEMETRY_ADDRESS};
use aer::calibration::{ChangeWhen, INTERNALS, PAGE_LEN, PARAMETERS};
use aer_ccm::calibration::Calibration;
use serde_json::{Value, json};
use std::path::Path;

/// Offset of the header's sequence number in the telemetry packet (after the fingerprint).
pub const SEQUENCE_OFFSET: usize = 4;

/// The description, with `a2l` as the A2L the script reads.
pub fn description(a2l: &Path) -> Value {
    let defaults = Calibration::DEFAULT.to_page();
    let parameters: Vec<Value> = PARAMETERS
        .iter()
        .map(|p| {
            json!({
                "name": p.name,
                "address": CALIBRATION_ADDRESS + p.offset as u32,
                "count": p.count,
                "defaults": (0..p.count).map(|i| p.value(&defaults, i)).collect::<Vec<_>>(),
                "min": p.min,
                "max": p.max,
                "change": match p.change {
                    ChangeWhen::Driving => "driving",
                    ChangeWhen::Standstill => "standstill",
                    ChangeWhen::TractiveOff => "tractive_off",
                },
            })
        })
        .collect();
    let internals: Vec<Value> = INTERNALS
        .iter()
        .map(|i| json!({"name": i.name, "offset": i.offset}))
        .collect();
    json!({
        "epk": EPK,
        "a2l": a2l,
        "page_len": PAGE_LEN,
        "calibration_address": CALIBRATION_ADDRESS,
        "telemetry_address": TELEMETRY_ADDRESS,
        "internals_address": INTERNALS_ADDRESS,
        "telemetry_sequence_offset": SEQUENCE_OFFSET,
        "parameters": parameters,
        "internals": internals,
    })
}
