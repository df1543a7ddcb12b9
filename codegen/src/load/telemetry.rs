//! Reads `telemetry.yaml`. Every value keeps its line so validation can point at it; unknown
//! keys are errors (a typo such as `sacle:` must not be silently ignored).

use std::path::Path;

use serde::Deserialize;
use serde_saphyr::Spanned;

use crate::diagnostic::{Code, Diagnostics};

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct TelemetryFile {
    pub packet: Spanned<PacketSpec>,
    pub fields: Vec<Spanned<FieldSpec>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct PacketSpec {
    pub name: Spanned<String>,
    #[serde(default)]
    pub description: String,
    pub tx_id: Spanned<u32>,
    pub flow_control_id: Spanned<u32>,
    pub period_ms: u32,
    /// How long a receiver waits for the next packet before it counts the data stale; by
    /// default a few periods, as for the DBC's messages.
    #[serde(default)]
    pub timeout_ms: Option<Spanned<u32>>,
    /// The bus it is sent on: one of the DBC's `AerBus` names.
    #[serde(default)]
    pub bus: Option<Spanned<String>>,
    /// The node that sends it (a `BU_` of the DBC): fields mirroring messages this node sends
    /// are filled from the messages it passes to `from_parts`, not from received frames.
    #[serde(default)]
    pub sender: Option<Spanned<String>>,
    /// Bytes the packet is planned to grow by (the team's next sensors): the generator warns
    /// (W0211) when its bus would then be loaded above the warning threshold.
    #[serde(default)]
    pub headroom_bytes: Option<Spanned<u32>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct FieldSpec {
    pub name: Spanned<String>,
    #[serde(default)]
    pub group: Option<String>,
    #[serde(default)]
    pub description: Option<String>,
    #[serde(default)]
    pub signal: Option<Spanned<String>>,
    #[serde(default, rename = "type")]
    pub wire: Option<Spanned<String>>,
    #[serde(default)]
    pub scale: Option<Spanned<f64>>,
    #[serde(default)]
    pub offset: Option<f64>,
    #[serde(default)]
    pub unit: Option<String>,
    #[serde(default)]
    pub min: Option<f64>,
    #[serde(default)]
    pub max: Option<f64>,
    #[serde(default, rename = "enum")]
    pub enum_name: Option<Spanned<String>>,
    /// The name people read (pit view, exports, bus documentation).
    #[serde(default)]
    pub label: Option<String>,
    #[serde(default)]
    pub display: Option<DisplaySpec>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct DisplaySpec {
    #[serde(default)]
    pub warn: Option<f64>,
    #[serde(default)]
    pub critical: Option<f64>,
    #[serde(default)]
    pub warn_below: Option<f64>,
    #[serde(default)]
    pub critical_below: Option<f64>,
}

/// A parsed telemetry file with its source, for diagnostics.
pub(crate) struct LoadedTelemetry {
    pub text: String,
    pub file: TelemetryFile,
}

pub(crate) fn load(path: &Path) -> Result<LoadedTelemetry, Diagnostics> {
    let text = super::read(path, Code::TelemetryUnreadable)?;
    parse(path, text)
}

pub(crate) fn parse(path: &Path, text: String) -> Result<LoadedTelemetry, Diagnostics> {
    let file = super::parse_yaml(
        path,
        &text,
        Code::TelemetrySyntax,
        "telemetry schema",
        "telemetry.yaml",
    )?;
    Ok(LoadedTelemetry { text, file })
}
