//! Renders the calibration tools' description of the CCM (`aer.a2l`, ASAM MCD-2 MC 1.71): the
//! calibration page as CHARACTERISTICs, the telemetry packet and the controllers' internals as
//! MEASUREMENTs, and the XCP slave's settings (IF_DATA XCP, with the standard XCP 1.0 A2ML
//! written out so any tool parses them).
//!
//! The address map and the values the slave promises here (MAX_CTO, MAX_BS, checksum,
//! timestamps) are this module's constants; `calibration.rs` renders the same ones into
//! `aer::calibration::xcp`, so the firmware answers what the file says.

use std::collections::HashSet;

use aer_xcp::protocol::{cmd, err};
use aer_xcp::status::{FIELDS, Kind, Names};
use aer_xcp::{Detail, reason};
use askama::Template;

use crate::model::{
    Calibration, Database, ElementType, INTERNAL_SIZE, Parameter, PhysType, Placement, Telemetry,
    TelemetryField, WireType,
};

/// Where the calibration page lies (XCP page 0 working, page 1 reference).
pub(crate) const CALIBRATION_ADDRESS: u32 = 0x0001_0000;
/// Where the packed telemetry packet lies, exactly as sent.
pub(crate) const TELEMETRY_ADDRESS: u32 = 0x0002_0000;
/// Where the internals' block lies.
pub(crate) const INTERNALS_ADDRESS: u32 = 0x0003_0000;
/// Where the EPK's ASCII bytes lie.
pub(crate) const EPK_ADDRESS: u32 = 0x0004_0000;
/// Where the XCP slave's own numbers lie: its last refusal and its counters
/// (`aer_xcp::status`).
pub(crate) const XCP_STATUS_ADDRESS: u32 = 0x0005_0000;

/// Bytes of the XCP slave's block (`aer_xcp::status`).
pub(crate) const XCP_STATUS_LEN: u32 = aer_xcp::status::STATUS_LEN as u32;

/// Bytes of a command/response packet (CTO) and of a DAQ packet (DTO): one classic CAN frame.
pub(crate) const MAX_CTO: u8 = 8;
/// See [`MAX_CTO`].
pub(crate) const MAX_DTO: u16 = 8;
/// Master block mode: command packets in one DOWNLOAD/DOWNLOAD_NEXT sequence. 32 frames of 6
/// bytes (192) hold a whole page, so a tool writes the page in one block.
pub(crate) const MAX_BS: u8 = 32;
/// The separation the slave needs between a block's frames, in 100 us: none (its receive
/// queue takes a burst at bus speed).
pub(crate) const MIN_ST: u8 = 0;
/// BUILD_CHECKSUM's type: XCP_CRC_16_CITT (CRC-16 CCITT, initial value 0xFFFF), code 0x08.
pub(crate) const CHECKSUM_TYPE: (&str, u8) = ("XCP_CRC_16_CITT", 0x08);
/// The largest block BUILD_CHECKSUM takes, in bytes: bounds one command's time.
pub(crate) const MAX_CHECKSUM_BLOCK: u32 = 0xFFFF;
/// The A2L file's name without extension (GET_ID type 1).
pub(crate) const A2L_NAME: &str = "aer";
/// DAQ timestamps: 4 bytes (the A2L's name and the size), one tick per microsecond.
pub(crate) const TIMESTAMP_SIZE: (&str, u8) = ("SIZE_DWORD", 4);
/// See [`TIMESTAMP_SIZE`].
pub(crate) const TIMESTAMP_TICKS: u16 = 1;
/// The protocol timeouts T1..T7 in ms (T1: a command's response; T3..T5 belong to flash
/// programming, which the slave does not offer).
pub(crate) const TIMEOUTS_MS: [u16; 7] = [2000; 7];
/// The optional commands the slave implements (beyond CONNECT, DISCONNECT, GET_STATUS, SYNCH).
pub(crate) const OPTIONAL_CMDS: [&str; 32] = [
    "GET_COMM_MODE_INFO",
    "GET_ID",
    "SET_REQUEST",
    "GET_SEED",
    "UNLOCK",
    "SET_MTA",
    "UPLOAD",
    "SHORT_UPLOAD",
    "BUILD_CHECKSUM",
    "DOWNLOAD",
    "DOWNLOAD_NEXT",
    "SET_CAL_PAGE",
    "GET_CAL_PAGE",
    "COPY_CAL_PAGE",
    "GET_PAG_PROCESSOR_INFO",
    "GET_SEGMENT_INFO",
    "GET_PAGE_INFO",
    "CLEAR_DAQ_LIST",
    "SET_DAQ_PTR",
    "WRITE_DAQ",
    "SET_DAQ_LIST_MODE",
    "GET_DAQ_LIST_MODE",
    "START_STOP_DAQ_LIST",
    "START_STOP_SYNCH",
    "GET_DAQ_CLOCK",
    "GET_DAQ_PROCESSOR_INFO",
    "GET_DAQ_RESOLUTION_INFO",
    "GET_DAQ_EVENT_INFO",
    "FREE_DAQ",
    "ALLOC_DAQ",
    "ALLOC_ODT",
    "ALLOC_ODT_ENTRY",
];

