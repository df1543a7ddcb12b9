//! The DTI HV-550 on the bench, from what the bring-up image hears on the inverter bus and
//! sends to it: the node id, CAN map, drive enable and fault code beside the schema's
//! ([`BenchCheck`], one report period); and its command timeout ([`EnableTimeout`]): drive
//! enable commanded (by the bring-up's own [`EnableTest`] or by a CAN adapter), then silence,
//! and the time until packet 0x24 reports the drive disabled.
//!
//! `dti enable` is guarded at every voltage ([`DtiGuard`]), when it is typed and at every step
//! while it runs: below 60 V on the DTI's own, fresh DC link reading, by `confirm
//! hv-disconnected`; at 60 V or more, by `confirm wheels-off-ground` with the PCC heard ONLINE.
//! Always with the DTI heard without a fault and the motor still. Anything else stops the test
//! with an explicit drive disable.

use crate::constants::{DTI_ASSUMED_COMMAND_TIMEOUT_MS, DTI_CAN_MAP_VERSION, TRACTIVE_OFF_V};
use crate::inverter::dti;
use crate::inverter::{DriveCommand, OutFrames};
use aer::can::{
    DtiDriveEnable, DtiFaultCode, DtiFlags, DtiSetDriveEnable, DtiSpeed, DtiTemperatures,
    PccStatus, PrechargeState,
};
use aer::runtime::EncodeError;
use aer_console::hv_gate::{self, HV_CONFIRMATION_MS, HvGate, HvReading, HvRefusal, HvSensor};
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
    dc_link_v: Option<i16>,
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
        } else if id == DtiSpeed::ID {
            if let Ok(speed) = DtiSpeed::decode(data) {
                self.dc_link_v = Some(speed.dti_input_voltage);
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
        if let Some(volts) = self.dc_link_v {
            write!(f, ", DC link {volts} V")?;
        }
        Ok(())
    }
}

/// How long the bench waits for the DTI to drop its drive enable after the last command
/// before it reports that it did not (ms).
pub const TIMEOUT_WAIT_MS: u32 = 1_000;

/// The longest measured command timeout the torque-off proofs accept (ms): what they assume
/// ([`DTI_ASSUMED_COMMAND_TIMEOUT_MS`]) plus the measurement's own slack (the DTI's status
/// comes every 10 ms, and a DTI's timeout counts from its last command, not to the ms).
pub const DTI_TIMEOUT_LIMIT_MS: u32 = DTI_ASSUMED_COMMAND_TIMEOUT_MS + 50;

