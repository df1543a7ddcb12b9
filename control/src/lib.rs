//! Small, hardware-free building blocks the CCM and PCC logic share. `no_std`, no
//! allocation, plain `f32` arithmetic (the Cortex-M7's FPU is single precision).
#![no_std]

mod filter;
mod persist;
mod pid;

pub use filter::LowPass;
pub use persist::Persist;
pub use pid::{Pid, PidGains};
