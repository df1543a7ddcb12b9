//! Checks `telemetry.yaml` against the CAN database it references and lays the packet out.

use std::collections::HashMap;
use std::path::Path;

use serde_saphyr::Spanned;

use crate::diagnostic::{Code, Diagnostic, Diagnostics, Reporter};
use crate::load::telemetry::{FieldSpec, LoadedTelemetry, PacketSpec};
use crate::model::{
    DEFAULT_MISSED_FRAMES, Database, Display, Encoding, ISOTP_MAX_LEN, IntType, PhysType,
    Placement, Signal, TELEMETRY_HEADER_LEN, Telemetry, TelemetryField, WireType,
};
use crate::naming::{camel, is_keyword};

/// Names the header uses; fields cannot take them.
const RESERVED: [&str; 4] = ["fingerprint", "sequence", "timestamp_us", "ts"];

fn line_of<T>(s: &Spanned<T>) -> usize {
    usize::try_from(s.referenced.line()).unwrap_or(0)
}

/// Validates the telemetry schema against `db` and lays out the packet.
pub(crate) fn validate(
    path: &Path,
    loaded: &LoadedTelemetry,
    db: &Database,
) -> Result<(Telemetry, Vec<Diagnostic>), Diagnostics> {
    let mut r = Reporter::new(path, &loaded.text);
    let packet = &loaded.file.packet.value;
    check_ids(&mut r, packet, db);
    let mut fields = fields(&mut r, loaded, db);
    let len = lay_out(&mut fields);
    if len > ISOTP_MAX_LEN {
        r.report(
            Code::PacketTooLong,
            line_of(&loaded.file.packet),
            format!("the packet is {len} bytes; ISO-TP carries at most {ISOTP_MAX_LEN}"),
            "remove fields or use narrower wire types (u8/u16 with a scale)",
        );
    }
    if r.has_errors() {
        return Err(Diagnostics(r.diagnostics));
    }
    let bus = check_bus(&mut r, packet, db);
    let timeout_ms = timeout(&mut r, packet);
    let sender = check_sender(&mut r, packet, db);
    if r.has_errors() {
        return Err(Diagnostics(r.diagnostics));
    }
    let telemetry = Telemetry {
        type_name: camel(&packet.name.value),
        description: packet.description.clone(),
        tx_id: packet.tx_id.value as u16,
        flow_control_id: packet.flow_control_id.value as u16,
        period_ms: packet.period_ms,
        timeout_ms,
        bus,
        sender,
        headroom_bytes: packet
            .headroom_bytes
            .as_ref()
            .map_or(0, |h| h.value as usize),
        fields,
        len,
    };
    // The packet's frames come on top of its bus's messages.
    let line = packet
        .bus
        .as_ref()
        .map_or_else(|| line_of(&loaded.file.packet), line_of);
    let loads = crate::bus_load::loads(db, Some(&telemetry));
    let own_bus = telemetry
        .bus
        .as_deref()
        .unwrap_or(crate::bus_load::UNNAMED_BUS);
    if let Some(load) = loads.iter().find(|l| l.bus == own_bus) {
        crate::validate::dbc::report_overload(&mut r, load, line);
        if load.load <= crate::bus_load::WARN_LOAD {
            report_no_headroom(&mut r, loaded, db, &telemetry);
        }
    }
    Ok((telemetry, r.diagnostics))
}

/// W0211 when the packet's planned growth would load its bus above the warning threshold.
fn report_no_headroom(
    r: &mut Reporter<'_>,
    loaded: &LoadedTelemetry,
    db: &Database,
    telemetry: &Telemetry,
) {
    let Some(planned) = crate::bus_load::planned(db, telemetry) else {
        return;
    };
    if planned.load <= crate::bus_load::WARN_LOAD {
        return;
    }
    let line = loaded
        .file
        .packet
        .value
        .headroom_bytes
        .as_ref()
        .map_or_else(|| line_of(&loaded.file.packet), line_of);
    r.report(
        Code::NoHeadroom,
        line,
        format!(
            "bus `{}` keeps no room for the packet's planned {} more bytes: at {} bytes the \
             packet takes {} frames and the bus {:.1} % at worst-case bit stuffing, above the \
             {:.0} % the generator allows without a warning",
            planned.bus,
            telemetry.headroom_bytes,
            telemetry.len + telemetry.headroom_bytes,
            crate::bus_load::isotp_frames(telemetry.len + telemetry.headroom_bytes),
            planned.load * 100.0,
            crate::bus_load::WARN_LOAD * 100.0
        ),
        "make room first (move a message to another bus, relax a cycle time: docs/schema.md, \
         \"The bus budget\"), or lower `headroom_bytes` knowing the next sensors will not fit",
    );
}

