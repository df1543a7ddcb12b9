//! Why a change to the calibration was refused, in the numbers the XCP slave publishes
//! ([`aer_xcp::Detail`]): the parameter (its index in [`PARAMETERS`], which the A2L's
//! `xcp.item` table names), the element, the value and the limit it met. A tuner reads them in
//! CANape or pyxcp as measurements (`xcp.refused_*`), the same reason the Pi's tune page
//! prints.

use super::sensors::CalibrationError as SensorError;
use crate::constants::{BSE_ZERO_V, MIN_PEDAL_TRAVEL_V, MIN_SHOCK_SPAN_V, SHOCK_VALID_V};
use aer::calibration::{CalibrationError as LimitError, ChangeWhen, PARAMETERS};
use aer_xcp::{Detail, reason};

/// The A2L item number of the parameter named `name` ([`Detail::NO_ITEM`] for none).
fn item(name: &str) -> u16 {
    PARAMETERS
        .iter()
        .position(|parameter| parameter.name == name)
        .and_then(|index| u16::try_from(index).ok())
        .unwrap_or(Detail::NO_ITEM)
}

fn element(index: usize) -> u8 {
    u8::try_from(index).unwrap_or(u8::MAX)
}

fn on(name: &str, index: usize, reason: u8, value: f32, limit: f32) -> Detail {
    Detail {
        reason,
        item: item(name),
        element: element(index),
        value,
        limit,
    }
}

/// `value` against the band `(low, high)`: below its low end or above its high end.
fn outside(name: &str, index: usize, value: f32, (low, high): (f32, f32)) -> Detail {
    if value.is_nan() {
        on(name, index, reason::NOT_A_NUMBER, value, 0.0)
    } else if value < low {
        on(name, index, reason::BELOW_MIN, value, low)
    } else {
        on(name, index, reason::ABOVE_MAX, value, high)
    }
}

/// A page a parameter's own limits refuse; `page` is the page that was refused.
pub fn limits(error: &LimitError, page: &[u8]) -> Detail {
    match *error {
        LimitError::OutOfRange {
            parameter,
            index,
            value,
        } => {
            let Some(declared) = PARAMETERS.iter().find(|p| p.name == parameter) else {
                return Detail::of(reason::NOT_A_NUMBER, value as f32, 0.0);
            };
            let normal = value == 0.0 || (value as f32).is_normal();
            if !normal {
                on(parameter, index, reason::NOT_A_NUMBER, value as f32, 0.0)
            } else {
                outside(
                    parameter,
                    index,
                    value as f32,
                    (declared.min as f32, declared.max as f32),
                )
            }
        }
        LimitError::NotIncreasing { parameter, index } => {
            let declared = PARAMETERS.iter().find(|p| p.name == parameter);
            let at = |i: usize| {
                declared
                    .and_then(|p| p.value(page, i))
                    .map_or(f32::NAN, |v| v as f32)
            };
            on(
                parameter,
                index,
                reason::NOT_INCREASING,
                at(index),
                index.checked_sub(1).map_or(f32::NAN, at),
            )
        }
    }
}

/// Which element of a per-sensor parameter `name` (a pedal, a brake circuit, a shock
/// corner) is: its position in the sensor error's own names.
fn sensor_index(name: &str, names: &[&str]) -> usize {
    names.iter().position(|n| *n == name).unwrap_or(0)
}

const PEDALS: [(&str, &str); 2] = [("APPS1", "apps1_v"), ("APPS2", "apps2_v")];
const PEDAL_POINTS: [&str; 2] = ["at rest", "at full travel"];
const BRAKES: [&str; 2] = ["front (BSE1)", "rear (BSE2)"];
const SHOCK_ENDS: [(&str, &str); 2] = [
    ("extended", "shock_extended_v"),
    ("compressed", "shock_compressed_v"),
];

fn pedal_parameter(sensor: &str) -> &'static str {
    PEDALS
        .iter()
        .find(|(name, _)| *name == sensor)
        .map_or("apps1_v", |(_, parameter)| parameter)
}

/// A page the sensor cross-checks refuse.
pub fn sensors(error: &SensorError) -> Detail {
    match *error {
        SensorError::PedalOutOfBand {
            sensor,
            point,
            volts,
            band,
        } => outside(
            pedal_parameter(sensor),
            sensor_index(point, &PEDAL_POINTS),
            volts,
            band,
        ),
        SensorError::TooLittleTravel { sensor, travel_v } => on(
            pedal_parameter(sensor),
            1,
            reason::CROSS_CHECK,
            travel_v,
            MIN_PEDAL_TRAVEL_V,
        ),
        SensorError::BrakeZeroOutOfBand { circuit, volts } => outside(
            "brake_zero_v",
            sensor_index(circuit, &BRAKES),
            volts,
            BSE_ZERO_V,
        ),
        SensorError::ShockOutOfBand {
            corner,
            point,
            volts,
        } => {
            let parameter = SHOCK_ENDS
                .iter()
                .find(|(end, _)| *end == point)
                .map_or("shock_extended_v", |(_, parameter)| parameter);
            outside(
                parameter,
                sensor_index(corner, &super::SHOCK_CORNERS),
                volts,
                SHOCK_VALID_V,
            )
        }
        SensorError::ShockTooLittleTravel { corner, span_v } => on(
            "shock_compressed_v",
            sensor_index(corner, &super::SHOCK_CORNERS),
            reason::CROSS_CHECK,
            span_v,
            MIN_SHOCK_SPAN_V,
        ),
    }
}

/// Parameter `index` may not change in the vehicle's state now.
pub fn not_now(index: usize, change: ChangeWhen) -> Detail {
    let reason = match change {
        ChangeWhen::TractiveOff => reason::NEEDS_TRACTIVE_OFF,
        ChangeWhen::Standstill | ChangeWhen::Driving => reason::NEEDS_STANDSTILL,
    };
    Detail {
        reason,
        item: u16::try_from(index).unwrap_or(Detail::NO_ITEM),
        element: 0,
        value: 0.0,
        limit: 0.0,
    }
}

/// Bytes outside the page.
pub const NOT_MAPPED: Detail = Detail::of(reason::NOT_MAPPED, 0.0, 0.0);
