//! ISO 15765-2 transport (ISO-TP) over classic CAN with normal addressing, `no_std` and without
//! allocation: one implementation for the CCM, which sends the telemetry packet, and for the
//! Pi, which receives it when it has no kernel ISO-TP socket (replays, tests).
//!
//! Both ends are sans-IO state machines: they take received payload bytes and a microsecond
//! clock, and hand back frames to send. Nothing here touches a CAN controller, so the same code
//! runs on the Teensy, on the host, and on the emulated Cortex-M7.
//!
//! Covered: single frames, first frame + consecutive frames up to 4095 bytes, flow control
//! (continue, wait, overflow; block size; STmin in ms and 100-900 us), sequence numbers,
//! optional padding, N_Bs/N_Cr timeouts.
#![no_std]

mod frame;
mod receiver;
mod sender;

pub use frame::{FlowStatus, Frame, FrameError, Pci, StMin, parse};
pub use receiver::{Received, Receiver, RxError};
pub use sender::{SendError, Sender};

/// Largest payload a classic-CAN first frame can announce (12-bit length).
pub const MAX_PAYLOAD: usize = 4095;

/// Settings shared by both ends.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Config {
    /// Byte that pads frames to 8 bytes, or `None` to send only the bytes used.
    pub padding: Option<u8>,
    /// Consecutive frames the receiver accepts before it sends the next flow control
    /// (0 = all of them after one flow control).
    pub block_size: u8,
    /// Minimum gap the receiver asks between consecutive frames.
    pub st_min: StMin,
    /// N_Bs (sender waiting for flow control) and N_Cr (receiver waiting for the next
    /// consecutive frame), in microseconds.
    pub timeout_us: u32,
    /// Flow-control WAIT frames the sender tolerates in a row before giving up.
    pub max_waits: u8,
}

impl Config {
    /// The car's link: padded with 0xCC, no blocks, no gap, 1 s timeouts (ISO default).
    pub const CAR: Self = Self {
        padding: Some(0xCC),
        block_size: 0,
        st_min: StMin::ZERO,
        timeout_us: 1_000_000,
        max_waits: 8,
    };
}

impl Default for Config {
    fn default() -> Self {
        Self::CAR
    }
}