/// The ECU program identifier: names the schema a firmware was built from, so a tool holding
/// a description of another build notices at connection.
pub(crate) struct Epk {
    pub telemetry: u32,
    pub calibration: u32,
    /// `AER <telemetry fingerprint> <calibration fingerprint>`, fixed-length ASCII.
    pub text: String,
}

impl Epk {
    pub(crate) fn new(telemetry: u32, calibration: u32) -> Self {
        Self {
            telemetry,
            calibration,
            text: format!("AER {telemetry:08X} {calibration:08X}"),
        }
    }
}

#[derive(Template)]
#[template(path = "aer.a2l", escape = "none")]
pub(crate) struct A2lTemplate<'a> {
    pub module: &'a str,
    pub module_description: String,
    pub epk: &'a Epk,
    pub epk_address: String,
    pub epk_len: usize,
    pub calibration_address: String,
    pub page_len: usize,
    pub telemetry_address: String,
    pub telemetry_len: usize,
    pub internals_address: String,
    pub internals_len: usize,
    pub xcp_status_address: String,
    pub xcp_status_len: u32,
    pub idle_timeout_s: u32,
    pub unlock_delay_s: u32,
    pub unlock_delay_max_s: u32,
    pub timeouts: String,
    pub max_cto: u8,
    pub max_dto: u16,
    pub max_bs: u8,
    pub min_st: u8,
    pub checksum: &'static str,
    pub max_checksum_block: String,
    pub optional_cmds: &'static [&'static str],
    pub max_daq: u16,
    pub max_odt_entry_size: u8,
    pub timestamp_size: &'static str,
    pub timestamp_ticks: u16,
    pub events: Vec<EventView>,
    pub can_id_master: String,
    pub can_id_slave: String,
    pub bit_rate: u32,
    pub tcp_port: u16,
    pub characteristics: Vec<CharacteristicView>,
    pub axis_pts: Vec<AxisPtsView>,
    pub measurements: Vec<MeasurementView>,
    pub conversions: Vec<ConversionView>,
    pub tables: Vec<TableView>,
    pub layouts: Vec<LayoutView>,
    pub groups: Vec<GroupView>,
}

pub(crate) struct EventView {
    pub name: String,
    /// At most 8 characters (the A2ML's `char[9]`).
    pub short_name: String,
    pub channel: usize,
    pub cycle: u8,
    pub unit: u8,
}

pub(crate) struct CharacteristicView {
    pub name: String,
    pub description: String,
    /// VALUE, VAL_BLK or CURVE.
    pub kind: &'static str,
    pub address: String,
    pub layout: String,
    pub conversion: String,
    pub lower: String,
    pub upper: String,
    /// A VAL_BLK's element count.
    pub matrix_dim: Option<usize>,
    pub axis: Option<AxisView>,
}

/// A curve's axis: its points in memory (COM_AXIS, AXIS_PTS_REF), its input quantity.
pub(crate) struct AxisView {
    pub input: String,
    pub conversion: String,
    pub count: usize,
    pub lower: String,
    pub upper: String,
    pub axis_pts: String,
}

/// A curve's tunable axis points (AXIS_PTS), strictly increasing.
pub(crate) struct AxisPtsView {
    pub name: String,
    pub description: String,
    pub address: String,
    pub input: String,
    pub layout: String,
    pub conversion: String,
    pub count: usize,
    pub lower: String,
    pub upper: String,
}

pub(crate) struct MeasurementView {
    pub name: String,
    pub description: String,
    pub datatype: &'static str,
    pub conversion: String,
    pub lower: String,
    pub upper: String,
    pub address: String,
    pub bit_mask: Option<String>,
}