/// The packet's bus: one the DBC's messages are sent on.
fn check_bus(r: &mut Reporter<'_>, packet: &PacketSpec, db: &Database) -> Option<String> {
    let bus = packet.bus.as_ref()?;
    let known = db.messages.iter().any(|m| m.buses.contains(&bus.value));
    if !known {
        r.report(
            Code::UnknownBus,
            line_of(bus),
            format!(
                "the packet is sent on bus `{}`, which no DBC message names",
                bus.value
            ),
            "use a bus name of the DBC's AerBus message attribute (the car's: vehicle)",
        );
    }
    Some(bus.value.clone())
}

/// The packet's sender: a node of the DBC.
fn check_sender(r: &mut Reporter<'_>, packet: &PacketSpec, db: &Database) -> Option<String> {
    let sender = packet.sender.as_ref()?;
    if !db.nodes.iter().any(|n| n.name == sender.value) {
        let nodes: Vec<&str> = db.nodes.iter().map(|n| n.name.as_str()).collect();
        r.report(
            Code::UnknownSender,
            line_of(sender),
            format!(
                "the packet's sender `{}` is not a node of the DBC (`BU_: {}`)",
                sender.value,
                nodes.join(" ")
            ),
            "name the node that sends the packet, as the DBC's BU_ line spells it",
        );
    }
    Some(sender.value.clone())
}

/// The freshness limit: the declared `timeout_ms`, else a few periods as for the DBC's
/// messages. One shorter than the period would call every packet late.
fn timeout(r: &mut Reporter<'_>, packet: &PacketSpec) -> u32 {
    let default = packet.period_ms.saturating_mul(DEFAULT_MISSED_FRAMES);
    let Some(declared) = &packet.timeout_ms else {
        return default;
    };
    if declared.value < packet.period_ms.max(1) {
        r.report(
            Code::PacketTimeout,
            line_of(declared),
            format!(
                "`timeout_ms` {} is shorter than the packet's period ({} ms)",
                declared.value, packet.period_ms
            ),
            "allow at least one period, better a few (receivers count the data stale after it)",
        );
    }
    declared.value
}

/// The ISO-TP ids: standard, distinct, and not used by a DBC message.
fn check_ids(r: &mut Reporter<'_>, packet: &PacketSpec, db: &Database) {
    for (what, id) in [
        ("tx_id", &packet.tx_id),
        ("flow_control_id", &packet.flow_control_id),
    ] {
        if id.value > 0x7FF {
            r.report(
                Code::IsoTpIds,
                line_of(id),
                format!("`{what}` 0x{:X} is not an 11-bit CAN id", id.value),
                "ISO-TP normal addressing on the car uses standard ids up to 0x7FF",
            );
        }
    }
    if packet.tx_id.value == packet.flow_control_id.value {
        r.report(
            Code::IsoTpIds,
            line_of(&packet.flow_control_id),
            "`flow_control_id` equals `tx_id`".to_owned(),
            "the receiver's flow control needs its own id (0x777 on the car)",
        );
    }
    if db
        .messages
        .iter()
        .any(|m| !m.extended && [packet.tx_id.value, packet.flow_control_id.value].contains(&m.id))
    {
        r.report(
            Code::IsoTpIds,
            line_of(&packet.tx_id),
            "an ISO-TP id is also the id of a DBC message".to_owned(),
            "pick ids no message in aer.dbc uses",
        );
    }
}

