//! Precharge controller (PCC) logic: hardware-free, `no_std`, tested on the host and on an
//! emulated Cortex-M7.
//!
//! Data flow per 10 ms control period: the V/F converters' edges become voltages
//! ([`measurement`]), BMS frames become a link state ([`bms`]), the state machine
//! ([`machine`]) turns both plus the shutdown input into a state, the relays follow from the
//! state alone ([`relays`]), and the status frame is built by the generated codec
//! ([`status`](Precharge::status)). [`watchdog`] decides when the hardware watchdog may be
//! serviced and what a restart after it expired means. [`bench`](mod@bench) is the bring-up image's bench
//! and [`bringup`] its gate in front of pin 11.
#![no_std]

pub mod bench;
pub mod bms;
pub mod bringup;
pub mod console;
pub mod constants;
#[cfg(feature = "firmware")]
pub mod hw;
pub mod machine;
pub mod measurement;
pub mod relays;
mod state;
mod status;
pub mod watchdog;

pub use constants::{PrechargeConfig, TASK_PERIOD_MS, VfConfig};
pub use machine::{HandoverRefusal, Inputs, Precharge, PrechargeTiming, Waiting};
pub use relays::Relays;
pub use state::{Errors, State};