/// A COMPU_METHOD: LINEAR (`coeffs`) or TAB_VERB (`table`).
pub(crate) struct ConversionView {
    pub name: String,
    pub description: String,
    pub format: String,
    pub unit: String,
    pub coeffs: Option<String>,
    pub table: Option<String>,
}

/// A COMPU_VTAB: a telemetry enum's raw values and names.
pub(crate) struct TableView {
    pub name: String,
    pub description: String,
    pub entries: Vec<(i128, String)>,
}

pub(crate) struct LayoutView {
    pub name: String,
    pub datatype: &'static str,
    /// Axis points (AXIS_PTS_X) rather than values (FNC_VALUES).
    pub axis: bool,
}

pub(crate) struct GroupView {
    pub name: String,
    pub description: String,
    pub root: bool,
    pub characteristics: Vec<String>,
    pub measurements: Vec<String>,
    pub sub_groups: Vec<String>,
}

/// A number as the A2L states it: whole numbers plainly, others in Rust's shortest form
/// (`0.07`, `1e-7`), which reads back to the same `f64`.
fn num(value: f64) -> String {
    if value.fract() == 0.0 && value.abs() < 1e15 {
        format!("{}", value as i64)
    } else {
        format!("{value:?}")
    }
}

fn hex(value: u32) -> String {
    format!("0x{value:X}")
}

/// Text as an A2L string's contents: one line, quotes and backslashes escaped.
fn text(value: &str) -> String {
    value
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
        .replace('\\', "\\\\")
        .replace('"', "\\\"")
}

/// Digits after the decimal point of `value` written shortest (`0.4` -> 1), at most 6.
fn decimals(value: f64) -> usize {
    let written = format!("{value}");
    written
        .split_once('.')
        .map_or(0, |(_, fraction)| fraction.len())
        .min(6)
}

/// The decimals an `f32` value is shown with.
const FLOAT_DECIMALS: usize = 4;

/// An identifier made of `unit` (`Nm/s` -> `Nm_per_s`, `%` -> `percent`, `1` -> `ratio`).
fn unit_ident(unit: &str) -> String {
    match unit {
        "" => "none".to_owned(),
        "1" => "ratio".to_owned(),
        _ => unit
            .replace('%', "percent")
            .replace('/', "_per_")
            .chars()
            .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
            .collect(),
    }
}

/// The conversions in order of first use, each distinct one once.
#[derive(Default)]
struct Conversions {
    views: Vec<ConversionView>,
    tables: Vec<TableView>,
    /// (scale bits, offset bits, unit, decimals) -> name, for LINEAR; enum index for tables.
    linear: Vec<((u64, u64, String, usize), String)>,
    enums: Vec<(usize, String)>,
    names: HashSet<String>,
}

impl Conversions {
    /// `base`, or `base.2`, `base.3`, ... when taken.
    fn fresh(&mut self, base: &str) -> String {
        let mut name = base.to_owned();
        let mut n = 1;
        while !self.names.insert(name.clone()) {
            n += 1;
            name = format!("{base}.{n}");
        }
        name
    }

    /// physical = `scale` * raw + `offset`, shown with `decimals` in `unit`.
    fn linear(&mut self, scale: f64, offset: f64, unit: &str, decimals: usize) -> String {
        let key = (scale.to_bits(), offset.to_bits(), unit.to_owned(), decimals);
        if let Some((_, name)) = self.linear.iter().find(|(k, _)| *k == key) {
            return name.clone();
        }
        let name = self.fresh(&format!("cm.{}", unit_ident(unit)));
        let description = if scale == 1.0 && offset == 0.0 {
            format!("identity, {}", display_unit(unit))
        } else {
            format!(
                "raw * {} + {}, {}",
                num(scale),
                num(offset),
                display_unit(unit)
            )
        };
        self.views.push(ConversionView {
            name: name.clone(),
            description,
            format: format!("%12.{decimals}"),
            unit: text(unit),
            coeffs: Some(format!("{} {}", num(scale), num(offset))),
            table: None,
        });
        self.linear.push((key, name.clone()));
        name
    }

