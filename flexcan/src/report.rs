//! How the driver's states and errors read on a console: words a person at the bench
//! understands, one line each, instead of `Debug`'s nested names.

use crate::{BusStatus, CanFrame, FaultState, InitError, SelfTestError};
use core::fmt;
use embedded_can::{Frame, Id};

impl fmt::Display for FaultState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::ErrorActive => "error-active",
            Self::ErrorPassive => "error-passive",
            Self::BusOff => "bus-off",
        })
    }
}

impl fmt::Display for BusStatus {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}, tx errors {}, rx errors {}, rx overflows {}, bus-off {}x, tx dropped {}",
            self.state,
            self.tx_errors,
            self.rx_errors,
            self.rx_fifo_overflows,
            self.bus_off_events,
            self.tx_dropped
        )
    }
}

impl fmt::Display for InitError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Bitrate(unreachable) => write!(
                f,
                "{} bit/s cannot be made from the {} Hz CAN clock",
                unreachable.bitrate, unreachable.clock_hz
            ),
            Self::WrongPins => f.write_str("the pins belong to another FlexCAN instance"),
            Self::Timeout(step) => write!(f, "the controller timed out trying to {step}"),
        }
    }
}

impl fmt::Display for SelfTestError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Init(error) => write!(f, "loopback mode: {error}"),
            Self::TxBusy => f.write_str("every mailbox busy"),
            Self::NothingReceived => f.write_str("the frame never came back"),
            Self::Mismatch(frame) => write!(f, "another frame came back ({})", FrameId(frame)),
        }
    }
}

/// A frame's identifier as candump writes it: 3 hex digits standard, 8 extended.
struct FrameId<'a>(&'a CanFrame);

impl fmt::Display for FrameId<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.0.id() {
            Id::Standard(id) => write!(f, "id {:03X}", id.as_raw()),
            Id::Extended(id) => write!(f, "id {:08X}", id.as_raw()),
        }
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use embedded_can::StandardId;
    use std::format;

    #[test]
    fn states_and_errors_read_as_words() {
        let status = BusStatus {
            state: FaultState::ErrorPassive,
            tx_errors: 128,
            rx_errors: 0,
            rx_fifo_overflows: 2,
            bus_off_events: 1,
            tx_dropped: 3,
        };
        assert_eq!(
            format!("{status}"),
            "error-passive, tx errors 128, rx errors 0, rx overflows 2, bus-off 1x, tx dropped 3"
        );
        let frame = StandardId::new(0x7F3)
            .and_then(|id| CanFrame::new(id, &[1]))
            .unwrap();
        assert_eq!(
            format!("{}", SelfTestError::Mismatch(frame)),
            "another frame came back (id 7F3)"
        );
        assert_eq!(
            format!(
                "{}",
                SelfTestError::Init(InitError::Timeout("enter freeze mode"))
            ),
            "loopback mode: the controller timed out trying to enter freeze mode"
        );
    }
}
