//! What the CCM keeps from the CAN buses: every decoded frame updates the telemetry mirror
//! (generated `TelemetryMirror::apply`), and the messages the control logic acts on are kept with
//! their arrival time, so the control step only ever uses fresh values.

use crate::constants::{
    BMS_CELLS_TIMEOUT_MS, BMS_LIMITS_TIMEOUT_MS, BMS_PACK_TIMEOUT_MS, PCC_STATUS_TIMEOUT_MS,
    START_UP_GRACE_MS,
};
use aer::can::{
    AnyMessage, DtiAcLimits, DtiCurrents, DtiFlags, DtiSpeed, DtiTemperatures, Mcu1, Mcu2, Mcu3,
    OrionCellVoltages, OrionLimits, OrionPackStatus, PccStatus,
};
use aer::runtime::{CounterCheck, DecodeError};
use aer::telemetry::TelemetryMirror;
use embedded_can::{Frame, Id};

/// The latest value of one message and when it arrived (ms).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Received<T> {
    latest: Option<(T, u32)>,
}

impl<T> Default for Received<T> {
    fn default() -> Self {
        Self { latest: None }
    }
}

impl<T: Copy> Received<T> {
    /// Records `value`, received at `now_ms`.
    pub fn store(&mut self, value: T, now_ms: u32) {
        self.latest = Some((value, now_ms));
    }

    /// The value if it is at most `limit_ms` old at `now_ms`.
    pub fn fresh(&self, now_ms: u32, limit_ms: u32) -> Option<T> {
        self.latest
            .filter(|(_, at)| now_ms.wrapping_sub(*at) <= limit_ms)
            .map(|(value, _)| value)
    }

    /// True when the value is older than `limit_ms`, or was never received although the CCM
    /// started (`started_ms`) more than the start-up grace period ago.
    pub fn lost(&self, now_ms: u32, limit_ms: u32, started_ms: u32) -> bool {
        match self.latest {
            Some((_, at)) => now_ms.wrapping_sub(at) > limit_ms,
            None => now_ms.wrapping_sub(started_ms) > START_UP_GRACE_MS,
        }
    }
}

/// What the control step reads from the inverter, whichever it is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InverterStatus {
    /// Motor speed (rpm).
    pub motor_rpm: Option<f32>,
    /// Torque at the motor as the inverter reports it (Nm).
    pub torque_nm: Option<f32>,
    /// Motor phase current (A; the DTI's is the peak AC current).
    pub phase_current_a: Option<f32>,
    /// The torque the inverter can deliver now, after its own limits (Nm).
    pub available_torque_nm: Option<f32>,
    /// DC link voltage (V) and current (A) as the inverter measures them.
    pub dc_link: Option<(f32, f32)>,
    /// Inverter and motor temperatures (degC).
    pub temperatures_degc: Option<(f32, f32)>,
    /// The inverter reports a fault (it will not drive, or it reports what it should not).
    pub fault: bool,
    /// The inverter reports a warning or a limit that only reduces what it delivers.
    pub warning: bool,
    /// A status frame the CCM acts on is older than its limit (or never came).
    pub lost: bool,
}

/// Which nodes the CCM has lost (an input older than its limit).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LostNodes {
    /// The PCC's status.
    pub pcc: bool,
    /// Any of the Orion BMS's three frames.
    pub bms: bool,
    /// Any of the inverter's status frames the CCM acts on.
    pub inverter: bool,
}

/// The values the control step acts on, each `None` unless fresh.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BusInputs {
    /// PCC status.
    pub pcc: Option<PccStatus>,
    /// Orion pack status: current, voltage, SOC.
    pub pack: Option<OrionPackStatus>,
    /// Orion current limits and temperatures.
    pub limits: Option<OrionLimits>,
    /// Orion cell voltages.
    pub cells: Option<OrionCellVoltages>,
    /// The inverter's status, whichever inverter the CCM drives.
    pub inverter: InverterStatus,
    /// Inputs gone stale.
    pub lost: LostNodes,
}

/// Latest values from the buses.
#[derive(Debug, Clone)]
pub struct BusState {
    /// Every telemetry field mirrored from a DBC signal, as last received.
    pub mirror: TelemetryMirror,
    /// PCC_Status.
    pub pcc: Received<PccStatus>,
    /// Orion_PackStatus.
    pub pack: Received<OrionPackStatus>,
    /// Orion_Limits.
    pub limits: Received<OrionLimits>,
    /// Orion_CellVoltages.
    pub cells: Received<OrionCellVoltages>,
    /// MCU1.
    pub mcu1: Received<Mcu1>,
    /// MCU2.
    pub mcu2: Received<Mcu2>,
    /// MCU3.
    pub mcu3: Received<Mcu3>,
    /// DTI packet 0x20: speed, DC voltage.
    pub dti_speed: Received<DtiSpeed>,
    /// DTI packet 0x21: AC and DC current.
    pub dti_currents: Received<DtiCurrents>,
    /// DTI packet 0x22: temperatures, fault code.
    pub dti_temperatures: Received<DtiTemperatures>,
    /// DTI packet 0x24: drive enabled, limits, CAN map version.
    pub dti_flags: Received<DtiFlags>,
    /// DTI packet 0x25: AC current limits.
    pub dti_ac_limits: Received<DtiAcLimits>,
    /// Frames of known ids that failed to decode (wrong length): counted and ignored.
    pub decode_errors: u32,
    /// Frames refused by their counter or checksum (a repeated or skipped counter, a wrong
    /// checksum): not fresh, intact data, so counted and ignored like a lost frame.
    pub integrity_errors: u32,
    /// The last counter accepted from MCU1: an inverter repeating its last frame is a stuck
    /// inverter, not a fresh one.
    mcu1_counter: CounterCheck,
    /// The last counter accepted from MCU2.
    mcu2_counter: CounterCheck,
    /// Frames whose id the schema does not know: counted and ignored.
    pub unknown_ids: u32,
}

