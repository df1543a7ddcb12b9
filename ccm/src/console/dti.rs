//! The DTI HV-550 on the bench, from what the bring-up image hears on the inverter bus and
//! sends to it: the node id, CAN map, drive enable and fault code beside the schema's
//! ([`BenchCheck`], one report period); the DC link voltage it reports, which the `dti enable`
//! test's high-voltage gate reads; and its command timeout, measured at low voltage
//! ([`EnableTimeout`]): drive enable commanded (by the bring-up's own [`EnableTest`] or by a CAN
//! adapter), then silence, and the time until packet 0x24 reports the drive disabled.

use crate::constants::{DTI_ASSUMED_COMMAND_TIMEOUT_MS, DTI_CAN_MAP_VERSION};
use crate::inverter::dti;
use crate::inverter::{DriveCommand, OutFrames};
use aer::can::{DtiDriveEnable, DtiFaultCode, DtiFlags, DtiSetDriveEnable, DtiSpeed};
use aer::runtime::EncodeError;
use core::fmt;

/// What a report period heard of the DTI: the node id its status packets carry, the CAN map
/// version, drive enable and the fault code, each beside what the schema expects.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct BenchCheck {
    node_id: Option<u8>,
    other_node: bool,
    map_version: Option<u8>,
    drive: Option<DtiDriveEnable>,
    fault: Option<DtiFaultCode>,
}

/// The DTI's status packet ids (0x1F-0x26), whatever the node id.
const STATUS_PACKETS: core::ops::RangeInclusive<u32> = 0x1F..=0x26;

impl BenchCheck {
    /// The node id the schema's DTI ids carry.
    pub const SCHEMA_NODE_ID: u8 = (DtiFlags::ID & 0xFF) as u8;

    /// Looks at one received frame.
    pub fn frame(&mut self, id: u32, extended: bool, data: &[u8]) {
        if !extended || !STATUS_PACKETS.contains(&(id >> 8)) {
            return;
        }
        let node = (id & 0xFF) as u8;
        match self.node_id {
            None => self.node_id = Some(node),
            Some(seen) if seen != node => self.other_node = true,
            Some(_) => {}
        }
        if node != Self::SCHEMA_NODE_ID {
            return;
        }
        if id == DtiFlags::ID {
            if let Ok(flags) = DtiFlags::decode(data) {
                self.map_version = Some(flags.dti_can_map_version);
                self.drive = Some(flags.dti_drive_enabled);
            }
        } else if id == aer::can::DtiTemperatures::ID {
            if let Ok(temperatures) = aer::can::DtiTemperatures::decode(data) {
                self.fault = Some(temperatures.dti_fault_code);
            }
        }
    }
}

impl fmt::Display for BenchCheck {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let Some(node) = self.node_id else {
            return write!(f, "DTI: no status packet heard");
        };
        write!(
            f,
            "DTI node 0x{node:02x} (schema 0x{:02x}{})",
            Self::SCHEMA_NODE_ID,
            if self.other_node {
                ", and other nodes"
            } else {
                ""
            }
        )?;
        match self.map_version {
            Some(version) => write!(f, ", CAN map {version} (schema {DTI_CAN_MAP_VERSION})")?,
            None => write!(f, ", CAN map not heard")?,
        }
        if let Some(drive) = self.drive {
            write!(f, ", drive {}", drive.label().unwrap_or("UNKNOWN"))?;
        }
        if let Some(fault) = self.fault {
            write!(f, ", fault {}", fault.label().unwrap_or("UNKNOWN"))?;
        }
        Ok(())
    }
}

/// How long the bench waits for the DTI to drop its drive enable after the last command
/// before it reports that it did not (ms).
pub const TIMEOUT_WAIT_MS: u32 = 1_000;

/// The DTI's command timeout, measured: the time from the last "drive enabled" command to the
/// first packet 0x24 that reports the drive disabled.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct EnableTimeout {
    /// The last drive-enable command (ms), while it asked for "enabled".
    last_enable_ms: Option<u32>,
    /// The DTI reported "enabled" since that command.
    enabled_seen: bool,
    result: Option<TimeoutResult>,
}

/// What a measurement found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TimeoutResult {
    /// The drive was reported disabled this long after the last enable command (ms).
    Dropped(u32),
    /// Still reported enabled [`TIMEOUT_WAIT_MS`] after the last command.
    NotDropped,
    /// Commands stopped without the DTI ever reporting "enabled" (no DC link, a fault, or
    /// another node id): nothing to time.
    NeverEnabled,
}

impl EnableTimeout {
    /// A drive-enable command (packet 0x0C), sent by the bring-up image or heard from another
    /// sender at `now_ms`.
    pub fn command(&mut self, now_ms: u32, enable: bool) {
        if enable {
            if self.last_enable_ms.is_none() {
                self.enabled_seen = false;
            }
            self.last_enable_ms = Some(now_ms);
            self.result = None;
        } else {
            // An explicit disable is not a timeout: nothing to measure.
            self.last_enable_ms = None;
        }
    }

    /// Packet 0x24 at `now_ms`, reporting the drive `enabled` or not.
    pub fn status(&mut self, now_ms: u32, enabled: bool) {
        let Some(last) = self.last_enable_ms else {
            return;
        };
        if enabled {
            self.enabled_seen = true;
        } else if self.enabled_seen {
            self.result = Some(TimeoutResult::Dropped(now_ms.wrapping_sub(last)));
            self.last_enable_ms = None;
        }
    }