    /// A table of `entries` (raw value, name) called `vtab.<ident>`, its conversion
    /// `cm.<ident>`.
    fn named(&mut self, ident: &str, description: &str, entries: Vec<(i128, String)>) -> String {
        let name = self.fresh(&format!("cm.{ident}"));
        let table = self.fresh(&format!("vtab.{ident}"));
        self.tables.push(TableView {
            name: table.clone(),
            description: text(description),
            entries,
        });
        self.views.push(ConversionView {
            name: name.clone(),
            description: format!("{}, named values", text(description)),
            format: "%12.0".to_owned(),
            unit: String::new(),
            coeffs: None,
            table: Some(table),
        });
        name
    }

    /// The value names of `db.enums[index]`.
    fn table(&mut self, db: &Database, index: usize) -> String {
        if let Some((_, name)) = self.enums.iter().find(|(i, _)| *i == index) {
            return name.clone();
        }
        let Some(e) = db.enums.get(index) else {
            return "NO_COMPU_METHOD".to_owned();
        };
        let name = self.fresh(&format!("cm.enum.{}", e.type_name));
        let table = self.fresh(&format!("vtab.{}", e.type_name));
        self.tables.push(TableView {
            name: table.clone(),
            description: format!("{}: the raw values' names", e.type_name),
            entries: e
                .variants
                .iter()
                .map(|v| (v.value, text(&v.label)))
                .collect(),
        });
        self.views.push(ConversionView {
            name: name.clone(),
            description: format!("{}, named values", e.type_name),
            format: "%12.0".to_owned(),
            unit: String::new(),
            coeffs: None,
            table: Some(table),
        });
        self.enums.push((index, name.clone()));
        name
    }
}

/// A unit for people: a ratio's `1` says so.
fn display_unit(unit: &str) -> String {
    match unit {
        "" => "no unit".to_owned(),
        "1" => "a ratio".to_owned(),
        _ => unit.to_owned(),
    }
}

/// The A2L data type of a parameter's elements, and its record layout's name.
fn element_datatype(element: ElementType) -> &'static str {
    match element {
        ElementType::F32 => "FLOAT32_IEEE",
        ElementType::U8 => "UBYTE",
        ElementType::U16 => "UWORD",
        ElementType::U32 => "ULONG",
        ElementType::I16 => "SWORD",
        ElementType::I32 => "SLONG",
    }
}

fn wire_datatype(wire: WireType) -> &'static str {
    match wire {
        WireType::U8 | WireType::Flag => "UBYTE",
        WireType::U16 => "UWORD",
        WireType::U32 => "ULONG",
        WireType::I8 => "SBYTE",
        WireType::I16 => "SWORD",
        WireType::I32 => "SLONG",
        WireType::F32 => "FLOAT32_IEEE",
    }
}

fn layout_name(element: ElementType) -> String {
    format!("rl.{}", element.rust())
}

fn axis_layout_name(element: ElementType) -> String {
    format!("rl.axis.{}", element.rust())
}

/// The parameter holding a curve's axis points, as an AXIS_PTS.
fn axis_pts(p: &Parameter, input: &str, conversions: &mut Conversions) -> AxisPtsView {
    AxisPtsView {
        name: format!("calibration.{}", p.name),
        description: text(&p.description),
        address: hex(CALIBRATION_ADDRESS + offset_u32(p.offset)),
        input: format!("internals.{input}"),
        layout: axis_layout_name(p.element),
        conversion: conversions.linear(1.0, 0.0, &p.unit, FLOAT_DECIMALS),
        count: p.defaults.len(),
        lower: num(p.min),
        upper: num(p.max),
    }
}

fn characteristic(p: &Parameter, conversions: &mut Conversions) -> CharacteristicView {
    let decimals = if p.element.is_integer() {
        0
    } else {
        FLOAT_DECIMALS
    };
    let conversion = conversions.linear(1.0, 0.0, &p.unit, decimals);
    let axis = p.axis.as_ref().map(|a| AxisView {
        input: format!("internals.{}", a.input),
        conversion: conversions.linear(1.0, 0.0, &a.unit, FLOAT_DECIMALS),
        count: a.points.len(),
        lower: num(a.min),
        upper: num(a.max),
        axis_pts: format!("calibration.{}", a.parameter),
    });
    let kind = match (p.scalar, &axis) {
        (true, _) => "VALUE",
        (false, Some(_)) => "CURVE",
        (false, None) => "VAL_BLK",
    };
    CharacteristicView {
        name: format!("calibration.{}", p.name),
        description: text(&p.description),
        kind,
        address: hex(CALIBRATION_ADDRESS + offset_u32(p.offset)),
        layout: layout_name(p.element),
        conversion,
        lower: num(p.min),
        upper: num(p.max),
        matrix_dim: (kind == "VAL_BLK").then_some(p.defaults.len()),
        axis,
    }
}

