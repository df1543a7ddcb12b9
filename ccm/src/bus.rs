//! What the CCM keeps from the CAN buses: every decoded frame updates the telemetry mirror
//! (generated `Telemetry::apply`), plus the few values the control logic needs that
//! telemetry does not carry.

use aer::can::{AnyMessage, PrechargeState};
use aer::runtime::DecodeError;
use aer::telemetry::Telemetry;
use embedded_can::{Frame, Id};

/// Latest values from the buses.
#[derive(Debug, Clone, Default)]
pub struct BusState {
    /// Every field mirrored from a DBC signal, as last received.
    pub mirror: Telemetry,
    /// The PCC's state and when its status arrived (ms).
    pub pcc: Option<(PrechargeState, u32)>,
    /// When the BMS last reported (ms).
    pub bms_seen_ms: Option<u32>,
    /// Hottest pack temperature (degC).
    pub pack_high_temp_degc: f32,
    /// Frames of known ids that failed to decode (wrong length): counted and ignored.
    pub decode_errors: u32,
    /// Frames whose id the schema does not know: counted and ignored.
    pub unknown_ids: u32,
}

impl BusState {
    /// Feeds one received frame.
    pub fn on_frame(&mut self, frame: &impl Frame, now_ms: u32) {
        let (id, extended) = match frame.id() {
            Id::Standard(id) => (u32::from(id.as_raw()), false),
            Id::Extended(id) => (id.as_raw(), true),
        };
        if frame.is_remote_frame() {
            return;
        }
        let message = match AnyMessage::decode(id, extended, frame.data()) {
            Ok(message) => message,
            Err(DecodeError::UnknownId { .. }) => {
                self.unknown_ids = self.unknown_ids.wrapping_add(1);
                return;
            }
            Err(_) => {
                self.decode_errors = self.decode_errors.wrapping_add(1);
                return;
            }
        };
        match &message {
            AnyMessage::PccStatus(status) => self.pcc = Some((status.pcc_state, now_ms)),
            AnyMessage::OrionPackStatus(_) | AnyMessage::OrionCellVoltages(_) => {
                self.bms_seen_ms = Some(now_ms);
            }
            AnyMessage::OrionLimits(limits) => {
                self.bms_seen_ms = Some(now_ms);
                self.pack_high_temp_degc = f32::from(limits.orion_high_temperature);
            }
            _ => {}
        }
        self.mirror.apply(&message);
    }
}