/// Every usable field, in schema order (not yet placed); the others are reported.
fn fields(r: &mut Reporter<'_>, loaded: &LoadedTelemetry, db: &Database) -> Vec<TelemetryField> {
    let mut fields = Vec::new();
    let mut names: HashMap<String, usize> = HashMap::new();
    for spec in &loaded.file.fields {
        let name = &spec.value.name.value;
        let name_line = line_of(&spec.value.name);
        let valid = name.starts_with(|c: char| c.is_ascii_lowercase())
            && name
                .chars()
                .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_');
        if !valid || is_keyword(name) || RESERVED.contains(&name.as_str()) {
            r.report(
                Code::FieldName,
                name_line,
                format!("field name `{name}` is not usable"),
                "use snake_case (a-z, 0-9, _), not a Rust keyword and not fingerprint/sequence/timestamp_us/ts",
            );
            continue;
        }
        if let Some(first) = names.insert(name.clone(), name_line) {
            r.report(
                Code::FieldName,
                name_line,
                format!("field `{name}` is defined twice (first on line {first})"),
                "every field needs its own name",
            );
            continue;
        }
        if let Some(field) = field(r, db, &spec.value, line_of(spec)) {
            fields.push(field);
        }
    }
    fields
}

/// Places byte-aligned values first, in schema order, then the flags packed LSB first;
/// returns the packet's length.
fn lay_out(fields: &mut [TelemetryField]) -> usize {
    let mut offset = TELEMETRY_HEADER_LEN;
    for f in fields.iter_mut().filter(|f| f.wire != WireType::Flag) {
        f.placement = Placement::Bytes(offset);
        offset += f.wire.bytes();
    }
    let mut flag = 0usize;
    for f in fields.iter_mut().filter(|f| f.wire == WireType::Flag) {
        f.placement = Placement::Bit(offset + flag / 8, (flag % 8) as u8);
        flag += 1;
    }
    offset + flag.div_ceil(8)
}

/// One field: its kind (a DBC signal, a wire type or an enum), scaling and range.
fn field(
    r: &mut Reporter<'_>,
    db: &Database,
    spec: &FieldSpec,
    line: usize,
) -> Option<TelemetryField> {
    let name = spec.name.value.clone();
    let display = display(r, spec, line)?;
    let mut field = TelemetryField {
        name: name.clone(),
        group: spec.group.clone().unwrap_or_else(|| "other".to_owned()),
        description: spec.description.clone().unwrap_or_default(),
        unit: spec.unit.clone().unwrap_or_default(),
        wire: WireType::U8,
        scale: spec.scale.as_ref().map_or(1.0, |s| s.value),
        offset: spec.offset.unwrap_or(0.0),
        min: spec.min,
        max: spec.max,
        phys: PhysType::F64,
        placement: Placement::Bytes(0),
        display,
        source: None,
    };
    match (&spec.signal, &spec.wire, &spec.enum_name) {
        (Some(reference), None, None) => {
            if spec.scale.is_some()
                || spec.offset.is_some()
                || spec.unit.is_some()
                || spec.min.is_some()
                || spec.max.is_some()
            {
                r.report(
                    Code::FieldKind,
                    line,
                    format!("field `{name}` references a signal and also sets scale/offset/unit/min/max"),
                    "a referenced signal's scaling comes from aer.dbc; remove them here (or drop `signal:`)",
                );
                return None;
            }
            let sig = find_signal(r, db, reference)?;
            inherit(r, db, &mut field, sig, line_of(reference))?;
            field.source = Some(reference.value.clone());
        }
        (None, Some(wire), None) => {
            field.wire = wire_type(r, &name, wire)?;
        }
        (None, None, Some(enum_name)) => {
            let index = find_enum(r, db, &name, enum_name)?;
            field.wire = enum_wire(db, index)?;
            field.phys = PhysType::Enum(index);
        }
        _ => {
            r.report(
                Code::FieldKind,
                line,
                format!("field `{name}` needs exactly one of `signal`, `type` or `enum`"),
                "reference a DBC signal (signal: MESSAGE.SIGNAL), or give a wire type, or an enum",
            );
            return None;
        }
    }
    check_scaling(r, &field, spec.scale.as_ref().map_or(line, line_of))?;
    if spec.wire.is_some() {
        // Only once the scaling is known to be usable: the type follows from it.
        field.phys = own_phys(&field);
    }
    check_range(r, &field, line)?;
    check_described(r, &field, line);
    Some(field)
}