/// An offset inside one of the address map's 64 KiB areas.
fn offset_u32(offset: usize) -> u32 {
    u32::try_from(offset).unwrap_or(u32::MAX)
}

/// The physical values a field's raw type spans, lowest first.
fn wire_range(f: &TelemetryField) -> (f64, f64) {
    if f.wire == WireType::F32 {
        let max = f64::from(f32::MAX);
        return (-max, max);
    }
    let (lo, hi) = f.wire.range();
    let (a, b) = (
        lo as f64 * f.scale + f.offset,
        hi as f64 * f.scale + f.offset,
    );
    (a.min(b), a.max(b))
}

fn field_measurement(
    db: &Database,
    f: &TelemetryField,
    conversions: &mut Conversions,
) -> MeasurementView {
    let (byte, bit_mask) = match f.placement {
        Placement::Bytes(byte) => (byte, None),
        Placement::Bit(byte, bit) => (byte, Some(format!("0x{:X}", 1u32 << bit))),
    };
    let (lo, hi) = wire_range(f);
    let (conversion, (lower, upper)) = match (f.wire, f.phys) {
        (WireType::Flag, _) => ("NO_COMPU_METHOD".to_owned(), (0.0, 1.0)),
        (_, PhysType::Enum(index)) => (
            conversions.table(db, index),
            (f.min.unwrap_or(lo), f.max.unwrap_or(hi)),
        ),
        _ => {
            let decimals = if f.wire == WireType::F32 {
                FLOAT_DECIMALS
            } else {
                decimals(f.scale).max(decimals(f.offset))
            };
            (
                conversions.linear(f.scale, f.offset, &f.unit, decimals),
                (f.min.unwrap_or(lo), f.max.unwrap_or(hi)),
            )
        }
    };
    let description = if f.description.trim().is_empty() {
        f.display.label.clone().unwrap_or_else(|| f.name.clone())
    } else {
        f.description.clone()
    };
    MeasurementView {
        name: format!("telemetry.{}", f.name),
        description: text(&description),
        datatype: wire_datatype(f.wire),
        conversion,
        lower: num(lower),
        upper: num(upper),
        address: hex(TELEMETRY_ADDRESS + offset_u32(byte)),
        bit_mask,
    }
}

/// The packet header's sequence and timestamp, then every field.
fn telemetry_measurements(
    db: &Database,
    t: &Telemetry,
    conversions: &mut Conversions,
) -> Vec<MeasurementView> {
    let header = [
        (
            "sequence",
            "Increments by one every packet (wrapping): a gap means lost packets.",
            "UWORD",
            "",
            4,
            f64::from(u16::MAX),
        ),
        (
            "timestamp_us",
            "The CCM's clock when the snapshot was taken (wrapping).",
            "ULONG",
            "us",
            6,
            f64::from(u32::MAX),
        ),
    ];
    let mut measurements: Vec<MeasurementView> = header
        .into_iter()
        .map(
            |(name, description, datatype, unit, offset, max)| MeasurementView {
                name: format!("telemetry.{name}"),
                description: description.to_owned(),
                datatype,
                conversion: conversions.linear(1.0, 0.0, unit, 0),
                lower: "0".to_owned(),
                upper: num(max),
                address: hex(TELEMETRY_ADDRESS + offset),
                bit_mask: None,
            },
        )
        .collect();
    measurements.extend(
        t.fields
            .iter()
            .map(|f| field_measurement(db, f, conversions)),
    );
    measurements
}

