//! Compiler-style diagnostics: every problem in a schema is reported with the file, the line, what
//! is wrong and how to fix it, so a student editing `aer.dbc` at the track can act on it at once.

use std::fmt;
use std::path::{Path, PathBuf};

/// How bad a finding is. Errors stop generation; warnings are printed and generation goes on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Severity {
    Warning,
    Error,
}

/// One finding about a schema file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Diagnostic {
    pub severity: Severity,
    /// Stable, greppable code such as `E0103`, so tests and people can refer to a kind of error.
    pub code: &'static str,
    pub file: PathBuf,
    /// 1-based line; 0 when the finding concerns the file as a whole.
    pub line: usize,
    pub message: String,
    pub help: String,
    /// The offending source line, shown under the location.
    pub source_line: Option<String>,
}

impl Diagnostic {
    pub fn is_error(&self) -> bool {
        self.severity == Severity::Error
    }
}

impl fmt::Display for Diagnostic {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let kind = match self.severity {
            Severity::Error => "error",
            Severity::Warning => "warning",
        };
        writeln!(f, "{kind}[{}]: {}", self.code, self.message)?;
        writeln!(f, "  --> {}:{}", self.file.display(), self.line)?;
        if let Some(src) = &self.source_line {
            let gutter = self.line.to_string();
            let pad = " ".repeat(gutter.len());
            writeln!(f, " {pad} |")?;
            writeln!(f, " {gutter} | {}", src.trim_end())?;
            writeln!(f, " {pad} |")?;
        }
        write!(f, "  = help: {}", self.help)
    }
}

/// Collects diagnostics for one file, attaching its path and source lines.
pub struct Reporter<'a> {
    file: &'a Path,
    lines: Vec<&'a str>,
    pub diagnostics: Vec<Diagnostic>,
}

impl<'a> Reporter<'a> {
    pub fn new(file: &'a Path, text: &'a str) -> Self {
        Self {
            file,
            lines: text.lines().collect(),
            diagnostics: Vec::new(),
        }
    }

    pub fn error(
        &mut self,
        code: &'static str,
        line: usize,
        message: String,
        help: impl Into<String>,
    ) {
        self.push(Severity::Error, code, line, message, help.into());
    }

    pub fn warning(
        &mut self,
        code: &'static str,
        line: usize,
        message: String,
        help: impl Into<String>,
    ) {
        self.push(Severity::Warning, code, line, message, help.into());
    }

    fn push(
        &mut self,
        severity: Severity,
        code: &'static str,
        line: usize,
        message: String,
        help: String,
    ) {
        let source_line = line
            .checked_sub(1)
            .and_then(|i| self.lines.get(i))
            .map(|s| (*s).to_owned());
        self.diagnostics.push(Diagnostic {
            severity,
            code,
            file: self.file.to_owned(),
            line,
            message,
            help,
            source_line,
        });
    }

    pub fn has_errors(&self) -> bool {
        self.diagnostics.iter().any(Diagnostic::is_error)
    }
}

/// The outcome of a failed load or validation: every diagnostic found, errors and warnings.
#[derive(Debug, Clone, thiserror::Error)]
#[error("{}", render_all(.0))]
pub struct Diagnostics(pub Vec<Diagnostic>);

/// Renders diagnostics the way the CLI and build.rs print them, with a summary line.
pub fn render_all(diags: &[Diagnostic]) -> String {
    let mut out = String::new();
    for d in diags {
        out.push_str(&d.to_string());
        out.push_str("\n\n");
    }
    let errors = diags.iter().filter(|d| d.is_error()).count();
    let warnings = diags.len() - errors;
    out.push_str(&format!("{errors} error(s), {warnings} warning(s)"));
    out
}