/// People read every field by its label and unit (pit view, exports, bus documentation), so
/// each is asked for; the car's schema denies warnings, so there they are required.
fn check_described(r: &mut Reporter<'_>, field: &TelemetryField, line: usize) {
    let name = &field.name;
    if field
        .display
        .label
        .as_deref()
        .is_none_or(|l| l.trim().is_empty())
    {
        r.report(
            Code::MissingLabel,
            line,
            format!("field `{name}` has no label"),
            "add `label:` with the name people should read, such as `label: Front brake pressure`",
        );
    }
    let numeric =
        !matches!(field.phys, PhysType::Bool | PhysType::Enum(_)) && field.wire != WireType::Flag;
    if numeric && field.unit.trim().is_empty() {
        r.report(
            Code::MissingUnit,
            line,
            format!("field `{name}` has no unit"),
            match field.source {
                Some(_) => "give the referenced signal a unit in aer.dbc",
                None => "add `unit:` (for a count, what is counted, such as `unit: frames`)",
            },
        );
    }
}

/// The dashboard hints, with thresholds in a sensible order.
fn display(r: &mut Reporter<'_>, spec: &FieldSpec, line: usize) -> Option<Display> {
    let thresholds = spec.display.as_ref();
    let display = Display {
        label: spec.label.clone(),
        warn: thresholds.and_then(|d| d.warn),
        critical: thresholds.and_then(|d| d.critical),
        warn_below: thresholds.and_then(|d| d.warn_below),
        critical_below: thresholds.and_then(|d| d.critical_below),
    };
    if let Some(problem) = threshold_problem(&display) {
        r.report(
            Code::Thresholds,
            line,
            format!(
                "field `{}` has display thresholds that {problem}",
                spec.name.value
            ),
            "a warning comes before critical: warn <= critical above, warn_below >= critical_below below",
        );
        return None;
    }
    Some(display)
}

fn wire_type(r: &mut Reporter<'_>, name: &str, wire: &Spanned<String>) -> Option<WireType> {
    Some(match wire.value.as_str() {
        "u8" => WireType::U8,
        "u16" => WireType::U16,
        "u32" => WireType::U32,
        "i8" => WireType::I8,
        "i16" => WireType::I16,
        "i32" => WireType::I32,
        "f32" => WireType::F32,
        "flag" => WireType::Flag,
        other => {
            r.report(
                Code::UnknownWireType,
                line_of(wire),
                format!("field `{name}` has unknown type `{other}`"),
                "use one of u8, u16, u32, i8, i16, i32, f32, flag",
            );
            return None;
        }
    })
}

/// The index of the DBC enum a field names.
fn find_enum(
    r: &mut Reporter<'_>,
    db: &Database,
    name: &str,
    enum_name: &Spanned<String>,
) -> Option<usize> {
    let wanted = camel(&enum_name.value);
    let index = db.enums.iter().position(|e| e.type_name == wanted);
    if index.is_none() {
        let known: Vec<&str> = db.enums.iter().map(|e| e.type_name.as_str()).collect();
        r.report(
            Code::UnknownEnum,
            line_of(enum_name),
            format!(
                "field `{name}` uses enum `{}`, which aer.dbc does not define",
                enum_name.value
            ),
            format!(
                "define a VAL_TABLE_ in aer.dbc or use one of: {}",
                known.join(", ")
            ),
        );
    }
    index
}

