//! The inverter behind one interface. The CCM drives either the comp car's DTI HV-550
//! ([`dti`]) or the HIMaC bench's IFL100 ([`ifl100`]); which one is the car's configuration
//! ([`crate::constants::INVERTER`], a build-time setting). Whichever it is, the control step reads
//! one [`InverterStatus`] and asks for one [`DriveCommand`], so the freshness limits, the
//! torque monitor, the power limiter and every fault reaction are the same code for both.

pub mod dti;
pub mod ifl100;
pub mod speed_watch;

use crate::bus::BusState;
pub use crate::bus::InverterStatus;
pub use crate::constants::InverterKind;
use crate::constants::{
    DTI_COMMAND_PERIOD_MS, DTI_SPEED_TIMEOUT_MS, IFL100_COMMAND_PERIOD_MS, MCU1_TIMEOUT_MS,
};
use aer::runtime::EncodeError;

impl InverterKind {
    /// The inverter as the start-up line names it.
    pub const fn name(self) -> &'static str {
        match self {
            Self::Dti => "DTI HV-550 (comp car)",
            Self::Ifl100 => "IFL100 (HIMaC bench)",
        }
    }

    /// How often the CCM sends the inverter its commands (ms): the cycle time the schema
    /// declares for the torque command.
    pub const fn command_period_ms(self) -> u32 {
        match self {
            Self::Dti => DTI_COMMAND_PERIOD_MS,
            Self::Ifl100 => IFL100_COMMAND_PERIOD_MS,
        }
    }

    /// How old the inverter's fastest status (motor speed) may be before the inverter counts
    /// as lost (ms).
    pub const fn status_timeout_ms(self) -> u32 {
        match self {
            Self::Dti => DTI_SPEED_TIMEOUT_MS,
            Self::Ifl100 => MCU1_TIMEOUT_MS,
        }
    }

    /// The inverter's status as the buses delivered it, each value `None` unless fresh at
    /// `now_ms`, for a CCM that started at `started_ms`.
    pub fn status(self, bus: &BusState, now_ms: u32, started_ms: u32) -> InverterStatus {
        match self {
            Self::Dti => dti::status(bus, now_ms, started_ms),
            Self::Ifl100 => ifl100::status(bus, now_ms, started_ms),
        }
    }
}

/// What the CCM asks of the inverter this period.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DriveCommand {
    /// Torque request (Nm); clamped to what the inverter's command can carry.
    pub torque_nm: f32,
    /// DRIVING with torque enabled: the inverter may drive.
    pub drive: bool,
    /// The precharge is complete: the inverter may close its main relay (IFL100).
    pub main_relay: bool,
    /// The PCC is precharging (IFL100's emulated BMS reports its precharge relay).
    pub precharging: bool,
    /// The brakes are engaged.
    pub brakes_engaged: bool,
    /// The DC current the inverter may draw (A): the BMS's fresh discharge limit, else 0.
    pub discharge_limit_a: f32,
}

/// A frame the CCM sends: identifier, its format and up to 8 payload bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OutFrame {
    /// The identifier (11 or 29 bits).
    pub id: u32,
    /// A 29-bit identifier.
    pub extended: bool,
    len: u8,
    data: [u8; 8],
}

impl OutFrame {
    /// A frame whose payload `encode` writes, returning its length.
    pub fn encoded(
        id: u32,
        extended: bool,
        encode: impl FnOnce(&mut [u8; 8]) -> Result<usize, EncodeError>,
    ) -> Result<Self, EncodeError> {
        let mut data = [0u8; 8];
        let len = encode(&mut data)?.min(8) as u8;
        Ok(Self {
            id,
            extended,
            len,
            data,
        })
    }

    /// The payload.
    pub fn data(&self) -> &[u8] {
        self.data.get(..usize::from(self.len)).unwrap_or(&[])
    }
}

/// The frames of one command period (at most four).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OutFrames {
    frames: [Option<OutFrame>; 4],
}

impl OutFrames {
    /// Frames in sending order.
    pub fn new(frames: [Option<OutFrame>; 4]) -> Self {
        Self { frames }
    }

    /// Every frame, in sending order.
    pub fn iter(&self) -> impl Iterator<Item = &OutFrame> {
        self.frames.iter().flatten()
    }

    /// How many frames there are.
    pub fn len(&self) -> usize {
        self.iter().count()
    }

    /// No frame at all.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// `value` if it is a number, else 0: a NaN must never reach a command.
fn finite_or_zero(value: f32) -> f32 {
    if value.is_finite() { value } else { 0.0 }
}
