//! A portable XCP slave protocol core (ASAM MCD-1 XCP 1.x), `no_std`, without allocation and
//! without dependencies: the same code serves the CCM's calibration and measurement over
//! XCP-on-CAN on the Teensy and, on the host, XCP-on-TCP to the `pyxcp` master.
//!
//! The core is sans-IO. [`Slave::command`] takes one command packet and writes at most one
//! answer; [`Slave::event`] samples the running DAQ lists when the ECU fires an event channel.
//! It never touches memory itself: every read and write goes through the ECU's [`Target`],
//! which exposes only its calibration page (working page 0, reference page 1), measurement
//! snapshot and EPK, and validates every calibration write as one transaction.
//!
//! Wire data is untrusted: a malformed command gets an XCP error packet, never a panic.
//!
//! What the slave offers:
//! - Session: CONNECT, DISCONNECT, GET_STATUS, SYNCH, GET_COMM_MODE_INFO, GET_ID (ASCII text,
//!   A2L name, EPK; read with UPLOAD), SET_REQUEST (STORE_CAL_REQ). A session ends with its
//!   master: DISCONNECT, the transport's end ([`Slave::transport_lost`]) or the idle time-out
//!   ([`Slave::poll`]; with DAQ running, only the calibration unlock lapses).
//! - Protection: calibration and page switching locked at every CONNECT; GET_SEED and UNLOCK
//!   (six-byte seed, key of up to 32 bytes over several UNLOCKs, algorithm in the target); a
//!   wrong key ends the session and delays the next seed, doubling with each wrong key in a
//!   row. Reads and DAQ stay unprotected.
//! - Memory: SET_MTA, UPLOAD, SHORT_UPLOAD, BUILD_CHECKSUM (XCP_CRC_16_CITT), DOWNLOAD with
//!   master block mode and DOWNLOAD_NEXT (a block reaches the target as one write).
//!   SHORT_DOWNLOAD is not offered: at MAX_CTO 8 it has no room for data.
//! - Pages: SET_CAL_PAGE, GET_CAL_PAGE, GET_PAG_PROCESSOR_INFO, GET_SEGMENT_INFO,
//!   GET_PAGE_INFO, COPY_CAL_PAGE.
//! - Dynamic DAQ: GET_DAQ_PROCESSOR_INFO, GET_DAQ_RESOLUTION_INFO, GET_DAQ_EVENT_INFO,
//!   FREE_DAQ, ALLOC_DAQ, ALLOC_ODT, ALLOC_ODT_ENTRY, SET_DAQ_PTR, WRITE_DAQ,
//!   SET_DAQ_LIST_MODE, GET_DAQ_LIST_MODE, CLEAR_DAQ_LIST, START_STOP_DAQ_LIST,
//!   START_STOP_SYNCH, GET_DAQ_CLOCK; 1-byte PIDs (absolute ODT numbers), optional 4-byte
//!   1 us timestamps, prescalers, and a frame budget that refuses lists the bus cannot carry;
//!   a lost DTO is announced with EV_DAQ_OVERLOAD.
//! - Refusals: the last one, with why in numbers ([`LastRefusal`], [`reason`]), for the ECU to
//!   publish as measurements.
//! - Byte order Intel, address granularity byte, MAX_CTO = MAX_DTO = 8 on both transports.
//!
//! The ECU fills a [`Config`] from its generated constants and checks it at compile time:
//!
//! ```
//! use aer_xcp::{Config, EventChannel, Segment, Slave};
//!
//! static EVENTS: [EventChannel; 2] = [
//!     EventChannel { name: "control", period_us: 10_000, priority: 1 },
//!     EventChannel { name: "sensors", period_us: 1_000, priority: 2 },
//! ];
//! static CONFIG: Config = Config {
//!     events: &EVENTS,
//!     id_text: "AER CCM",
//!     a2l_name: "aer",
//!     segment: Segment { address: 0x0001_0000, length: 512, ext: 0 },
//!     frame_budget_per_s: 250,    // XCP_Res's cycle time in the DBC
//!     response_reserve_per_s: 50, // DAQ may use 200 frames/s
//!     max_bs: 42,
//!     min_st_100us: 0,
//!     max_odt_entry_size: 7,
//!     max_checksum_block: 4096,
//!     driver_version: 1,
//!     idle_timeout_ms: 60_000,   // no command for a minute ends the session
//!     unlock_delay_ms: 1_000,    // a wrong key: 1 s, 2 s, 4 s, ... before the next seed
//!     unlock_delay_max_ms: 300_000,
//! };
//! const _: () = assert!(CONFIG.is_valid());
//!
//! // 8 DAQ lists, 32 ODTs, 128 ODT entries.
//! let slave: Slave<8, 32, 128> = Slave::new(&CONFIG);
//! assert!(!slave.is_connected());
//! ```
//!
//! Then, for every command frame, [`Slave::command`] and (on CAN) [`transport::can_frame`] on
//! the answer; after every control step and sensor sample, [`Slave::event`].
#![no_std]
#![forbid(unsafe_code)]
#![deny(missing_docs)]

mod checksum;
mod config;
mod daq;
mod daq_cmd;
mod memory;
mod pages;
pub mod protocol;
mod refusal;
pub mod seed_key;
pub mod seeds;
mod slave;
pub mod status;
mod target;
mod transfer;
pub mod transport;
mod wire;

pub use checksum::{Crc16Ccitt, crc16_ccitt};
pub use config::{Config, EventChannel, Segment};
pub use protocol::{MAX_CTO, MAX_DTO};
pub use refusal::{Detail, LAST_REFUSAL_LEN, LastRefusal, reason};
pub use slave::{Counters, DaqReport, SessionEnd, Slave};
pub use target::{KEY_MAX, Refusal, SEED_LEN, Target};
