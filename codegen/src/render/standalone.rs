//! Renders the files of a crate: the codec, its crate root, and the decode/encode examples.

use askama::Template;

#[derive(Template)]
#[template(path = "lib.rs", escape = "none")]
pub(crate) struct LibTemplate<'a> {
    pub title: &'a str,
    pub source: &'a str,
    /// Whether the crate also carries the telemetry packet, TDengine schema and MQTT topics.
    pub telemetry: bool,
    /// Whether the crate also carries the CCM's calibration.
    pub calibration: bool,
}

#[derive(Template)]
#[template(path = "crate/Cargo.toml", escape = "none")]
pub(crate) struct CargoTemplate<'a> {
    pub name: &'a str,
    pub source: &'a str,
    /// Adds an empty `[workspace]` so the crate builds wherever it is written.
    pub standalone: bool,
}

#[derive(Template)]
#[template(path = "decode.rs", escape = "none")]
pub(crate) struct DecodeExample<'a> {
    pub krate: &'a str,
}

#[derive(Template)]
#[template(path = "encode.rs", escape = "none")]
pub(crate) struct EncodeExample<'a> {
    pub krate: &'a str,
}