/// The DTI's command timeout, measured: the time from the last "drive enabled" command to the
/// first packet 0x24 that reports the drive disabled.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct EnableTimeout {
    /// The last drive-enable command (ms), while it asked for "enabled".
    last_enable_ms: Option<u32>,
    /// The DTI reported "enabled" since that command.
    enabled_seen: bool,
    result: Option<TimeoutResult>,
    /// A measurement ended and the bench has not taken it yet ([`Self::take_ended`]).
    ended: bool,
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
            self.ended = true;
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
            self.ended = true;
        }
    }

    /// The result of a measurement that ended since the last call (once each).
    pub fn take_ended(&mut self) -> Option<TimeoutResult> {
        if core::mem::take(&mut self.ended) {
            self.result
        } else {
            None
        }
    }

    /// True when the last measurement passed: the drive dropped within the limit.
    pub fn passed(&self) -> bool {
        matches!(self.result, Some(TimeoutResult::Dropped(ms)) if ms <= DTI_TIMEOUT_LIMIT_MS)
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
                "NOT MEASURED (`confirm hv-disconnected`, then `dti enable`, or drive enable from a CAN adapter, then silence): no spin until it reads PASS",
            ),
            (Some(TimeoutResult::Dropped(ms)), None) if ms <= DTI_TIMEOUT_LIMIT_MS => write!(
                f,
                "PASS: drive enable dropped {ms} ms after the last command (limit {DTI_TIMEOUT_LIMIT_MS} ms; the torque-off proofs assume {DTI_ASSUMED_COMMAND_TIMEOUT_MS} ms): write {ms} ms on the sheet"
            ),
            (Some(TimeoutResult::Dropped(ms)), None) => write!(
                f,
                "FAIL: drive enable dropped {ms} ms after the last command, LONGER than the {DTI_TIMEOUT_LIMIT_MS} ms limit: no spin; set the CAN timeout in the DTI tool to {DTI_ASSUMED_COMMAND_TIMEOUT_MS} ms and measure again"
            ),
            (Some(TimeoutResult::NotDropped), None) => write!(
                f,
                "FAIL: STILL ENABLED {TIMEOUT_WAIT_MS} ms after the last command (the bench has sent drive disabled): no spin; set the CAN timeout in the DTI tool, then measure again"
            ),
            (Some(TimeoutResult::NeverEnabled), None) => f.write_str(
                "NOT MEASURED: the DTI never reported its drive enabled: check its node id, fault code and enable input, then repeat; no spin until it reads PASS",
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

    /// Stops it (`off`, a guard that no longer allows it).
    pub fn stop(&mut self) {
        self.started_ms = None;
    }

    /// The frames that end a test at once instead of by the DTI's timeout: zero current,
    /// drive disabled.
    pub fn disable_frames() -> Result<OutFrames, EncodeError> {
        let command = DriveCommand {
            torque_nm: 0.0,
            drive: false,
            main_relay: false,
            precharging: false,
            brakes_engaged: false,
            discharge_limit_a: 0.0,
        };
        dti::frames(&command).map(|(_, frames)| frames)
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

/// Everything the CCM bring-up image keeps about the DTI and the PCC beside it.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DtiBench {
    /// This report period's check.
    pub check: BenchCheck,
    /// The command timeout measurement.
    pub timeout: EnableTimeout,
    /// The `dti enable` test.
    pub test: EnableTest,
    /// What `dti enable` needs.
    pub guard: DtiGuard,
    /// What the guard reads.
    pub evidence: DtiEvidence,
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
                self.evidence.dc_link = Some((f32::from(speed.dti_input_voltage), now_ms));
                self.evidence.erpm = Some((speed.dti_erpm, now_ms));
            }
        } else if id == DtiTemperatures::ID {
            if let Ok(temperatures) = DtiTemperatures::decode(data) {
                self.evidence.fault = Some((temperatures.dti_fault_code, now_ms));
            }
        } else if id == DtiSetDriveEnable::ID {
            if let Ok(command) = DtiSetDriveEnable::decode(data) {
                let enable = command.dti_drive_enable_cmd == DtiDriveEnable::Enabled;
                self.timeout.command(now_ms, enable);
            }
        }
    }

    /// Looks at one frame heard on the vehicle bus at `now_ms`: the PCC's status.
    pub fn vehicle_frame(&mut self, now_ms: u32, id: u32, extended: bool, data: &[u8]) {
        if !extended && id == PccStatus::ID {
            if let Ok(status) = PccStatus::decode(data) {
                self.evidence.pcc = Some((status.pcc_state, now_ms));
                self.evidence.pcc_fault = crate::faults::pcc_reports_error(&status);
                // A tractive converter that fell silent after reading 60 V or more: its
                // last reading is not the voltage now.
                self.evidence.pcc_tractive_v = (!status.pcc_error_tractive_silent)
                    .then_some(status.pcc_tractive_voltage as f32);
            }
        }
    }

    /// `dti enable` at `now_ms`: starts the test if the guard allows it.
    pub fn enable(&mut self, now_ms: u32) -> Result<Path, DtiRefusal> {
        let path = self.guard.allows(now_ms, &self.evidence)?;
        self.test.start(now_ms);
        Ok(path)
    }

    /// Every step while the test runs: the frames due, or, when the guard no longer allows
    /// it, the test stopped with an explicit drive disable and the reason. Counts sent enable
    /// commands for the timeout.
    pub fn due(&mut self, now_ms: u32) -> Option<Step> {
        if !self.test.active() {
            return None;
        }
        if let Err(why) = self.guard.allows(now_ms, &self.evidence) {
            self.test.stop();
            self.timeout.command(now_ms, false);
            return Some(Step::Stopped(why, EnableTest::disable_frames()));
        }
        let frames = self.test.due(now_ms)?;
        self.timeout.command(now_ms, true);
        Some(Step::Send(frames))
    }

    /// Ends a timeout measurement that waited long enough. Returns the result of one that
    /// ended at this step (by the DTI's answer or the wait), with the frames that disable the
    /// DTI whatever it answered: the bench sends them, so a DTI whose timeout does not work is
    /// never left enabled.
    pub fn poll(&mut self, now_ms: u32) -> Option<(EnableTimeout, Result<OutFrames, EncodeError>)> {
        self.timeout.poll(now_ms);
        self.timeout
            .take_ended()
            .map(|_| (self.timeout, EnableTest::disable_frames()))
    }

    /// A report was printed: the next period's check starts empty.
    pub fn report_done(&mut self) {
        self.check = BenchCheck::default();
    }
}

