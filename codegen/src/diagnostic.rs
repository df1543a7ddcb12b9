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

/// What kind of problem a finding is. Each has a stable, greppable code (`E0103`) so tests and
/// people can refer to it; `E` codes are errors, `W` codes warnings.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Code {
    /// E0001: the DBC file cannot be read.
    DbcUnreadable,
    /// E0002: the DBC is neither UTF-8 nor Windows-1252.
    DbcEncoding,
    /// E0003: the DBC does not parse.
    DbcSyntax,
    /// E0101: a message id beyond the 11- or 29-bit limit.
    IdOutOfRange,
    /// E0102: two messages with one id.
    DuplicateId,
    /// E0103: two messages with one name.
    DuplicateMessageName,
    /// E0104: a payload length no CAN or CAN FD frame has.
    FrameLength,
    /// E0105: a signal shorter than 1 or longer than 64 bits.
    SignalLength,
    /// E0106: a signal with bits outside its frame.
    SignalOutsideFrame,
    /// E0107: signals that share bits (and can be present together).
    SignalOverlap,
    /// E0108: two signals with one name in a message.
    DuplicateSignal,
    /// E0112: an IEEE float signal of the wrong length.
    FloatLength,
    /// E0113: a zero or non-finite factor.
    BadFactor,
    /// E0114: multiplexing that cannot be resolved.
    Multiplexing,
    /// E0115: a minimum above the maximum.
    RangeInverted,
    /// E0116: multiplexor values the multiplexor cannot take.
    MuxValueOutOfRange,
    /// E0118: an f32 physical value for a raw value f32 cannot hold.
    F32TooNarrow,
    /// E0119: an extended id without the node id its node declares (`NodeIdInCanId`).
    NodeIdNotInId,
    /// E0120: a rolling counter (`CounterStep`) the codec cannot keep: not a small unsigned
    /// integer, a step it cannot hold, multiplexed, or a second one in the message.
    CounterInvalid,
    /// E0121: a checksum (`ChecksumAlgorithm`) the codec cannot compute: an unknown algorithm,
    /// not one whole byte, multiplexed, or a second one in the message.
    ChecksumInvalid,
    /// E0201: the telemetry schema cannot be read.
    TelemetryUnreadable,
    /// E0202: the telemetry schema does not parse.
    TelemetrySyntax,
    /// E0203: a field references a signal that does not exist.
    UnknownSignal,
    /// E0204: an unknown wire type.
    UnknownWireType,
    /// E0205: a field that is not exactly one of signal, type or enum.
    FieldKind,
    /// E0206: an unusable or duplicate field name.
    FieldName,
    /// E0207: a field uses an enum the DBC does not define.
    UnknownEnum,
    /// E0209: a packet longer than ISO-TP carries.
    PacketTooLong,
    /// E0210: a referenced signal too wide for a telemetry field.
    SignalTooWide,
    /// E0211: an unusable scale.
    BadScale,
    /// E0212: unusable ISO-TP ids.
    IsoTpIds,
    /// E0213: a range the wire type cannot hold.
    FieldRange,
    /// E0214: display thresholds in the wrong order.
    Thresholds,
    /// E0215: a packet sent on a bus no DBC message names.
    UnknownBus,
    /// E0216: a packet timeout shorter than its period (every packet would be late).
    PacketTimeout,
    /// E0217: a packet sender that is not a node of the DBC.
    UnknownSender,
    /// E0301: the calibration schema cannot be read.
    CalibrationUnreadable,
    /// E0302: the calibration schema does not parse.
    CalibrationSyntax,
    /// E0303: an unusable or duplicate parameter name.
    ParameterName,
    /// E0304: a parameter type the calibration cannot hold.
    ParameterType,
    /// E0305: a default whose shape does not match its elements or axis, or an unusable axis.
    ParameterShape,
    /// E0306: limits the parameter's type cannot hold, or in the wrong order.
    ParameterLimits,
    /// E0307: a default outside its limits, or not increasing where it must.
    ParameterDefault,
    /// E0308: an unknown change condition.
    ChangeCondition,
    /// E0309: a parameter without the label, unit or description a calibration tool shows.
    ParameterText,
    /// E0310: an unusable or duplicate internal's name, or no internals at all.
    InternalName,
    /// E0311: an internal's limits that are not finite f32 values in increasing order.
    InternalLimits,
    /// E0312: an internal without the unit or description a calibration tool shows.
    InternalText,
    /// E0313: XCP messages the slave cannot use: missing from the DBC or from the bus, not 8
    /// bytes, extended, one message for both directions, a response without a cycle time (its
    /// frame budget) or a DBC without a bit rate.
    XcpMessage,
    /// E0314: an XCP setting the slave cannot keep (port, DAQ lists, ODT entries, entry size).
    XcpSetting,
    /// E0315: unusable XCP events: none, a name that is not snake_case, a keyword or declared
    /// twice, a period an A2L event cannot state, or no description.
    XcpEvent,
    /// W0201: a name that is a Rust keyword.
    KeywordName,
    /// W0202: a range the raw value cannot reach.
    RangeBeyondRaw,
    /// W0203: value descriptions the signal cannot hold.
    UnusableValues,
    /// W0204: a name renamed to avoid a clash.
    Renamed,
    /// W0205: a CAN FD length that is not a frame length.
    FdLength,
    /// W0206: a file with no messages (empty, or cut short at a line boundary).
    NoMessages,
    /// W0207: a telemetry field without a human label.
    MissingLabel,
    /// W0208: a numeric telemetry field without a unit.
    MissingUnit,
    /// W0209: a cycle time on a message sent on demand (`GenMsgSendType` `NoMsgSendType`).
    CycleTimeOnEvent,
    /// W0210: a bus loaded above the warning threshold at worst-case stuffing.
    BusOverloaded,
    /// W0211: the telemetry's bus would be loaded above the warning threshold once the packet
    /// grows by its planned headroom.
    NoHeadroom,
}

