//! The demo's desk master: what a pit master's session through the gateway records, so the
//! demo's sessions have a calibration record to read, export and compare (docs/test-day.md's
//! "After" runs on the demo as written). There is no CCM behind the demo, so the answers are
//! the ones the CCM gives a write inside the limits: the entries come from the gateway's own
//! [`Recorder`], fed the commands a master sends and those answers.
//!
//! When the demo starts, the desk "connects" and the record takes the page the bundled session
//! was recorded with (the schema's defaults, as `cargo xtask session-log` runs the CCM's logic);
//! then every [`CHANGE_EVERY`] it sets `traction_kp` to the next of [`TRACTION_KP_STEPS`], so
//! two sessions of one demo end with different values. The replayed data does not follow: it
//! is the recorded session, whatever the record says (the master's name says so).

use super::record::Recorder;
use crate::store::NoteSender;
use crate::store::calibration::Entry;
use aer::calibration::xcp::CALIBRATION_ADDRESS;
use aer::calibration::{Calibration, PARAMETERS};
use aer_xcp::protocol::{cmd, pid};
use std::time::Duration;
use tokio_util::sync::CancellationToken;

/// The desk master's name in the record.
pub const MASTER: &str = "demo desk (a rehearsal: the replayed data does not change)";
/// How often the desk changes the parameter.
pub const CHANGE_EVERY: Duration = Duration::from_secs(20);
/// The parameter the desk tunes.
pub const PARAMETER: &str = "traction_kp";
/// The values it sets in turn (Nm per unit of slip; the schema's limits are 0-2000).
pub const TRACTION_KP_STEPS: [f32; 3] = [450.0, 500.0, 400.0];

/// Records the desk's connection and its changes into the open session until `cancel`.
/// Each accepted change counts in `counters` as the gateway's would (`calibration_changes`).
pub async fn run(
    record: NoteSender,
    counters: std::sync::Arc<aer_host::reports::counters::Counters>,
    now_us: fn() -> i64,
    cancel: CancellationToken,
) {
    let mut desk = Desk::default();
    for entry in desk.connect(now_us()) {
        record.send(entry);
    }
    loop {
        tokio::select! {
            () = tokio::time::sleep(CHANGE_EVERY) => {}
            () = cancel.cancelled() => return,
        }
        for entry in desk.change(now_us()) {
            if entry.accepted {
                aer_host::reports::counters::Counters::bump(&counters.calibration_changes);
            }
            record.send(entry);
        }
    }
}

/// The desk's session as the gateway's recorder sees it.
#[derive(Default)]
pub struct Desk {
    recorder: Recorder,
    changes: usize,
}

impl Desk {
    /// The desk connects: the page the demo's session runs with (the working page, 0), as
    /// `Found` entries.
    pub fn connect(&mut self, at_us: i64) -> Vec<Entry> {
        self.recorder
            .found(Calibration::DEFAULT.to_page(), Some(0), at_us, MASTER)
    }

    /// The desk's next change of [`PARAMETER`], answered as the CCM answers a write inside
    /// the limits.
    pub fn change(&mut self, at_us: i64) -> Vec<Entry> {
        let value = TRACTION_KP_STEPS
            .get(self.changes % TRACTION_KP_STEPS.len())
            .copied()
            .unwrap_or_default();
        self.changes += 1;
        let Some(offset) = PARAMETERS
            .iter()
            .find(|p| p.name == PARAMETER)
            .and_then(|p| u32::try_from(p.offset).ok())
        else {
            return Vec::new();
        };
        self.recorder.command(&short_download(
            CALIBRATION_ADDRESS + offset,
            &value.to_le_bytes(),
        ));
        self.recorder.answer(&[pid::RES], at_us, MASTER)
    }
}

/// SHORT_DOWNLOAD of `data` (at most 8 bytes, as the CAN transport allows) to `address`.
fn short_download(address: u32, data: &[u8; 4]) -> [u8; 12] {
    let [a0, a1, a2, a3] = address.to_le_bytes();
    let [d0, d1, d2, d3] = *data;
    // cmd, count, reserved, address extension, address (LE), data.
    [cmd::SHORT_DOWNLOAD, 4, 0, 0, a0, a1, a2, a3, d0, d1, d2, d3]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::calibration::{Kind, values_at_end};

    #[test]
    fn the_desk_records_the_page_then_each_change_as_the_gateway_would() {
        let mut desk = Desk::default();
        let mut entries = desk.connect(1_000);
        let page_elements: usize = PARAMETERS.iter().map(|p| p.count).sum();
        assert_eq!(
            entries.len(),
            page_elements + 1,
            "every element, and the page"
        );
        assert!(entries.iter().all(|e| e.checksum.is_some()), "{entries:?}");
        assert!(entries.iter().all(|e| e.kind == Kind::Found));
        let first = desk.change(2_000);
        let second = desk.change(3_000);
        for (change, old, new) in [
            (
                &first,
                Calibration::DEFAULT.traction_kp,
                TRACTION_KP_STEPS[0],
            ),
            (&second, TRACTION_KP_STEPS[0], TRACTION_KP_STEPS[1]),
        ] {
            assert_eq!(change.len(), 1, "{change:?}");
            let write = &change[0];
            assert!(write.kind == Kind::Write && write.accepted, "{write:?}");
            assert!(write.checksum.is_some(), "{write:?}");
            assert_eq!(write.parameter, PARAMETER);
            assert_eq!(write.old, Some(f64::from(old)));
            assert_eq!(write.new, Some(f64::from(new)));
        }
        entries.extend(first);
        entries.extend(second);
        let at_end = values_at_end(&entries);
        let kp = at_end.iter().find(|(p, _, _)| p == PARAMETER).map(|v| v.2);
        assert_eq!(kp, Some(f64::from(TRACTION_KP_STEPS[1])));
    }
}
