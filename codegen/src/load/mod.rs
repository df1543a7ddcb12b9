//! Load: bytes on disk -> parsed schema plus where each item was written, for diagnostics.

pub(crate) mod calibration;
pub(crate) mod dbc;
pub(crate) mod telemetry;

use std::path::Path;

use crate::diagnostic::{Code, Diagnostics, Reporter};

/// The text of a schema file; one that cannot be read is reported as `unreadable`.
pub(crate) fn read(path: &Path, unreadable: Code) -> Result<String, Diagnostics> {
    std::fs::read_to_string(path).map_err(|e| {
        let mut r = Reporter::new(path, "");
        r.report(
            unreadable,
            0,
            format!("cannot read the file: {e}"),
            "check the path and that the file is UTF-8",
        );
        Diagnostics(r.diagnostics)
    })
}

/// A YAML schema (`what`, described at the top of `file_name`) parsed from `text`; a file
/// that does not parse is reported as `syntax` at the line the parser names.
pub(crate) fn parse_yaml<T: serde::de::DeserializeOwned>(
    path: &Path,
    text: &str,
    syntax: Code,
    what: &str,
    file_name: &str,
) -> Result<T, Diagnostics> {
    serde_saphyr::from_str::<T>(text).map_err(|err| {
        let line = err
            .location()
            .map_or(0, |l| usize::try_from(l.line()).unwrap_or(0));
        let message = err.to_string();
        let first = message.lines().next().unwrap_or("invalid YAML").to_owned();
        let mut r = Reporter::new(path, text);
        r.report(
            syntax,
            line,
            format!("the {what} is not valid: {first}"),
            format!(
                "compare with the description at the top of {file_name} (known keys, YAML indentation)"
            ),
        );
        Diagnostics(r.diagnostics)
    })
}