impl Default for BusState {
    fn default() -> Self {
        Self {
            mirror: TelemetryMirror::EMPTY,
            pcc: Received::default(),
            pack: Received::default(),
            limits: Received::default(),
            cells: Received::default(),
            mcu1: Received::default(),
            mcu2: Received::default(),
            mcu3: Received::default(),
            dti_speed: Received::default(),
            dti_currents: Received::default(),
            dti_temperatures: Received::default(),
            dti_flags: Received::default(),
            dti_ac_limits: Received::default(),
            decode_errors: 0,
            integrity_errors: 0,
            mcu1_counter: CounterCheck::default(),
            mcu2_counter: CounterCheck::default(),
            unknown_ids: 0,
        }
    }
}

impl BusState {
    /// Feeds one received frame.
    pub fn on_frame(&mut self, frame: &impl Frame, now_ms: u32) {
        let (id, extended) = match frame.id() {
            Id::Standard(id) => (u32::from(id.as_raw()), false),
            Id::Extended(id) => (id.as_raw(), true),
        };
        if frame.is_remote_frame() {
            return;
        }
        let message = match AnyMessage::decode(id, extended, frame.data()) {
            Ok(message) => message,
            Err(DecodeError::UnknownId { .. }) => {
                self.unknown_ids = self.unknown_ids.wrapping_add(1);
                return;
            }
            Err(_) => {
                self.decode_errors = self.decode_errors.wrapping_add(1);
                return;
            }
        };
        let verdict = match &message {
            AnyMessage::Mcu1(_) => Mcu1::META.verify(&mut self.mcu1_counter, frame.data()),
            AnyMessage::Mcu2(_) => Mcu2::META.verify(&mut self.mcu2_counter, frame.data()),
            _ => Ok(()),
        };
        if verdict.is_err() {
            self.integrity_errors = self.integrity_errors.wrapping_add(1);
            return;
        }
        match message {
            AnyMessage::PccStatus(status) => self.pcc.store(status, now_ms),
            AnyMessage::OrionPackStatus(pack) => self.pack.store(pack, now_ms),
            AnyMessage::OrionLimits(limits) => self.limits.store(limits, now_ms),
            AnyMessage::OrionCellVoltages(cells) => self.cells.store(cells, now_ms),
            AnyMessage::Mcu1(mcu1) => self.mcu1.store(mcu1, now_ms),
            AnyMessage::Mcu2(mcu2) => self.mcu2.store(mcu2, now_ms),
            AnyMessage::Mcu3(mcu3) => self.mcu3.store(mcu3, now_ms),
            AnyMessage::DtiSpeed(speed) => self.dti_speed.store(speed, now_ms),
            AnyMessage::DtiCurrents(currents) => self.dti_currents.store(currents, now_ms),
            AnyMessage::DtiTemperatures(temperatures) => {
                self.dti_temperatures.store(temperatures, now_ms);
            }
            AnyMessage::DtiFlags(flags) => self.dti_flags.store(flags, now_ms),
            AnyMessage::DtiAcLimits(limits) => self.dti_ac_limits.store(limits, now_ms),
            _ => {}
        }
        self.mirror.apply(&message);
    }

    /// The fresh values at `now_ms`, for a CCM that started at `started_ms`, with the
    /// inverter's `status` as read from these frames (`InverterKind::status`).
    pub fn inputs(&self, now_ms: u32, started_ms: u32, status: InverterStatus) -> BusInputs {
        let lost = LostNodes {
            pcc: self.pcc.lost(now_ms, PCC_STATUS_TIMEOUT_MS, started_ms),
            bms: self.pack.lost(now_ms, BMS_PACK_TIMEOUT_MS, started_ms)
                || self.limits.lost(now_ms, BMS_LIMITS_TIMEOUT_MS, started_ms)
                || self.cells.lost(now_ms, BMS_CELLS_TIMEOUT_MS, started_ms),
            inverter: status.lost,
        };
        BusInputs {
            pcc: self.pcc.fresh(now_ms, PCC_STATUS_TIMEOUT_MS),
            pack: self.pack.fresh(now_ms, BMS_PACK_TIMEOUT_MS),
            limits: self.limits.fresh(now_ms, BMS_LIMITS_TIMEOUT_MS),
            cells: self.cells.fresh(now_ms, BMS_CELLS_TIMEOUT_MS),
            inverter: status,
            lost,
        }
    }
}
