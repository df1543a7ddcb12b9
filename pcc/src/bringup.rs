//! The PCC bring-up image's one decision, without hardware: pin 11 (AIR+) behind the HV gate.
//!
//! The gate reads both V/F converters as they are at each 10 ms step of the bench loop (the
//! edge interrupt time-stamps every pulse; [`FrequencyMeter::reading`] turns the stamps into a
//! frequency, or silence). A converter that gives no pulses is unknown, not 0 V: unplugged,
//! unpowered and broken look the same. So AIR+ can be armed only while both converters show
//! they are alive with a voltage below 60 V (on the bench: the bench supply on their sense
//! inputs), and it drops at the first step where that stops being true.
//!
//! [`FrequencyMeter::reading`]: crate::measurement::FrequencyMeter::reading

use crate::constants::{PrechargeConfig, TASK_PERIOD_MS, VfConfig};
use aer_console::hv_gate::{HV_CONFIRMATION_MS, HvGate, HvReading, HvRefusal, HvSensor};
use core::fmt;

/// The converters as the gate names them: accumulator, tractive system.
pub const CONVERTERS: [&str; 2] = ["accumulator (pin 14)", "tractive system (pin 15)"];

/// What a silent converter means, in the refusal.
const SILENT: &str = "no pulses, which a converter unplugged, unpowered or broken gives just as 0 V would: put a known voltage below 60 V on its sense input (the bench supply, step 6b) so it shows it is alive";

/// A converter's reading for the gate: the frequency its edges give at `now_ms` (`None`:
/// silent), as volts through `vf`.
pub fn converter_reading(hz: Option<f32>, vf: &VfConfig, now_ms: u32) -> HvReading {
    match hz {
        Some(hz) => HvReading::Volts {
            volts: vf.volts_for_hz(hz),
            at_ms: now_ms,
        },
        None => HvReading::Silent,
    }
}

/// Both converters as the gate reads them.
pub fn sensors(readings: [HvReading; 2]) -> [HvSensor<'static>; 2] {
    let [accumulator, tractive] = readings;
    let [accumulator_name, tractive_name] = CONVERTERS;
    [
        HvSensor {
            name: accumulator_name,
            reading: accumulator,
            silent: SILENT,
        },
        HvSensor {
            name: tractive_name,
            reading: tractive,
            silent: SILENT,
        },
    ]
}

/// Pin 11 behind the gate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AirPlusBench {
    gate: HvGate,
    high: bool,
}

impl Default for AirPlusBench {
    fn default() -> Self {
        Self::new()
    }
}

/// What `out air-plus-close on|off` did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum AirPlusAnswer {
    /// Pin 11 is high now.
    High,
    /// Pin 11 is low now (asked for).
    Low,
    /// Refused: pin 11 stays low.
    Refused(HvRefusal<'static>),
}

impl fmt::Display for AirPlusAnswer {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::High => f.write_str(
                "pin 11 (AIR+) HIGH for at most 30 s from the confirmation, while both converters read below 60 V",
            ),
            Self::Low => f.write_str("pin 11 (AIR+) low"),
            Self::Refused(why) => write!(f, "pin 11 (AIR+) stays low: {why}"),
        }
    }
}

/// The gate as the report states it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GateLine {
    /// Pin 11 is high.
    pub air_plus: bool,
    /// Armed for this many more ms, or why not.
    pub gate: Result<u32, HvRefusal<'static>>,
}

impl fmt::Display for GateLine {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "pin 11 (AIR+) {}; ",
            if self.air_plus { "HIGH" } else { "low" }
        )?;
        match self.gate {
            Ok(left_ms) => write!(f, "HV gate armed for {} s more", left_ms.div_ceil(1_000)),
            Err(why) => write!(f, "HV gate closed: {why}"),
        }
    }
}

impl AirPlusBench {
    /// Pin 11 low, nothing confirmed.
    pub const fn new() -> Self {
        Self {
            gate: HvGate::new(PrechargeConfig::CAR.discharged_v, TASK_PERIOD_MS),
            high: false,
        }
    }

    /// Whether pin 11 is to be high.
    pub const fn air_plus(&self) -> bool {
        self.high
    }

    /// `confirm hv-disconnected` at `now_ms`: taken only if both converters are alive and
    /// below 60 V.
    pub fn confirm(
        &mut self,
        now_ms: u32,
        readings: [HvReading; 2],
    ) -> Result<(), HvRefusal<'static>> {
        self.gate.confirm(now_ms, &sensors(readings))
    }

    /// `out air-plus-close on|off` at `now_ms`.
    pub fn set(&mut self, high: bool, now_ms: u32, readings: [HvReading; 2]) -> AirPlusAnswer {
        if !high {
            self.high = false;
            return AirPlusAnswer::Low;
        }
        match self.gate.allows(now_ms, &sensors(readings)) {
            Ok(()) => {
                self.high = true;
                AirPlusAnswer::High
            }
            Err(why) => {
                self.high = false;
                AirPlusAnswer::Refused(why)
            }
        }
    }

    /// Every step: pin 11 stays high only while the gate allows it; returns why it dropped.
    pub fn step(&mut self, now_ms: u32, readings: [HvReading; 2]) -> Option<HvRefusal<'static>> {
        if !self.high {
            return None;
        }
        let why = self.gate.allows(now_ms, &sensors(readings)).err()?;
        self.high = false;
        self.gate.revoke();
        Some(why)
    }

    /// `off`, `bootloader`, `restart`: pin 11 low, the confirmation revoked.
    pub fn all_off(&mut self) {
        self.high = false;
        self.gate.revoke();
    }

    /// The gate as the report states it at `now_ms`.
    pub fn line(&self, now_ms: u32, readings: [HvReading; 2]) -> GateLine {
        GateLine {
            air_plus: self.high,
            gate: self
                .gate
                .allows(now_ms, &sensors(readings))
                .map(|()| self.left_ms(now_ms)),
        }
    }

    fn left_ms(&self, now_ms: u32) -> u32 {
        // `allows` succeeded: the confirmation is younger than its limit.
        self.gate
            .confirmed_for(now_ms)
            .map_or(0, |age| HV_CONFIRMATION_MS.saturating_sub(age))
    }
}
