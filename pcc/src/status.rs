//! The PCC status frame (0x222), through the generated codec.

use crate::machine::Precharge;
use aer::can::PccStatus;
use embedded_can::{Frame, StandardId};

/// Largest value the status frame's 16-bit, 0.01-scaled fields hold.
const FIELD_MAX: f64 = 655.35;

impl Precharge {
    /// The status as the schema's message, values clamped to what the frame can carry.
    pub fn status(&self) -> PccStatus {
        let errors = self.errors();
        PccStatus {
            pcc_state: self.state().to_wire(),
            pcc_error_too_fast: errors.too_fast,
            pcc_error_too_slow: errors.too_slow,
            pcc_error_bms_timeout: errors.bms_timeout,
            pcc_error_shutdown: errors.shutdown,
            pcc_error_undefined_state: errors.undefined_state,
            pcc_accumulator_voltage: clamp(self.accumulator_v()),
            pcc_tractive_voltage: clamp(self.tractive_v()),
            pcc_precharge_progress: clamp(self.progress_percent()),
        }
    }

    /// The status as a CAN frame ready to send, or `None` if it cannot be encoded (values
    /// are clamped first, so that would be a codec defect; the caller counts it).
    pub fn status_frame<F: Frame>(&self) -> Option<F> {
        let mut data = [0u8; PccStatus::LEN];
        let len = self.status().encode(&mut data).ok()?;
        let id = StandardId::new(u16::try_from(PccStatus::ID).ok()?)?;
        F::new(id, data.get(..len)?)
    }
}

fn clamp(value: f32) -> f64 {
    f64::from(value).clamp(0.0, FIELD_MAX)
}
