//! Reads a DBC file: strips a UTF-8 BOM, falls back to cp1252 (what CANdb++ writes), parses with
//! can-dbc, and indexes the lines where messages, signals and attributes are written so that
//! validation can point at them.

use std::collections::HashMap;
use std::path::Path;

use crate::diagnostic::{Code, Diagnostic, Diagnostics, Reporter};

/// A parsed DBC file with the source kept for diagnostics.
pub(crate) struct LoadedDbc {
    pub text: String,
    pub dbc: can_dbc::Dbc,
    pub lines: LineIndex,
}

/// Where things are written in the file (1-based lines).
#[derive(Debug, Default)]
pub(crate) struct LineIndex {
    /// One entry per `BO_` line, in file order: (line, id exactly as written).
    pub messages: Vec<(usize, u64)>,
    /// (raw message id as written, signal name) -> lines of its `SG_`s, in file order (a name
    /// written twice has two).
    pub signals: HashMap<(u64, String), Vec<usize>>,
    /// (raw message id, signal name) -> line of its `VAL_`.
    pub values: HashMap<(u64, String), usize>,
    /// (raw message id, signal name) -> line of its `SG_MUL_VAL_`.
    pub mux_values: HashMap<(u64, String), usize>,
    /// (raw message id, signal name) -> line of its `SIG_VALTYPE_`.
    pub value_types: HashMap<(u64, String), usize>,
    /// (attribute name, raw message id) -> line of a `BA_ "name" BO_ id` assignment.
    pub message_attributes: HashMap<(String, u64), usize>,
    /// (attribute name, raw message id, signal) -> line of a `BA_ "name" SG_ id sig` assignment.
    pub signal_attributes: HashMap<(String, u64, String), usize>,
    /// Value table name -> line of its `VAL_TABLE_`.
    pub value_tables: HashMap<String, usize>,
}

impl LineIndex {
    fn build(text: &str) -> Self {
        let mut index = LineIndex::default();
        let mut current_message: Option<u64> = None;
        for (i, line) in text.lines().enumerate() {
            let n = i + 1;
            let mut tokens = line.split_whitespace();
            match tokens.next() {
                Some("BO_") => {
                    let id = tokens.next().and_then(|t| t.parse::<u64>().ok());
                    if let Some(id) = id {
                        index.messages.push((n, id));
                    }
                    current_message = id;
                }
                Some("SG_") => {
                    if let (Some(id), Some(name)) = (current_message, tokens.next()) {
                        index
                            .signals
                            .entry((id, name.to_owned()))
                            .or_default()
                            .push(n);
                    }
                }
                Some("VAL_") => {
                    if let Some((id, sig)) = id_and_signal(&mut tokens) {
                        index.values.insert((id, sig), n);
                    }
                }
                Some("SG_MUL_VAL_") => {
                    if let Some((id, sig)) = id_and_signal(&mut tokens) {
                        index.mux_values.insert((id, sig), n);
                    }
                }
                Some("SIG_VALTYPE_") => {
                    if let Some((id, sig)) = id_and_signal(&mut tokens) {
                        index.value_types.insert((id, sig), n);
                    }
                }
                Some("BA_") => {
                    let name = tokens.next().map(|t| t.trim_matches('"').to_owned());
                    match (name, tokens.next()) {
                        (Some(name), Some("BO_")) => {
                            if let Some(id) = tokens.next().and_then(|t| t.parse().ok()) {
                                index.message_attributes.insert((name, id), n);
                            }
                        }
                        (Some(name), Some("SG_")) => {
                            if let Some((id, sig)) = id_and_signal(&mut tokens) {
                                index.signal_attributes.insert((name, id, sig), n);
                            }
                        }
                        _ => {}
                    }
                }
                Some("VAL_TABLE_") => {
                    if let Some(name) = tokens.next() {
                        index.value_tables.entry(name.to_owned()).or_insert(n);
                    }
                    current_message = None;
                }
                Some(t) if !t.is_empty() => current_message = None,
                _ => {}
            }
        }
        index
    }
}

fn id_and_signal<'a>(tokens: &mut impl Iterator<Item = &'a str>) -> Option<(u64, String)> {
    let id = tokens.next()?.parse().ok()?;
    let sig = tokens.next()?.trim_end_matches(';').to_owned();
    Some((id, sig))
}

/// Decodes DBC bytes: UTF-8 (BOM stripped) when valid, otherwise Windows-1252.
pub fn decode_text(bytes: &[u8]) -> Option<String> {
    let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    match std::str::from_utf8(bytes) {
        Ok(s) => Some(s.to_owned()),
        Err(_) => can_dbc::decode_cp1252(bytes).map(|c| c.into_owned()),
    }
}

/// Reads and parses `path`.
pub(crate) fn load(path: &Path) -> Result<LoadedDbc, Diagnostics> {
    let bytes = std::fs::read(path).map_err(|e| {
        Diagnostics(vec![file_error(
            path,
            Code::DbcUnreadable,
            format!("cannot read the file: {e}"),
            "check the path and permissions",
        )])
    })?;
    let text = decode_text(&bytes).ok_or_else(|| {
        Diagnostics(vec![file_error(
            path,
            Code::DbcEncoding,
            "the file is neither UTF-8 nor Windows-1252 text".into(),
            "save the DBC as UTF-8 or as CANdb++ writes it (Windows-1252)",
        )])
    })?;
    parse(path, text)
}

/// Parses DBC text already in memory (used by `load` and by tests).
pub(crate) fn parse(path: &Path, text: String) -> Result<LoadedDbc, Diagnostics> {
    match can_dbc::Dbc::try_from(text.as_str()) {
        Ok(dbc) => {
            let lines = LineIndex::build(&text);
            Ok(LoadedDbc { text, dbc, lines })
        }
        Err(err) => {
            let mut reporter = Reporter::new(path, &text);
            let (line, what) = match &err {
                can_dbc::DbcError::Pest(pest_err) => {
                    let line = match pest_err.line_col {
                        pest::error::LineColLocation::Pos((l, _)) => l,
                        pest::error::LineColLocation::Span((l, _), _) => l,
                    };
                    (line, pest_err.variant.message().into_owned())
                }
                other => (0, other.to_string()),
            };
            reporter.report(
                Code::DbcSyntax,
                line,
                format!("the DBC syntax is invalid: {what}"),
                "compare the line with the DBC grammar (a missing quote, semicolon or `|` is the usual cause)",
            );
            Err(Diagnostics(reporter.diagnostics))
        }
    }
}

fn file_error(path: &Path, code: Code, message: String, help: &str) -> Diagnostic {
    Diagnostic {
        severity: code.severity(),
        code,
        file: path.to_owned(),
        line: 0,
        message,
        help: help.to_owned(),
        source_line: None,
    }
}
