//! What the PCC needs from the Orion BMS: that it is alive, and its charger-safety output.

use aer::can::{OrionCellVoltages, OrionLimits, OrionPackStatus};
use embedded_can::{Frame, Id};

/// Orion relay-state bit for the charger-safety output (Orion BMS 2 CAN message
/// documentation: bit 2 of the relay state).
const CHARGER_SAFETY: u16 = 1 << 2;

/// Tracks the BMS link from the frames the PCC receives.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct BmsLink {
    last_seen_ms: Option<u32>,
    charger_safety: bool,
    /// BMS frames that failed to decode (wrong length): counted, not trusted as a heartbeat.
    pub decode_errors: u32,
}

impl BmsLink {
    /// Feeds one received frame; frames of other nodes are ignored.
    pub fn on_frame(&mut self, now_ms: u32, frame: &impl Frame) {
        let Id::Standard(id) = frame.id() else {
            return;
        };
        let id = u32::from(id.as_raw());
        let data = frame.data();
        let decoded = if id == OrionPackStatus::ID {
            OrionPackStatus::decode(data)
                .map(|status| self.charger_safety = status.orion_relay_state & CHARGER_SAFETY != 0)
        } else if id == OrionLimits::ID {
            OrionLimits::decode(data).map(|_| ())
        } else if id == OrionCellVoltages::ID {
            OrionCellVoltages::decode(data).map(|_| ())
        } else {
            return;
        };
        match decoded {
            Ok(()) if !frame.is_remote_frame() => self.last_seen_ms = Some(now_ms),
            _ => self.decode_errors = self.decode_errors.wrapping_add(1),
        }
    }

    /// When the last valid BMS frame arrived.
    pub fn last_seen_ms(&self) -> Option<u32> {
        self.last_seen_ms
    }

    /// The charger-safety output, from the last pack-status frame.
    pub fn charger_safety(&self) -> bool {
        self.charger_safety
    }
}
