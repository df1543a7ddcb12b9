//! The fault bitmap (the CCM_Status and telemetry fault flags) and its handler.

use crate::config::{MAX_TEMP_DEGC, MIN_CELL_V, SENSOR_FAULT_PERSIST_MS, SOC_DERATE_END};
use aer_control::Persist;

/// One fault bit (vehicle-facts.md: bits 0-7).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Fault {
    /// Pack current above the BMS's discharge limit.
    OverCurrent = 0,
    /// Lowest cell below 2.8 V.
    UnderVoltage = 1,
    /// Motor, inverter or pack over its temperature limit.
    OverTemperature = 2,
    /// APPS out of range or implausible.
    Apps = 3,
    /// Brake pressure sensor out of range.
    Bse = 4,
    /// Front and rear brake circuits implausible.
    Bpps = 5,
    /// Throttle with the brake pressed (EV.4.7), until the throttle is released.
    AppsBrakePlausibility = 6,
    /// Pack SOC at or below 5 %.
    LowBatteryVoltage = 7,
}

impl Fault {
    /// Every fault, in bit order.
    pub const ALL: [Self; 8] = [
        Self::OverCurrent,
        Self::UnderVoltage,
        Self::OverTemperature,
        Self::Apps,
        Self::Bse,
        Self::Bpps,
        Self::AppsBrakePlausibility,
        Self::LowBatteryVoltage,
    ];

    /// The fault's bit.
    pub const fn mask(self) -> u32 {
        1 << self as u8
    }

    /// Whether the vehicle must leave DRIVING for FAULT. EV.4.7 only asks that the motor
    /// stops while the pedals disagree, so the plausibility fault cuts torque in DRIVING
    /// instead.
    pub const fn stops_the_vehicle(self) -> bool {
        !matches!(self, Self::AppsBrakePlausibility)
    }
}

/// Active faults, one bit each (32 bits as in the team's design; 8 used).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FaultMap(u32);

impl FaultMap {
    /// No fault.
    pub const NONE: Self = Self(0);

    /// Sets or clears `fault`.
    pub fn set(&mut self, fault: Fault, active: bool) {
        if active {
            self.0 |= fault.mask();
        } else {
            self.0 &= !fault.mask();
        }
    }

    /// Whether `fault` is active.
    pub const fn has(&self, fault: Fault) -> bool {
        self.0 & fault.mask() != 0
    }

    /// The raw bitmap.
    pub const fn bits(&self) -> u32 {
        self.0
    }

    /// Any fault at all: no torque.
    pub const fn any(&self) -> bool {
        self.0 != 0
    }

    /// Any fault that puts the vehicle in FAULT.
    pub fn stops_the_vehicle(&self) -> bool {
        Fault::ALL
            .iter()
            .any(|fault| self.has(*fault) && fault.stops_the_vehicle())
    }
}

/// Accumulator and drive readings the fault checks need.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PackReadings {
    /// Pack current (A, positive discharging).
    pub current_a: f32,
    /// BMS discharge current limit (A).
    pub discharge_limit_a: f32,
    /// Lowest cell voltage (V).
    pub low_cell_v: f32,
    /// SOC (0..1).
    pub soc: f32,
    /// Motor, inverter and hottest pack temperatures (degC).
    pub temperatures_degc: (f32, f32, f32),
    /// True once the BMS has reported (limits and cells are meaningless before).
    pub bms_seen: bool,
}

/// Turns readings into the fault bitmap; readings-based faults must persist 100 ms.
#[derive(Debug, Clone, Default)]
pub struct FaultMonitor {
    over_current: Persist,
    under_voltage: Persist,
    over_temperature: Persist,
}

impl FaultMonitor {
    /// Evaluates every fault at `now_ms`.
    pub fn evaluate(
        &mut self,
        now_ms: u32,
        pack: &PackReadings,
        apps_fault: bool,
        apps_brake_plausibility: bool,
        bse_fault: bool,
        brake_circuits_implausible: bool,
    ) -> FaultMap {
        let persists = |persist: &mut Persist, condition: bool| {
            persist
                .update(condition, now_ms)
                .is_some_and(|held| held > SENSOR_FAULT_PERSIST_MS)
        };
        let (motor, inverter, pack_temp) = pack.temperatures_degc;
        let (motor_max, inverter_max, pack_max) = MAX_TEMP_DEGC;
        let mut map = FaultMap::NONE;
        map.set(
            Fault::OverCurrent,
            persists(
                &mut self.over_current,
                pack.bms_seen && pack.current_a > pack.discharge_limit_a,
            ),
        );
        map.set(
            Fault::UnderVoltage,
            persists(
                &mut self.under_voltage,
                pack.bms_seen && pack.low_cell_v < MIN_CELL_V,
            ),
        );
        // A temperature that is not a number counts as too hot.
        let too_hot = |t: f32, max: f32| t.is_nan() || t > max;
        let hot = too_hot(motor, motor_max)
            || too_hot(inverter, inverter_max)
            || too_hot(pack_temp, pack_max);
        map.set(
            Fault::OverTemperature,
            persists(&mut self.over_temperature, hot),
        );
        map.set(Fault::Apps, apps_fault);
        map.set(Fault::Bse, bse_fault);
        map.set(Fault::Bpps, brake_circuits_implausible);
        map.set(Fault::AppsBrakePlausibility, apps_brake_plausibility);
        map.set(
            Fault::LowBatteryVoltage,
            pack.bms_seen && pack.soc <= SOC_DERATE_END,
        );
        map
    }
}