/// What a step of a running `dti enable` does.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Step {
    /// Send these frames (zero current, drive enabled).
    Send(Result<OutFrames, EncodeError>),
    /// The guard stopped the test: send these (drive disabled) and say why.
    Stopped(DtiRefusal, Result<OutFrames, EncodeError>),
}

/// The DTI's DC link reading is evidence for two of its status periods (its packet 0x20
/// comes every 10 ms): older, it is unknown.
pub const DC_LINK_MAX_AGE_MS: u32 = 2 * DtiSpeed::CYCLE_TIME_MS;
/// Above this the motor turns (electrical rpm; 30 rpm of a 10-pole-pair motor) although the
/// test commands 0 A: stop.
pub const STILL_ERPM: i32 = 300;

/// At high voltage the PCC's tractive-system reading and the DTI's DC link must agree within
/// this fraction of the DTI's: AIR+ closed joins the two, and 6c and 8.1 check the PCC's
/// converters to 1 %.
pub const AGREE_FRACTION: f32 = 0.1;

/// What the guard reads: the last of each, with when it arrived.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DtiEvidence {
    /// The DC link voltage the DTI reported (V, packet 0x20).
    pub dc_link: Option<(f32, u32)>,
    /// The motor's electrical rpm (packet 0x20).
    pub erpm: Option<(i32, u32)>,
    /// The DTI's fault code (packet 0x22).
    pub fault: Option<(DtiFaultCode, u32)>,
    /// The PCC's state (PCC_Status on the vehicle bus).
    pub pcc: Option<(PrechargeState, u32)>,
    /// The tractive-system voltage the PCC reads, from the same status (V).
    pub pcc_tractive_v: Option<f32>,
    /// The same status reports a fault or says what a working PCC cannot
    /// ([`crate::faults::pcc_reports_error`], as the race CCM judges it).
    pub pcc_fault: bool,
}

impl DtiEvidence {
    /// The DC link as the HV gate reads it.
    fn dc_link_sensor(&self) -> HvSensor<'static> {
        HvSensor {
            name: "DTI DC link",
            reading: match self.dc_link {
                Some((volts, at_ms)) => HvReading::Volts { volts, at_ms },
                None => HvReading::Silent,
            },
            silent: "no packet 0x20 heard from the DTI: check its logic supply, CAN2 and its node id",
        }
    }
}

/// Which way `dti enable` was allowed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Path {
    /// Below 60 V, with `confirm hv-disconnected`.
    LowVoltage,
    /// At high voltage, with `confirm wheels-off-ground` and the PCC ONLINE.
    HighVoltage,
}

/// Why `dti enable` may not run (or must stop).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DtiRefusal {
    /// The DC link reading, or the low-voltage path's confirmation.
    Hv(HvRefusal<'static>),
    /// At high voltage without `confirm wheels-off-ground` (or it expired).
    WheelsNotConfirmed,
    /// At high voltage without the PCC heard ONLINE.
    PccNotOnline(Option<PrechargeState>),
    /// The DTI reads its DC link below 60 V while the PCC reports a state in which the
    /// tractive system is, or may be, live: the two disagree, and low voltage is not proven.
    PccEnergised(PrechargeState),
    /// At high voltage the PCC reports ONLINE with a fault, or with readings no working PCC
    /// sends ([`crate::faults::pcc_reports_error`]).
    PccFault,
    /// At high voltage the PCC's tractive-system reading (`None`: unknown) and the DTI's DC
    /// link differ by more than [`AGREE_FRACTION`]: one of them measures wrong.
    Disagree {
        /// The PCC's reading (V).
        pcc_v: Option<f32>,
        /// The DTI's (V).
        dti_v: f32,
    },
    /// The DTI reads its DC link below 60 V while the PCC's tractive converter fell silent
    /// after reading 60 V or more (latched): the tractive system may be live.
    PccVoltageUnknown,
    /// The DTI reads its DC link below 60 V while the PCC reads the tractive system at 60 V or
    /// more (V).
    PccReadsLive(f32),
    /// No fresh fault code from the DTI.
    FaultUnknown,
    /// The DTI reports a fault.
    Fault(DtiFaultCode),
    /// No fresh motor speed, or the motor turns.
    Turning(Option<i32>),
}

