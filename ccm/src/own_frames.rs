//! The CCM's own periodic messages, encoded once for whatever puts them on the wire: the
//! firmware's control task and the car model send the same frames on the same buses, so a
//! message the CCM starts sending is added here and reaches both. Each message goes on the
//! buses the schema's `AerBus` names for it (`vehicle`: CAN3; `inverter` or `bench-inverter`:
//! CAN2, whichever inverter the car has).

use crate::control::Due;
use crate::inverter::OutFrame;
use aer::can::{CcmCalibration, CcmStatus};
use aer::runtime::{EncodeError, MessageMeta};

/// The CCM's CAN controllers a frame goes out on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Buses {
    /// FlexCAN3: BMS, charger, PCC, IMD, the Pi.
    pub vehicle: bool,
    /// FlexCAN2: the inverter (the DTI, or the bench's IFL100).
    pub inverter: bool,
}

impl Buses {
    /// The controllers `meta`'s `AerBus` names.
    pub fn of(meta: &MessageMeta) -> Self {
        let on = |names: &[&str]| meta.buses.iter().any(|bus| names.contains(bus));
        Self {
            vehicle: on(&["vehicle"]),
            inverter: on(&["inverter", "bench-inverter"]),
        }
    }

    /// How many controllers that is.
    pub fn count(self) -> u32 {
        u32::from(self.vehicle) + u32::from(self.inverter)
    }
}

/// One of the CCM's own frames and where it goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OwnFrame {
    pub frame: OutFrame,
    pub buses: Buses,
}

/// The CCM's own frames due after a control step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OwnFrames {
    frames: [Option<OwnFrame>; 2],
    /// Sends lost because a message did not encode (a codec defect: one per bus it was for).
    pub not_encoded: u32,
}

impl OwnFrames {
    /// What `due` asks for: CCM_Status if due, CCM_Calibration (`calibration`, from the
    /// calibration's owner) if due.
    pub fn of(due: &Due, calibration: Option<CcmCalibration>) -> Self {
        let mut not_encoded = 0;
        let mut own = |meta: &'static MessageMeta, encoded: Result<OutFrame, EncodeError>| {
            let buses = Buses::of(meta);
            if encoded.is_err() {
                not_encoded += buses.count();
            }
            encoded.ok().map(|frame| OwnFrame { frame, buses })
        };
        let status = due.status.and_then(|status| {
            let encoded = OutFrame::encoded(CcmStatus::ID, false, |data| status.encode(data));
            own(CcmStatus::META, encoded)
        });
        let calibration = calibration
            .filter(|_| due.calibration)
            .and_then(|calibration| {
                let encoded =
                    OutFrame::encoded(CcmCalibration::ID, false, |data| calibration.encode(data));
                own(CcmCalibration::META, encoded)
            });
        Self {
            frames: [status, calibration],
            not_encoded,
        }
    }

    /// Every frame, in sending order.
    pub fn iter(&self) -> impl Iterator<Item = &OwnFrame> {
        self.frames.iter().flatten()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_message_goes_on_the_buses_the_schema_names() {
        // CCM_Status is on all three of the schema's buses, CCM_Calibration on the vehicle's.
        assert_eq!(
            Buses::of(CcmStatus::META),
            Buses {
                vehicle: true,
                inverter: true
            }
        );
        assert_eq!(
            Buses::of(CcmCalibration::META),
            Buses {
                vehicle: true,
                inverter: false
            }
        );
    }
}