    /// Ends a measurement that has waited [`TIMEOUT_WAIT_MS`] since the last command.
    pub fn poll(&mut self, now_ms: u32) {
        let Some(last) = self.last_enable_ms else {
            return;
        };
        if now_ms.wrapping_sub(last) > TIMEOUT_WAIT_MS {
            self.result = Some(if self.enabled_seen {
                TimeoutResult::NotDropped
            } else {
                TimeoutResult::NeverEnabled
            });
            self.last_enable_ms = None;
        }
    }

    /// The last measurement's result.
    pub fn result(&self) -> Option<TimeoutResult> {
        self.result
    }
}

impl fmt::Display for EnableTimeout {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("DTI command timeout: ")?;
        match (self.result, self.last_enable_ms) {
            (_, Some(_)) => f.write_str("measuring (drive enable commanded)"),
            (None, None) => f.write_str(
                "not measured (`confirm hv-disconnected`, then `dti enable`, or drive enable from a CAN adapter, then silence)",
            ),
            (Some(TimeoutResult::Dropped(ms)), None) => write!(
                f,
                "drive enable dropped {ms} ms after the last command (the car model assumes {DTI_ASSUMED_COMMAND_TIMEOUT_MS} ms)"
            ),
            (Some(TimeoutResult::NotDropped), None) => write!(
                f,
                "STILL ENABLED {TIMEOUT_WAIT_MS} ms after the last command: set the CAN timeout in the DTI tool before any spin"
            ),
            (Some(TimeoutResult::NeverEnabled), None) => f.write_str(
                "the DTI never reported its drive enabled: check its node id, fault code and enable input, then repeat",
            ),
        }
    }
}

/// The bring-up image's `dti enable`: zero current with drive enable every command period
/// for one second, then silence, so [`EnableTimeout`] can time the DTI's own timeout at low
/// voltage. Never any current: the commands carry 0 A and a DC current limit of 0 A.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct EnableTest {
    started_ms: Option<u32>,
    sent_ms: Option<u32>,
}

impl EnableTest {
    /// How long the test commands drive enable (ms).
    pub const DURATION_MS: u32 = 1_000;

    /// Starts the test at `now_ms`.
    pub fn start(&mut self, now_ms: u32) {
        self.started_ms = Some(now_ms);
        self.sent_ms = None;
    }

    /// Stops it (`off`, an expired or revoked HV gate).
    pub fn stop(&mut self) {
        self.started_ms = None;
    }

    /// True while it commands drive enable.
    pub fn active(&self) -> bool {
        self.started_ms.is_some()
    }

    /// The frames due at `now_ms`, if any (every command period while active); ends the test
    /// after [`Self::DURATION_MS`].
    pub fn due(&mut self, now_ms: u32) -> Option<Result<OutFrames, EncodeError>> {
        let started = self.started_ms?;
        if now_ms.wrapping_sub(started) >= Self::DURATION_MS {
            self.started_ms = None;
            return None;
        }
        let period = DtiSetDriveEnable::CYCLE_TIME_MS;
        if self
            .sent_ms
            .is_some_and(|sent| now_ms.wrapping_sub(sent) < period)
        {
            return None;
        }
        self.sent_ms = Some(now_ms);
        let command = DriveCommand {
            torque_nm: 0.0,
            drive: true,
            main_relay: false,
            precharging: false,
            brakes_engaged: false,
            discharge_limit_a: 0.0,
        };
        Some(dti::frames(&command).map(|(_, frames)| frames))
    }
}

/// Everything the CCM bring-up image keeps about the DTI.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DtiBench {
    /// This report period's check.
    pub check: BenchCheck,
    /// The command timeout measurement.
    pub timeout: EnableTimeout,
    /// The `dti enable` test.
    pub test: EnableTest,
    /// The DC link voltage the DTI last reported (V) and when (ms).
    dc_link: Option<(f32, u32)>,
}

impl DtiBench {
    /// Looks at one frame heard on the inverter bus at `now_ms`: a status packet, or another
    /// sender's drive-enable command.
    pub fn frame(&mut self, now_ms: u32, id: u32, extended: bool, data: &[u8]) {
        if !extended {
            return;
        }
        self.check.frame(id, extended, data);
        if id == DtiFlags::ID {
            if let Ok(flags) = DtiFlags::decode(data) {
                let enabled = flags.dti_drive_enabled == DtiDriveEnable::Enabled;
                self.timeout.status(now_ms, enabled);
            }
        } else if id == DtiSpeed::ID {
            if let Ok(speed) = DtiSpeed::decode(data) {
                self.dc_link = Some((f32::from(speed.dti_input_voltage), now_ms));
            }
        } else if id == DtiSetDriveEnable::ID {
            if let Ok(command) = DtiSetDriveEnable::decode(data) {
                let enable = command.dti_drive_enable_cmd == DtiDriveEnable::Enabled;
                self.timeout.command(now_ms, enable);
            }
        }
    }

    /// The DC link voltage reported within the packet's freshness limit (V), else `None`.
    pub fn dc_link_v(&self, now_ms: u32) -> Option<f32> {
        self.dc_link
            .filter(|(_, at)| now_ms.wrapping_sub(*at) <= DtiSpeed::TIMEOUT_MS)
            .map(|(volts, _)| volts)
    }

    /// The `dti enable` frames due at `now_ms` (counted as enable commands for the timeout).
    pub fn due(&mut self, now_ms: u32) -> Option<Result<OutFrames, EncodeError>> {
        let frames = self.test.due(now_ms)?;
        self.timeout.command(now_ms, true);
        Some(frames)
    }

    /// Ends a timeout measurement that waited long enough.
    pub fn poll(&mut self, now_ms: u32) {
        self.timeout.poll(now_ms);
    }

    /// A report was printed: the next period's check starts empty.
    pub fn report_done(&mut self) {
        self.check = BenchCheck::default();
    }
}