impl fmt::Display for DtiRefusal {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Hv(why) => write!(f, "{why}"),
            Self::WheelsNotConfirmed => f.write_str(
                "the DTI reads its DC link at 60 V or more: type `confirm wheels-off-ground` (car on stands, driven wheels free) first",
            ),
            Self::PccNotOnline(None) => write!(
                f,
                "at high voltage the PCC must be heard ONLINE, and no PCC_Status came in the last {} ms",
                PccStatus::TIMEOUT_MS
            ),
            Self::PccNotOnline(Some(state)) => write!(
                f,
                "at high voltage the PCC must be ONLINE, and it reports {}",
                state.label().unwrap_or("an unknown state")
            ),
            Self::PccEnergised(state) => write!(
                f,
                "the DTI reads its DC link below 60 V but the PCC reports {}: the tractive system may be live: open the shutdown circuit, then check the DTI's HV input and its DC link reading against the TSMP meter",
                state.label().unwrap_or("an unknown state")
            ),
            Self::PccFault => f.write_str(
                "at high voltage the PCC must be ONLINE without a fault, and its status reports one (the report's PCC line names it): open the shutdown circuit and find it first",
            ),
            Self::Disagree { pcc_v, dti_v } => match pcc_v {
                Some(pcc_v) => write!(
                    f,
                    "the PCC reads the tractive system at {pcc_v:.0} V and the DTI its DC link at {dti_v:.0} V: more than 10 % apart, one of them measures wrong: open the shutdown circuit, then check both against the TSMP meter at the next precharge"
                ),
                None => write!(
                    f,
                    "the DTI reads its DC link at {dti_v:.0} V and the PCC's tractive-system reading is unknown (its converter fell silent): open the shutdown circuit"
                ),
            },
            Self::PccVoltageUnknown => f.write_str(
                "the DTI reads its DC link below 60 V but the PCC's tractive converter fell silent after reading 60 V or more: the tractive system may be live: open the shutdown circuit, measure at the TSMP, and power-cycle the PCC (LV off, USB out) once the ESO has measured below 60 V",
            ),
            Self::PccReadsLive(volts) => write!(
                f,
                "the DTI reads its DC link below 60 V but the PCC reads the tractive system at {volts:.0} V: it may be live: open the shutdown circuit, then check the DTI's HV input and its DC link reading against the TSMP meter"
            ),
            Self::FaultUnknown => write!(
                f,
                "no fault code from the DTI (packet 0x22) in the last {} ms",
                DtiTemperatures::TIMEOUT_MS
            ),
            Self::Fault(fault) => write!(
                f,
                "the DTI reports fault {}: clear it first (the DTI tool)",
                fault.label().unwrap_or("UNKNOWN")
            ),
            Self::Turning(None) => write!(
                f,
                "no motor speed from the DTI (packet 0x20) in the last {DC_LINK_MAX_AGE_MS} ms"
            ),
            Self::Turning(Some(erpm)) => write!(
                f,
                "the motor turns ({erpm} ERPM) with 0 A commanded: stop and find out why before anything else"
            ),
        }
    }
}

/// What `dti enable` needs (see the module's description).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DtiGuard {
    hv: HvGate,
    wheels_off_ms: Option<u32>,
}

impl Default for DtiGuard {
    fn default() -> Self {
        Self {
            hv: HvGate::new(TRACTIVE_OFF_V, DC_LINK_MAX_AGE_MS),
            wheels_off_ms: None,
        }
    }
}

