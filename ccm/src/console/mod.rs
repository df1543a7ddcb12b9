//! What the CCM's images print on the USB console, without hardware types, so every line a
//! bench procedure relies on is built here, tested on the host (worst cases included) and
//! quoted in docs/bench-day.md from the test that prints it: the race image's start-up lines
//! (with the calibration it runs) and its answer to `bootloader` and `restart`, the bring-up
//! image's report and calibration ([`bringup`]) and its DTI checks ([`dti`]).

pub mod bringup;
pub mod dti;

use crate::calibration::store::Startup as Loaded;
use crate::control::HandoverRefusal;
use crate::inverter::InverterKind;
use aer_boards::assumed::Board as AssumedBoard;
use aer_console::board_check::BoardCheck;
use aer_console::bringup::{ResetCause, Startup, write_assumed};
use aer_console::{LogBuffer, Reboot};
use core::fmt;

/// Bytes of log the race image keeps for the host: its start-up lines (with the list of what
/// is still assumed, about 3 KiB) and a full set of answers besides, for a console opened
/// after the start.
pub const LOG_BYTES: usize = 8_192;

/// The race image's start-up lines: the inverter it was built for, the board, the
/// fingerprints, why it started, the calibration it runs and where that came from. Returns
/// the lines that did not fit.
pub fn race_startup<const N: usize>(
    log: &mut LogBuffer<N>,
    board: &str,
    inverter: InverterKind,
    reset: ResetCause,
    check: BoardCheck,
    calibration: CalibrationLine<'_>,
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
        check,
    }
    .write(log);
    if !log.line(format_args!("{calibration}")) {
        missed += 1;
    }
    missed + write_assumed(log, AssumedBoard::Ccm)
}

/// The one line that says which calibration runs and where it came from, by the one rule
/// (`Loaded::or_measured`): the newest good saved copy, else the schema's defaults with
/// `ccm/calibration.toml`'s sensors. The race image prints it at start-up, the bring-up
/// image's `cal load` prints what start-up would.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CalibrationLine<'a> {
    /// What start-up found in the flash.
    pub startup: Loaded,
    /// CRC-32 of the page that runs (`CCM_CalChecksum`).
    pub checksum: u32,
    /// `ccm/calibration.toml`'s `source`.
    pub file_source: &'a str,
}

impl fmt::Display for CalibrationLine<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let why = match self.startup {
            Loaded::Saved { slot, generation } => {
                return write!(
                    f,
                    "calibration: saved copy {} (generation {generation}), checksum 0x{:08X}; a saved copy wins over ccm/calibration.toml",
                    slot.name(),
                    self.checksum
                );
            }
            Loaded::NoneSaved => "no copy saved",
            Loaded::Corrupt => "the saved copy is corrupt",
            Loaded::OtherSchema => "the saved copy is of another schema",
            Loaded::OutOfLimits => "the saved copy is outside the limits",
        };
        write!(
            f,
            "calibration: ccm/calibration.toml's sensors ({}) on the schema's defaults, checksum 0x{:08X}; {why}",
            self.file_source, self.checksum
        )
    }
}

/// The race image's answer to `bootloader` (or 134 baud) and `restart`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RebootAnswer {
    /// What was asked.
    pub reboot: Reboot,
    /// Obeyed (the inverter sent its safe commands), or refused and why.
    pub outcome: Result<(), HandoverRefusal>,
}

impl fmt::Display for RebootAnswer {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (asked, doing) = match self.reboot {
            Reboot::Bootloader => ("bootloader", "rebooting into the bootloader"),
            Reboot::Restart => ("restart", "restarting"),
        };
        match self.outcome {
            Ok(()) => write!(
                f,
                "{asked}: inverter commanded to zero torque, drive disabled; {doing}"
            ),
            Err(why) => write!(f, "{asked} REFUSED: {why}"),
        }
    }
}

/// The PCC as the CCM last heard it (PCC_Status): its state and every latched cause by the
/// names the PCC's own console uses, for the race image's log and `status`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PccLine(pub Option<aer::can::PccStatus>);

impl PccLine {
    /// The state and the error bits alone (what the log watches: the voltages move).
    pub fn key(&self) -> Option<(aer::can::PrechargeState, u16)> {
        self.0.map(|status| {
            let bits = pcc_causes(&status)
                .iter()
                .enumerate()
                .fold(0u16, |bits, (index, (set, _))| {
                    bits | (u16::from(*set) << index)
                });
            (status.pcc_state, bits)
        })
    }
}

/// PCC_Status's latched causes with their names.
fn pcc_causes(status: &aer::can::PccStatus) -> [(bool, &'static str); 12] {
    [
        (status.pcc_error_too_fast, "too-fast"),
        (
            status.pcc_error_bypassed,
            "bypassed (AIR+ welded or the precharge resistor bypassed)",
        ),
        (status.pcc_error_too_slow, "too-slow"),
        (status.pcc_error_bms_timeout, "bms-timeout"),
        (status.pcc_error_shutdown, "shutdown"),
        (
            status.pcc_error_air_plus_open,
            "air-plus-open (AIR+ did not close)",
        ),
        (
            status.pcc_error_converters_disagree,
            "converters-disagree (the tractive system read above the pack)",
        ),
        (
            status.pcc_error_accumulator_silent,
            "accumulator-converter-silent",
        ),
        (
            status.pcc_error_tractive_silent,
            "tractive-converter-silent",
        ),
        (status.pcc_error_no_discharge, "no-discharge"),
        (status.pcc_error_resistor_hot, "resistor-hot"),
        (status.pcc_error_undefined_state, "undefined-state"),
    ]
}

impl fmt::Display for PccLine {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let Some(status) = self.0 else {
            return f.write_str("PCC not heard");
        };
        write!(
            f,
            "PCC {}, errors:",
            status.pcc_state.label().unwrap_or("UNKNOWN")
        )?;
        let mut any = false;
        for (_, name) in pcc_causes(&status).iter().filter(|(set, _)| *set) {
            write!(f, " {name}")?;
            any = true;
        }
        if !any {
            f.write_str(" none")?;
        }
        Ok(())
    }
}

/// The race image's answer to `status`: the vehicle state, the active faults by name and the
/// PCC as last heard; the list of what the image runs with unchecked follows it
/// ([`aer_console::bringup::write_assumed`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StatusLine {
    /// Milliseconds since start-up.
    pub now_ms: u32,
    /// The vehicle state.
    pub state: crate::vehicle::State,
    /// The active faults.
    pub faults: crate::faults::FaultMap,
    /// The PCC.
    pub pcc: PccLine,
}

impl fmt::Display for StatusLine {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "t={} ms status: vehicle {:?}, faults {:#06x}:{}; {}",
            self.now_ms,
            self.state,
            self.faults.bits(),
            FaultNames(self.faults),
            self.pcc
        )
    }
}

/// The active faults' names, each after a space.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FaultNames(pub crate::faults::FaultMap);

impl fmt::Display for FaultNames {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for fault in crate::faults::Fault::ALL {
            if self.0.has(fault) {
                write!(f, " {fault:?}")?;
            }
        }
        Ok(())
    }
}