/// A usable scale: non-zero and finite, and none at all for an f32 of the field's own.
fn check_scaling(r: &mut Reporter<'_>, field: &TelemetryField, scale_line: usize) -> Option<()> {
    let name = &field.name;
    if field.scale == 0.0 || !field.scale.is_finite() || !field.offset.is_finite() {
        r.report(
            Code::BadScale,
            scale_line,
            format!("field `{name}` has scale {}", field.scale),
            "the scale must be a non-zero finite number",
        );
        return None;
    }
    if field.wire != WireType::F32 {
        if let Some(problem) = resolution_problem(field) {
            r.report(
                Code::BadScale,
                scale_line,
                format!(
                    "field `{name}` has scale {} and offset {}: {problem}",
                    field.scale, field.offset
                ),
                "use a scale and offset that keep physical values within f64 and apart",
            );
            return None;
        }
    }
    if field.wire == WireType::F32
        && (field.scale != 1.0 || field.offset != 0.0)
        && field.source.is_none()
    {
        r.report(
            Code::BadScale,
            scale_line,
            format!("field `{name}` is f32 on the wire and also scaled"),
            "an f32 carries the physical value itself: drop scale/offset, or use an integer type with a scale",
        );
        return None;
    }
    Some(())
}

/// Why an integer field's physical values are unusable: beyond f64, or so far from zero that
/// neighbouring raw values give the same f64 (so encoding could not find the raw value).
fn resolution_problem(field: &TelemetryField) -> Option<&'static str> {
    let (lo, hi) = field.wire.range();
    let (a, b) = physical_extremes(lo, hi, field.scale, field.offset);
    if !a.is_finite() || !b.is_finite() {
        return Some("its physical values overflow f64");
    }
    // One raw step must stay above f64's resolution at the largest magnitude.
    if field.scale.abs() <= a.abs().max(b.abs()) * f64::EPSILON * 2.0 {
        return Some("f64 cannot tell neighbouring raw values apart");
    }
    None
}

/// The physical values of raw `lo` and `hi`, in f64.
fn physical_extremes(lo: i128, hi: i128, scale: f64, offset: f64) -> (f64, f64) {
    (lo as f64 * scale + offset, hi as f64 * scale + offset)
}

/// `min`/`max` within what the wire type holds at the field's scale.
fn check_range(r: &mut Reporter<'_>, field: &TelemetryField, line: usize) -> Option<()> {
    let (Some(lo), Some(hi)) = (field.min, field.max) else {
        return Some(());
    };
    let (raw_lo, raw_hi) = field.wire.range();
    let (a, b) = physical_extremes(raw_lo, raw_hi, field.scale, field.offset);
    let tol = field.scale.abs() / 2.0;
    if field.wire != WireType::F32 && (lo < a.min(b) - tol || hi > a.max(b) + tol || lo > hi) {
        r.report(
            Code::FieldRange,
            line,
            format!(
                "field `{}` has range [{lo}, {hi}] but a {} with scale {} holds [{}, {}]",
                field.name,
                field.wire.rust(),
                field.scale,
                a.min(b),
                a.max(b)
            ),
            "use a wider type or a larger scale, or narrow min/max",
        );
        return None;
    }
    Some(())
}

/// What is wrong with a field's thresholds, if anything.
fn threshold_problem(display: &Display) -> Option<String> {
    let all = [
        display.warn,
        display.critical,
        display.warn_below,
        display.critical_below,
    ];
    if all.iter().flatten().any(|v| !v.is_finite()) {
        return Some("are not finite numbers".to_owned());
    }
    if let (Some(warn), Some(critical)) = (display.warn, display.critical)
        && warn > critical
    {
        return Some(format!("warn above critical ({warn} > {critical})"));
    }
    if let (Some(warn), Some(critical)) = (display.warn_below, display.critical_below)
        && warn < critical
    {
        return Some(format!(
            "warn below critical (warn_below {warn} < critical_below {critical})"
        ));
    }
    None
}

fn find_signal<'d>(
    r: &mut Reporter<'_>,
    db: &'d Database,
    reference: &Spanned<String>,
) -> Option<&'d Signal> {
    let line = line_of(reference);
    let Some((msg_name, sig_name)) = reference.value.split_once('.') else {
        r.report(
            Code::UnknownSignal,
            line,
            format!("`{}` does not name a DBC signal", reference.value),
            "write MESSAGE.SIGNAL, as in MCU1.MCU_MotorSpeed",
        );
        return None;
    };
    let Some(msg) = db.messages.iter().find(|m| m.name == msg_name) else {
        r.report(
            Code::UnknownSignal,
            line,
            format!("aer.dbc has no message `{msg_name}`"),
            "check the message name in schema/aer.dbc (names are case-sensitive)",
        );
        return None;
    };
    match msg.signals.iter().find(|s| s.name == sig_name) {
        Some(s) => Some(s),
        None => {
            let known: Vec<&str> = msg.signals.iter().map(|s| s.name.as_str()).collect();
            r.report(
                Code::UnknownSignal,
                line,
                format!("message `{msg_name}` has no signal `{sig_name}`"),
                format!("its signals are: {}", known.join(", ")),
            );
            None
        }
    }
}

