//! What the CCM's images print on the USB console, without hardware types, so every line a
//! bench procedure relies on is built here, tested on the host (worst cases included) and
//! quoted in docs/bench-day.md from the test that prints it: the race image's start-up lines
//! and its answer to `bootloader`, the bring-up image's report ([`bringup`]) and its DTI checks
//! ([`dti`]).

pub mod bringup;
pub mod dti;

use crate::calibration::measured;
use crate::control::HandoverRefusal;
use crate::inverter::InverterKind;
use aer_console::LogBuffer;
use aer_console::bringup::{ResetCause, Startup};

/// Bytes of log the race image keeps for the host.
pub const LOG_BYTES: usize = 4_096;

/// The race image's start-up lines: the inverter it was built for, the board, the
/// fingerprints, why it started, the sensor calibration it runs with. Returns the lines that
/// did not fit.
pub fn race_startup<const N: usize>(
    log: &mut LogBuffer<N>,
    board: &str,
    inverter: InverterKind,
    reset: ResetCause,
) -> u32 {
    let image = match inverter {
        InverterKind::Dti => "AER CCM for the DTI HV-550 (comp car)",
        InverterKind::Ifl100 => "AER CCM for the IFL100 (HIMaC bench)",
    };
    let mut missed = Startup {
        image,
        board,
        fingerprints: &[
            ("schema", aer::can::SCHEMA_FINGERPRINT),
            ("telemetry", aer::telemetry::TELEMETRY_FINGERPRINT),
        ],
        reset,
        clocks: None,
        pins: &[],
    }
    .write(log);
    if !log.line(format_args!(
        "sensor calibration: ccm/calibration.toml ({})",
        measured::SOURCE
    )) {
        missed += 1;
    }
    missed
}

/// The race image's answer to a bootloader request (typed `bootloader`, or 134 baud).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BootloaderAnswer {
    /// Obeyed: the inverter was sent its safe commands.
    Obeyed,
    /// Refused, and why.
    Refused(HandoverRefusal),
}

impl core::fmt::Display for BootloaderAnswer {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Obeyed => f.write_str(
                "bootloader: inverter commanded to zero torque, drive disabled; rebooting into the bootloader",
            ),
            Self::Refused(why) => write!(f, "bootloader REFUSED: {why}"),
        }
    }
}
