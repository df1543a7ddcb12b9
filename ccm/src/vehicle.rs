//! The vehicle state machine: OFF, STANDBY, PRECHARGING, IDLE, DRIVING, FAULT.
//!
//! Driven by the PCC's status frame (the generated `PccStatus`), the debounced ready-to-move
//! button, the brakes, and the fault bitmap. DRIVING needs the PCC to report ONLINE in a fresh
//! frame at every step, the button pressed with the brakes engaged, and the ready-to-drive
//! sound played for its full length first (EV.9.2).

use crate::constants::{RTD_SOUND_MS, RTM_DEBOUNCE_MS};
use crate::faults::FaultMap;
use aer::can::PrechargeState;
use aer_control::Persist;

/// Vehicle state, as sent in CCM_Status and telemetry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum State {
    /// No PCC status seen yet.
    Off,
    /// Low voltage up, tractive system off.
    Standby,
    /// The PCC is precharging.
    Precharging,
    /// Tractive system live, no torque.
    Idle,
    /// Ready to drive: torque follows the pedal.
    Driving,
    /// A fault stops the vehicle.
    Fault,
}

impl State {
    /// The schema's value for this state.
    pub const fn to_wire(self) -> aer::can::VehicleState {
        use aer::can::VehicleState as Wire;
        match self {
            Self::Off => Wire::Off,
            Self::Standby => Wire::Standby,
            Self::Precharging => Wire::Precharging,
            Self::Idle => Wire::Idle,
            Self::Driving => Wire::Driving,
            Self::Fault => Wire::Fault,
        }
    }
}

/// What the state machine reads each step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VehicleInputs {
    /// Free-running milliseconds.
    pub now_ms: u32,
    /// The PCC's state, if its status is fresh (see [`crate::constants::PCC_STATUS_TIMEOUT_MS`]).
    pub pcc: Option<PrechargeState>,
    /// Ready-to-move button, raw (debounced here).
    pub rtm_button: bool,
    /// The brakes are engaged.
    pub brakes_engaged: bool,
    /// Active faults.
    pub faults: FaultMap,
}

/// What the rest of the CCM does with the state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct VehicleOutputs {
    /// Current state.
    pub state: State,
    /// Torque may follow the pedal (DRIVING, sound finished).
    pub torque_enabled: bool,
    /// The ready-to-drive sound is playing.
    pub rtd_sound: bool,
    /// The PCC reports a completed precharge in a fresh frame.
    pub precharge_complete: bool,
}

/// The state machine.
#[derive(Debug, Clone)]
pub struct Vehicle {
    state: State,
    button: Persist,
    button_latched: bool,
    sound_since_ms: Option<u32>,
}

impl Default for Vehicle {
    fn default() -> Self {
        Self::new()
    }
}

impl Vehicle {
    /// OFF, as at reset.
    pub const fn new() -> Self {
        Self {
            state: State::Off,
            button: Persist::new(),
            button_latched: false,
            sound_since_ms: None,
        }
    }

    /// Current state.
    pub fn state(&self) -> State {
        self.state
    }

    /// One control step.
    pub fn step(&mut self, inputs: &VehicleInputs) -> VehicleOutputs {
        let now = inputs.now_ms;
        let pcc = inputs.pcc;
        let precharge_complete = pcc == Some(PrechargeState::Online);
        let pressed = self.button_pressed(inputs.rtm_button, now);

        // A PCC in ERROR is a fault in the map (`Fault::PccError`), like every other cause.
        if inputs.faults.stops_the_vehicle() {
            self.enter(State::Fault);
        }
        match self.state {
            State::Off => {
                if pcc.is_some() {
                    self.enter(State::Standby);
                }
            }
            State::Standby | State::Precharging => {
                self.state = match pcc {
                    Some(PrechargeState::Online) => State::Idle,
                    Some(PrechargeState::Precharge) => State::Precharging,
                    _ => State::Standby,
                };
            }
            State::Idle => {
                if !precharge_complete {
                    self.enter(State::Standby);
                } else if let Some(since) = self.sound_since_ms {
                    if pressed {
                        // A second press cancels the start-up.
                        self.sound_since_ms = None;
                    } else if now.wrapping_sub(since) >= RTD_SOUND_MS {
                        self.enter(State::Driving);
                    }
                } else if pressed && inputs.brakes_engaged {
                    self.sound_since_ms = Some(now);
                }
            }
            State::Driving => {
                if !precharge_complete {
                    self.enter(State::Standby);
                } else if pressed {
                    self.enter(State::Idle);
                }
            }
            State::Fault => {
                if !inputs.faults.stops_the_vehicle() {
                    self.enter(State::Standby);
                }
            }
        }
        VehicleOutputs {
            state: self.state,
            torque_enabled: self.state == State::Driving && precharge_complete,
            rtd_sound: self.sound_since_ms.is_some(),
            precharge_complete,
        }
    }

    /// A debounced press: true once per press, when the button has been down for the
    /// debounce time.
    fn button_pressed(&mut self, raw: bool, now: u32) -> bool {
        let held = self
            .button
            .update(raw, now)
            .is_some_and(|held| held >= RTM_DEBOUNCE_MS);
        if !raw {
            self.button_latched = false;
            return false;
        }
        if held && !self.button_latched {
            self.button_latched = true;
            return true;
        }
        false
    }

    fn enter(&mut self, state: State) {
        self.state = state;
        self.sound_since_ms = None;
    }
}