/// Copies wire type, scaling, unit, range, enum and comment from a DBC signal.
fn inherit(
    r: &mut Reporter<'_>,
    db: &Database,
    f: &mut TelemetryField,
    s: &Signal,
    line: usize,
) -> Option<()> {
    let signed = s.encoding == Encoding::Signed;
    f.wire =
        match (s.encoding, s.len) {
            (Encoding::Float32, _) => WireType::F32,
            (Encoding::Float64, _) | (_, 33..) => {
                r.report(
                Code::SignalTooWide,
                line,
                format!("signal `{}` ({} bits) is too wide for a telemetry field", s.name, s.len),
                "declare the field with its own type and scale instead of referencing the signal",
            );
                return None;
            }
            (_, 1) if !signed && s.phys == PhysType::Bool => WireType::Flag,
            (_, 0..=8) => {
                if signed {
                    WireType::I8
                } else {
                    WireType::U8
                }
            }
            (_, 9..=16) => {
                if signed {
                    WireType::I16
                } else {
                    WireType::U16
                }
            }
            _ => {
                if signed {
                    WireType::I32
                } else {
                    WireType::U32
                }
            }
        };
    if let PhysType::Enum(index) = s.phys {
        f.wire = enum_wire(db, index)?;
    }
    f.scale = s.factor;
    f.offset = s.offset;
    f.unit = s.unit.clone();
    f.min = s.min;
    f.max = s.max;
    if f.description.is_empty() {
        f.description = s.comment.clone().unwrap_or_default();
    }
    f.phys = match s.phys {
        PhysType::Enum(_) | PhysType::Bool | PhysType::Int(_) => s.phys,
        _ => own_phys(f),
    };
    Some(())
}

fn enum_wire(db: &Database, index: usize) -> Option<WireType> {
    Some(match db.enums.get(index)?.repr {
        IntType::U8 => WireType::U8,
        IntType::I8 => WireType::I8,
        IntType::U16 => WireType::U16,
        IntType::I16 => WireType::I16,
        IntType::I32 => WireType::I32,
        _ => WireType::U32,
    })
}

/// Physical type of a field with its own wire type: exact integers where the scaling allows
/// (and they fit 128 bits), `f32` where it holds every raw value exactly enough (24-bit
/// mantissa) and within its range, `f64` otherwise.
fn own_phys(f: &TelemetryField) -> PhysType {
    let (lo, hi) = f.wire.range();
    match f.wire {
        WireType::Flag => PhysType::Bool,
        WireType::F32 => PhysType::F32,
        _ if f.scale.fract() == 0.0 && f.offset.fract() == 0.0 => {
            match (exact_physical(lo, f), exact_physical(hi, f)) {
                (Some(a), Some(b)) => PhysType::Int(IntType::smallest_for(a.min(b), a.max(b))),
                _ => PhysType::F64,
            }
        }
        w if w.bits() <= 24 => {
            let (a, b) = physical_extremes(lo, hi, f.scale, f.offset);
            if a.abs().max(b.abs()) <= f64::from(f32::MAX) {
                PhysType::F32
            } else {
                PhysType::F64
            }
        }
        _ => PhysType::F64,
    }
}

/// `raw * scale + offset` in integers, for whole scale and offset; `None` beyond 128 bits.
fn exact_physical(raw: i128, f: &TelemetryField) -> Option<i128> {
    let whole = |v: f64| (v.abs() < 1.7e38).then_some(v as i128);
    raw.checked_mul(whole(f.scale)?)?
        .checked_add(whole(f.offset)?)
}