/// Every code, for [`Code::parse`].
const ALL: [Code; 62] = [
    Code::DbcUnreadable,
    Code::DbcEncoding,
    Code::DbcSyntax,
    Code::IdOutOfRange,
    Code::DuplicateId,
    Code::DuplicateMessageName,
    Code::FrameLength,
    Code::SignalLength,
    Code::SignalOutsideFrame,
    Code::SignalOverlap,
    Code::DuplicateSignal,
    Code::FloatLength,
    Code::BadFactor,
    Code::Multiplexing,
    Code::RangeInverted,
    Code::MuxValueOutOfRange,
    Code::F32TooNarrow,
    Code::NodeIdNotInId,
    Code::CounterInvalid,
    Code::ChecksumInvalid,
    Code::TelemetryUnreadable,
    Code::TelemetrySyntax,
    Code::UnknownSignal,
    Code::UnknownWireType,
    Code::FieldKind,
    Code::FieldName,
    Code::UnknownEnum,
    Code::PacketTooLong,
    Code::SignalTooWide,
    Code::BadScale,
    Code::IsoTpIds,
    Code::FieldRange,
    Code::Thresholds,
    Code::UnknownBus,
    Code::PacketTimeout,
    Code::UnknownSender,
    Code::CalibrationUnreadable,
    Code::CalibrationSyntax,
    Code::ParameterName,
    Code::ParameterType,
    Code::ParameterShape,
    Code::ParameterLimits,
    Code::ParameterDefault,
    Code::ChangeCondition,
    Code::ParameterText,
    Code::InternalName,
    Code::InternalLimits,
    Code::InternalText,
    Code::XcpMessage,
    Code::XcpSetting,
    Code::XcpEvent,
    Code::KeywordName,
    Code::RangeBeyondRaw,
    Code::UnusableValues,
    Code::Renamed,
    Code::FdLength,
    Code::NoMessages,
    Code::MissingLabel,
    Code::MissingUnit,
    Code::CycleTimeOnEvent,
    Code::BusOverloaded,
    Code::NoHeadroom,
];

