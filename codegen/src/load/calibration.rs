//! Reads `calibration.yaml`. Every value keeps its line so validation can point at it; unknown
//! keys are errors (a typo such as `chnage:` must not leave a parameter writable while driving).

use std::path::Path;

use serde::Deserialize;
use serde_saphyr::Spanned;

use crate::diagnostic::{Code, Diagnostics};

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct CalibrationFile {
    pub calibration: Spanned<CalibrationSpec>,
    pub parameters: Vec<Spanned<ParameterSpec>>,
    pub internals: Spanned<Vec<Spanned<InternalSpec>>>,
    pub xcp: Spanned<XcpSpec>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct CalibrationSpec {
    pub name: Spanned<String>,
    #[serde(default)]
    pub description: String,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct ParameterSpec {
    pub name: Spanned<String>,
    #[serde(default)]
    pub label: Option<String>,
    #[serde(default)]
    pub group: Option<String>,
    #[serde(rename = "type")]
    pub element: Spanned<String>,
    #[serde(default)]
    pub unit: Option<String>,
    pub default: Spanned<DefaultSpec>,
    pub min: Spanned<f64>,
    pub max: Spanned<f64>,
    #[serde(default)]
    pub increasing: bool,
    #[serde(default)]
    pub elements: Option<Spanned<Vec<String>>>,
    #[serde(default)]
    pub axis: Option<Spanned<AxisSpec>>,
    pub change: Spanned<String>,
    #[serde(default)]
    pub description: Option<String>,
}

/// A scalar's value or a list's elements.
#[derive(Debug, Deserialize)]
#[serde(untagged)]
pub(crate) enum DefaultSpec {
    One(f64),
    Many(Vec<f64>),
}

/// A curve's input: the points it is stored at (tunable, in the page after the curve), their
/// limits, and the internal value the firmware looks the curve up with.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct AxisSpec {
    pub label: String,
    pub unit: String,
    pub points: Spanned<Vec<f64>>,
    pub min: Spanned<f64>,
    pub max: Spanned<f64>,
    pub input: Spanned<String>,
}

/// A controller's internal value a tuner samples (always f32).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct InternalSpec {
    pub name: Spanned<String>,
    #[serde(default)]
    pub unit: Option<String>,
    pub min: Spanned<f64>,
    pub max: Spanned<f64>,
    #[serde(default)]
    pub description: Option<String>,
}

/// The XCP slave's settings. Numbers are read as numbers and checked by validation, so a
/// port of 0 or 70000 is reported with its own code rather than as a YAML type error.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct XcpSpec {
    #[serde(default)]
    pub bus: Option<Spanned<String>>,
    pub command_message: Spanned<String>,
    pub response_message: Spanned<String>,
    pub tcp_port: Spanned<f64>,
    pub max_daq: Spanned<f64>,
    pub odt_entries: Spanned<f64>,
    pub max_odt_entry_size: Spanned<f64>,
    pub idle_timeout_s: Spanned<f64>,
    pub unlock_delay_s: Spanned<f64>,
    pub unlock_delay_max_s: Spanned<f64>,
    pub events: Spanned<Vec<Spanned<EventSpec>>>,
}

/// An XCP event channel: a point in the firmware where DAQ lists are sampled.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct EventSpec {
    pub name: Spanned<String>,
    pub period_ms: Spanned<f64>,
    #[serde(default)]
    pub description: Option<String>,
}

/// A parsed calibration file with its source, for diagnostics.
pub(crate) struct LoadedCalibration {
    pub text: String,
    pub file: CalibrationFile,
}

pub(crate) fn load(path: &Path) -> Result<LoadedCalibration, Diagnostics> {
    let text = super::read(path, Code::CalibrationUnreadable)?;
    parse(path, text)
}

pub(crate) fn parse(path: &Path, text: String) -> Result<LoadedCalibration, Diagnostics> {
    let file = super::parse_yaml(
        path,
        &text,
        Code::CalibrationSyntax,
        "calibration schema",
        "calibration.yaml",
    )?;
    Ok(LoadedCalibration { text, file })
}