fn groups(c: &Calibration, t: &Telemetry) -> Vec<GroupView> {
    let group = |name: String, description: String| GroupView {
        name,
        description,
        root: false,
        characteristics: Vec::new(),
        measurements: Vec::new(),
        sub_groups: Vec::new(),
    };
    // The calibration by when it may change.
    let mut by_change: Vec<GroupView> = Vec::new();
    for p in &c.parameters {
        let name = format!("Calibration.{}", p.change.schema_name());
        let index = match by_change.iter().position(|g| g.name == name) {
            Some(index) => index,
            None => {
                by_change.push(group(name, format!("Changes {}", p.change.words())));
                by_change.len() - 1
            }
        };
        by_change[index]
            .characteristics
            .push(format!("calibration.{}", p.name));
    }
    by_change.sort_by_key(|g| g.name.clone());
    // The telemetry by its groups, the header first.
    let mut by_group = vec![group(
        "Telemetry.header".to_owned(),
        "The packet header".to_owned(),
    )];
    by_group[0].measurements = vec![
        "telemetry.sequence".to_owned(),
        "telemetry.timestamp_us".to_owned(),
    ];
    for f in &t.fields {
        let name = format!("Telemetry.{}", f.group);
        let index = match by_group.iter().position(|g| g.name == name) {
            Some(index) => index,
            None => {
                by_group.push(group(name, format!("Telemetry: {}", f.group)));
                by_group.len() - 1
            }
        };
        by_group[index]
            .measurements
            .push(format!("telemetry.{}", f.name));
    }
    let mut calibration = group(
        "Calibration".to_owned(),
        "The tuned numbers, by when they may change".to_owned(),
    );
    calibration.root = true;
    calibration.sub_groups = by_change.iter().map(|g| g.name.clone()).collect();
    let mut telemetry = group(
        "Telemetry".to_owned(),
        "The telemetry packet as sent".to_owned(),
    );
    telemetry.root = true;
    telemetry.sub_groups = by_group.iter().map(|g| g.name.clone()).collect();
    let mut internals = group(
        "Internals".to_owned(),
        "The controllers' internal values".to_owned(),
    );
    internals.root = true;
    internals.measurements = c
        .internals
        .iter()
        .map(|i| format!("internals.{}", i.name))
        .collect();
    let mut xcp = group(
        "Xcp".to_owned(),
        "The XCP slave: the last refusal and why, what DAQ lost".to_owned(),
    );
    xcp.root = true;
    xcp.measurements = aer_xcp::status::FIELDS
        .iter()
        .map(|field| format!("xcp.{}", field.name))
        .collect();
    let mut all = vec![calibration];
    all.extend(by_change);
    all.push(telemetry);
    all.extend(by_group);
    all.push(internals);
    all.push(xcp);
    all
}

/// The XCP slave's block (its last refusal and counters), with the tables that name commands,
/// error codes, reasons and parameters.
fn xcp_status_measurements(c: &Calibration, conversions: &mut Conversions) -> Vec<MeasurementView> {
    let entries = |list: &[(u8, &str)]| {
        list.iter()
            .map(|(value, name)| (i128::from(*value), text(name)))
            .collect::<Vec<_>>()
    };
    let command = conversions.named("xcp.command", "XCP commands", entries(&cmd::NAMES));
    let error = conversions.named("xcp.error", "XCP error codes", entries(&err::NAMES));
    let reason = conversions.named(
        "xcp.reason",
        "Why a command was refused",
        entries(&reason::ALL),
    );
    let mut items: Vec<(i128, String)> = c
        .parameters
        .iter()
        .enumerate()
        .map(|(index, p)| (index as i128, p.name.clone()))
        .collect();
    items.push((i128::from(Detail::NO_ITEM), "none".to_owned()));
    let item = conversions.named("xcp.item", "Calibration parameters by index", items);
    let count = conversions.linear(1.0, 0.0, "", 0);
    let plain = conversions.linear(1.0, 0.0, "", FLOAT_DECIMALS);
    FIELDS
        .iter()
        .map(|field| {
            let conversion = match (field.names, field.kind) {
                (Names::Command, _) => command.clone(),
                (Names::Error, _) => error.clone(),
                (Names::Reason, _) => reason.clone(),
                (Names::Item, _) => item.clone(),
                (Names::None, Kind::F32) => plain.clone(),
                (Names::None, _) => count.clone(),
            };
            let (datatype, lower, upper) = match field.kind {
                Kind::U8 => ("UBYTE", 0.0, f64::from(u8::MAX)),
                Kind::U16 => ("UWORD", 0.0, f64::from(u16::MAX)),
                Kind::U32 => ("ULONG", 0.0, f64::from(u32::MAX)),
                Kind::F32 => ("FLOAT32_IEEE", -f64::from(f32::MAX), f64::from(f32::MAX)),
            };
            MeasurementView {
                name: format!("xcp.{}", field.name),
                description: field.description.to_owned(),
                datatype,
                conversion,
                lower: num(lower),
                upper: num(upper),
                address: hex(XCP_STATUS_ADDRESS + field.offset),
                bit_mask: None,
            }
        })
        .collect()
}

