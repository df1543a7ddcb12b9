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

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct AxisSpec {
    pub label: String,
    pub unit: String,
    pub points: Spanned<Vec<f64>>,
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