impl DtiGuard {
    /// `confirm hv-disconnected` at `now_ms`: taken only if the DTI's fresh DC link reading
    /// is below 60 V.
    pub fn confirm_hv_disconnected(
        &mut self,
        now_ms: u32,
        evidence: &DtiEvidence,
    ) -> Result<(), HvRefusal<'static>> {
        self.hv.confirm(now_ms, &[evidence.dc_link_sensor()])
    }

    /// `confirm wheels-off-ground` at `now_ms`.
    pub fn confirm_wheels_off_ground(&mut self, now_ms: u32) {
        self.wheels_off_ms = Some(now_ms);
    }

    /// `off`: both confirmations revoked.
    pub fn revoke(&mut self) {
        self.hv.revoke();
        self.wheels_off_ms = None;
    }

    /// Whether `dti enable` may run at `now_ms`, and by which path.
    pub fn allows(&self, now_ms: u32, evidence: &DtiEvidence) -> Result<Path, DtiRefusal> {
        let fresh = |at: u32, limit_ms: u32| now_ms.wrapping_sub(at) <= limit_ms;
        let sensor = evidence.dc_link_sensor();
        let volts =
            hv_gate::evidence(&sensor, now_ms, DC_LINK_MAX_AGE_MS).map_err(DtiRefusal::Hv)?;
        match evidence.fault {
            Some((DtiFaultCode::None, at)) if fresh(at, DtiTemperatures::TIMEOUT_MS) => {}
            Some((fault, at)) if fresh(at, DtiTemperatures::TIMEOUT_MS) => {
                return Err(DtiRefusal::Fault(fault));
            }
            _ => return Err(DtiRefusal::FaultUnknown),
        }
        match evidence.erpm {
            Some((erpm, at)) if fresh(at, DC_LINK_MAX_AGE_MS) => {
                if erpm.unsigned_abs() > STILL_ERPM.unsigned_abs() {
                    return Err(DtiRefusal::Turning(Some(erpm)));
                }
            }
            _ => return Err(DtiRefusal::Turning(None)),
        }
        if volts < TRACTIVE_OFF_V {
            // Low voltage needs the PCC to agree, when it is heard: STANDBY or ERROR (AIR+
            // open, the tractive system discharged or discharging), not a precharge or ONLINE.
            if let Some((state, at)) = evidence.pcc
                && fresh(at, PccStatus::TIMEOUT_MS)
            {
                if !matches!(state, PrechargeState::Standby | PrechargeState::Error) {
                    return Err(DtiRefusal::PccEnergised(state));
                }
                // STANDBY after an untimed precharge, or ERROR with the circuit still closed:
                // the PCC's own reading says live.
                match evidence.pcc_tractive_v {
                    Some(volts)
                        if volts.partial_cmp(&TRACTIVE_OFF_V)
                            != Some(core::cmp::Ordering::Less) =>
                    {
                        return Err(DtiRefusal::PccReadsLive(volts));
                    }
                    Some(_) => {}
                    None => return Err(DtiRefusal::PccVoltageUnknown),
                }
            }
            self.hv.allows(now_ms, &[sensor]).map_err(DtiRefusal::Hv)?;
            return Ok(Path::LowVoltage);
        }
        let confirmed = self
            .wheels_off_ms
            .is_some_and(|at| now_ms.wrapping_sub(at) < HV_CONFIRMATION_MS);
        if !confirmed {
            return Err(DtiRefusal::WheelsNotConfirmed);
        }
        match evidence.pcc {
            Some((PrechargeState::Online, at)) if fresh(at, PccStatus::TIMEOUT_MS) => {
                if evidence.pcc_fault {
                    return Err(DtiRefusal::PccFault);
                }
                // With AIR+ closed the PCC and the DTI measure one node.
                match evidence.pcc_tractive_v {
                    Some(pcc_v) if (pcc_v - volts).abs() <= volts * AGREE_FRACTION => {
                        Ok(Path::HighVoltage)
                    }
                    pcc_v => Err(DtiRefusal::Disagree {
                        pcc_v,
                        dti_v: volts,
                    }),
                }
            }
            Some((state, at)) if fresh(at, PccStatus::TIMEOUT_MS) => {
                Err(DtiRefusal::PccNotOnline(Some(state)))
            }
            _ => Err(DtiRefusal::PccNotOnline(None)),
        }
    }
}