impl Code {
    /// The stable code, such as `E0103`.
    pub fn as_str(self) -> &'static str {
        match self {
            Code::DbcUnreadable => "E0001",
            Code::DbcEncoding => "E0002",
            Code::DbcSyntax => "E0003",
            Code::IdOutOfRange => "E0101",
            Code::DuplicateId => "E0102",
            Code::DuplicateMessageName => "E0103",
            Code::FrameLength => "E0104",
            Code::SignalLength => "E0105",
            Code::SignalOutsideFrame => "E0106",
            Code::SignalOverlap => "E0107",
            Code::DuplicateSignal => "E0108",
            Code::FloatLength => "E0112",
            Code::BadFactor => "E0113",
            Code::Multiplexing => "E0114",
            Code::RangeInverted => "E0115",
            Code::MuxValueOutOfRange => "E0116",
            Code::F32TooNarrow => "E0118",
            Code::NodeIdNotInId => "E0119",
            Code::CounterInvalid => "E0120",
            Code::ChecksumInvalid => "E0121",
            Code::TelemetryUnreadable => "E0201",
            Code::TelemetrySyntax => "E0202",
            Code::UnknownSignal => "E0203",
            Code::UnknownWireType => "E0204",
            Code::FieldKind => "E0205",
            Code::FieldName => "E0206",
            Code::UnknownEnum => "E0207",
            Code::PacketTooLong => "E0209",
            Code::SignalTooWide => "E0210",
            Code::BadScale => "E0211",
            Code::IsoTpIds => "E0212",
            Code::FieldRange => "E0213",
            Code::Thresholds => "E0214",
            Code::UnknownBus => "E0215",
            Code::PacketTimeout => "E0216",
            Code::UnknownSender => "E0217",
            Code::CalibrationUnreadable => "E0301",
            Code::CalibrationSyntax => "E0302",
            Code::ParameterName => "E0303",
            Code::ParameterType => "E0304",
            Code::ParameterShape => "E0305",
            Code::ParameterLimits => "E0306",
            Code::ParameterDefault => "E0307",
            Code::ChangeCondition => "E0308",
            Code::ParameterText => "E0309",
            Code::InternalName => "E0310",
            Code::InternalLimits => "E0311",
            Code::InternalText => "E0312",
            Code::XcpMessage => "E0313",
            Code::XcpSetting => "E0314",
            Code::XcpEvent => "E0315",
            Code::KeywordName => "W0201",
            Code::RangeBeyondRaw => "W0202",
            Code::UnusableValues => "W0203",
            Code::Renamed => "W0204",
            Code::FdLength => "W0205",
            Code::NoMessages => "W0206",
            Code::MissingLabel => "W0207",
            Code::MissingUnit => "W0208",
            Code::CycleTimeOnEvent => "W0209",
            Code::BusOverloaded => "W0210",
            Code::NoHeadroom => "W0211",
        }
    }

    /// Errors stop generation; warnings do not.
    /// The code for `text` (`E0107`), if there is one.
    pub fn parse(text: &str) -> Option<Code> {
        ALL.iter().copied().find(|code| code.as_str() == text)
    }

    /// What the generator does with a finding of this code that `--allow` lets through, for
    /// the errors it can handle safely in a vendor's file the team cannot fix (`None`: it
    /// cannot be allowed).
    pub fn when_allowed(self) -> Option<&'static str> {
        match self {
            Code::SignalOverlap => Some(
                "allowed: each signal is decoded from its bits as written; encoding writes the \
                 signals in order, so the later one's bits win",
            ),
            Code::IdOutOfRange => Some(
                "allowed: a standard id above 0x7FF is taken as a 29-bit extended id (as \
                 SocketCAN tools do); an id above 29 bits leaves its message out",
            ),
            _ => None,
        }
    }

    pub fn severity(self) -> Severity {
        if self.as_str().starts_with('W') {
            Severity::Warning
        } else {
            Severity::Error
        }
    }
}

impl fmt::Display for Code {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Lets tests and tools compare with the printed code: `d.code == "E0103"`.
impl PartialEq<&str> for Code {
    fn eq(&self, other: &&str) -> bool {
        self.as_str() == *other
    }
}

/// One finding about a schema file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Diagnostic {
    pub severity: Severity,
    pub code: Code,
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
pub(crate) struct Reporter<'a> {
    file: &'a Path,
    lines: Vec<&'a str>,
    /// Error codes let through as warnings (`--allow`; only codes with [`Code::when_allowed`]).
    allowed: Vec<Code>,
    pub diagnostics: Vec<Diagnostic>,
}

impl<'a> Reporter<'a> {
    pub(crate) fn new(file: &'a Path, text: &'a str) -> Self {
        Self {
            file,
            lines: text.lines().collect(),
            allowed: Vec::new(),
            diagnostics: Vec::new(),
        }
    }

    /// Lets `allowed` through as warnings, each saying how it is handled; codes that cannot
    /// be handled safely stay errors.
    pub(crate) fn allowing(mut self, allowed: &[Code]) -> Self {
        self.allowed = allowed
            .iter()
            .copied()
            .filter(|code| code.when_allowed().is_some())
            .collect();
        self
    }

    /// True when findings of `code` are let through.
    pub(crate) fn allows(&self, code: Code) -> bool {
        self.allowed.contains(&code)
    }

    /// Records a finding at `line` (1-based; 0 for the whole file); its code says how severe.
    pub(crate) fn report(
        &mut self,
        code: Code,
        line: usize,
        message: String,
        help: impl Into<String>,
    ) {
        let source_line = line
            .checked_sub(1)
            .and_then(|i| self.lines.get(i))
            .map(|s| (*s).to_owned());
        let (severity, help) = match code.when_allowed().filter(|_| self.allows(code)) {
            Some(handled) => (Severity::Warning, handled.to_owned()),
            None => (code.severity(), help.into()),
        };
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

    pub(crate) fn has_errors(&self) -> bool {
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

#[cfg(test)]
mod tests {
    use super::{ALL, Code};

    #[test]
    fn every_code_parses_back_and_only_safe_ones_can_be_allowed() {
        for code in ALL {
            assert_eq!(Code::parse(code.as_str()), Some(code));
        }
        let allowable: Vec<&str> = ALL
            .iter()
            .filter(|c| c.when_allowed().is_some())
            .map(|c| c.as_str())
            .collect();
        assert_eq!(allowable, ["E0101", "E0107"]);
        assert_eq!(Code::parse("E9999"), None);
    }
}