pub(crate) fn render(
    db: &Database,
    t: &Telemetry,
    c: &Calibration,
    epk: &Epk,
) -> Result<String, askama::Error> {
    let mut conversions = Conversions::default();
    let characteristics: Vec<CharacteristicView> = c
        .parameters
        .iter()
        .filter(|p| p.axis_of.is_none())
        .map(|p| characteristic(p, &mut conversions))
        .collect();
    let axis_pts: Vec<AxisPtsView> = c
        .parameters
        .iter()
        .filter_map(|curve| {
            let axis = curve.axis.as_ref()?;
            let points = c.parameters.iter().find(|p| p.name == axis.parameter)?;
            Some(axis_pts(points, &axis.input, &mut conversions))
        })
        .collect();
    let mut measurements = telemetry_measurements(db, t, &mut conversions);
    for (index, i) in c.internals.iter().enumerate() {
        measurements.push(MeasurementView {
            name: format!("internals.{}", i.name),
            description: text(&i.description),
            datatype: "FLOAT32_IEEE",
            conversion: conversions.linear(1.0, 0.0, &i.unit, FLOAT_DECIMALS),
            lower: num(i.min),
            upper: num(i.max),
            address: hex(INTERNALS_ADDRESS + offset_u32(index * INTERNAL_SIZE)),
            bit_mask: None,
        });
    }
    measurements.extend(xcp_status_measurements(c, &mut conversions));
    let mut layouts: Vec<LayoutView> = Vec::new();
    for p in &c.parameters {
        let axis = p.axis_of.is_some();
        let name = if axis {
            axis_layout_name(p.element)
        } else {
            layout_name(p.element)
        };
        if !layouts.iter().any(|l| l.name == name) {
            layouts.push(LayoutView {
                name,
                datatype: element_datatype(p.element),
                axis,
            });
        }
    }
    let x = &c.xcp;
    A2lTemplate {
        module: &c.name,
        module_description: text(&c.description),
        epk,
        epk_address: hex(EPK_ADDRESS),
        epk_len: epk.text.len(),
        calibration_address: hex(CALIBRATION_ADDRESS),
        page_len: c.page_len,
        telemetry_address: hex(TELEMETRY_ADDRESS),
        telemetry_len: t.len,
        internals_address: hex(INTERNALS_ADDRESS),
        internals_len: c.internals_len(),
        xcp_status_address: hex(XCP_STATUS_ADDRESS),
        xcp_status_len: XCP_STATUS_LEN,
        idle_timeout_s: x.idle_timeout_ms / 1000,
        unlock_delay_s: x.unlock_delay_ms / 1000,
        unlock_delay_max_s: x.unlock_delay_max_ms / 1000,
        timeouts: TIMEOUTS_MS
            .iter()
            .map(u16::to_string)
            .collect::<Vec<_>>()
            .join(" "),
        max_cto: MAX_CTO,
        max_dto: MAX_DTO,
        max_bs: MAX_BS,
        min_st: MIN_ST,
        checksum: CHECKSUM_TYPE.0,
        max_checksum_block: hex(MAX_CHECKSUM_BLOCK),
        optional_cmds: &OPTIONAL_CMDS,
        max_daq: x.max_daq,
        max_odt_entry_size: x.max_odt_entry_size,
        timestamp_size: TIMESTAMP_SIZE.0,
        timestamp_ticks: TIMESTAMP_TICKS,
        events: x
            .events
            .iter()
            .enumerate()
            .map(|(channel, e)| {
                let (cycle, unit) = e.time_cycle().unwrap_or((0, 0));
                EventView {
                    name: text(&e.name),
                    short_name: e.name.chars().take(8).collect(),
                    channel,
                    cycle,
                    unit,
                }
            })
            .collect(),
        can_id_master: hex(x.can_id_master),
        can_id_slave: hex(x.can_id_slave),
        bit_rate: x.bit_rate,
        tcp_port: x.tcp_port,
        characteristics,
        axis_pts,
        measurements,
        conversions: conversions.views,
        tables: conversions.tables,
        layouts,
        groups: groups(c, t),
    }
    .render()
}
