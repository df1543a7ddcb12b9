//! What goes in and out of the CCM's steps: sensor samples, driver inputs, the firmware's
//! counters and bus health, and the control step's outputs and frames.

use crate::apps::PedalVolts;
use crate::faults::FaultMap;
use crate::thermal::Cooling;
use crate::torque_path::TorqueCommand;
use crate::vehicle::{State, VehicleOutputs};

/// One 1 kHz sensor sample.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SensorSample {
    /// New readings of APPS1 and APPS2 since the last sample, volts at the sensors (`None` on
    /// a channel with nothing new: the converter is slower than the sample rate, or lost).
    pub apps_v: PedalVolts,
    /// Front and rear brake sensor voltages (after the divider).
    pub brake_v: (f32, f32),
    /// Raw 12-bit readings of the four shock potentiometers (FL, FR, RL, RR).
    pub shock_raw: [u16; 4],
}

/// Driver inputs read by the control step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DriverInputs {
    /// Ready-to-move button (raw).
    pub ready_to_move: bool,
    /// Launch-control button.
    pub launch: bool,
}

/// What the control step decided; the firmware applies it to the outputs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ControlOutputs {
    /// Vehicle state machine outputs.
    pub vehicle: VehicleOutputs,
    /// Torque command.
    pub torque: TorqueCommand,
    /// Active faults.
    pub faults: FaultMap,
    /// Brake light: on exactly while the brakes count as engaged.
    pub brake_light: bool,
    /// Pump and fan duty.
    pub cooling: Cooling,
}

impl ControlOutputs {
    /// The outputs before the first control step: OFF, no torque, everything off.
    pub const RESET: Self = Self {
        vehicle: VehicleOutputs {
            state: State::Off,
            torque_enabled: false,
            rtd_sound: false,
            precharge_complete: false,
        },
        torque: TorqueCommand::ZERO,
        faults: FaultMap::NONE,
        brake_light: false,
        cooling: Cooling {
            pump: 0.0,
            fan: 0.0,
        },
    };
}

/// One CAN controller's health, as the firmware reads it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct BusHealth {
    /// An error counter is above 127: the node only sends passive error flags.
    pub error_passive: bool,
    /// The transmit error counter passed 255: the controller is off the bus until it
    /// recovers by itself.
    pub bus_off: bool,
    /// Times the controller went bus-off (since start-up).
    pub bus_off_events: u32,
}

/// What the firmware counts outside the library (queues, mailboxes, the pedal converter's
/// bus), reported in telemetry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DriverCounters {
    /// Received frames lost: receive queue or hardware FIFO full.
    pub rx_dropped: u32,
    /// Frames that never went out: every mailbox busy, a frame that failed to encode, a
    /// pending frame replaced by a newer one or dropped when the bus went off.
    pub tx_dropped: u32,
    /// Failed I2C transactions with the pedal converter.
    pub pedal_bus_errors: u32,
    /// The vehicle bus (FlexCAN3: BMS, charger, PCC, the Pi) and the inverter bus (FlexCAN2).
    pub buses: [BusHealth; 2],
}
