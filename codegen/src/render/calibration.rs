//! Renders the CCM's calibration (`calibration.rs`): the struct with its defaults, the page
//! calibration tools address (every parameter little-endian at a fixed offset), each
//! parameter's limits and change condition, and the typed curve lookups.

use askama::Template;

use super::a2l::{self, Epk};
use super::doc_lines;
use crate::model::{Calibration, ElementType, INTERNAL_SIZE, Internal, Parameter, Xcp};

#[derive(Template)]
#[template(path = "calibration.rs", escape = "none")]
pub(crate) struct CalibrationTemplate<'a> {
    pub source: &'a str,
    pub description: Vec<String>,
    pub fingerprint: String,
    pub page_len: usize,
    pub parameters: Vec<ParameterView>,
    /// The element types the page uses (one variant each).
    pub element_types: Vec<ElementView>,
    /// Some parameter is a curve (the interpolation is emitted only then).
    pub curves: bool,
    pub internals: Vec<InternalView>,
    pub internals_len: usize,
    pub xcp: XcpView,
}

pub(crate) struct InternalView {
    pub name: String,
    pub doc: Vec<String>,
    pub unit: String,
    pub description: String,
    pub offset: usize,
    pub min: String,
    pub max: String,
}

/// The `xcp` module's constants, as Rust literals.
pub(crate) struct XcpView {
    pub calibration_address: String,
    pub telemetry_address: String,
    pub internals_address: String,
    pub epk_address: String,
    pub xcp_status_address: String,
    pub xcp_status_len: u32,
    pub epk: String,
    pub command_message: String,
    pub response_message: String,
    pub bus: String,
    pub can_id_master: String,
    pub can_id_slave: String,
    pub bit_rate: String,
    pub response_cycle_ms: u32,
    pub daq_frames_per_s: u32,
    pub tcp_port: u16,
    pub max_cto: u8,
    pub max_dto: u16,
    pub max_bs: u8,
    pub min_st: u8,
    pub checksum_name: &'static str,
    pub checksum_type: String,
    pub max_checksum_block: String,
    pub a2l_name: &'static str,
    pub timestamp_size: u8,
    pub timestamp_ticks: u16,
    pub max_daq: u16,
    pub odt_entries: u16,
    pub max_odt_entry_size: u8,
    pub idle_timeout_ms: u32,
    pub idle_timeout: String,
    pub unlock_delay_ms: u32,
    pub unlock_delay_max_ms: u32,
    pub unlock_delays: String,
    pub events: Vec<EventView>,
}

pub(crate) struct EventView {
    pub name: String,
    pub upper: String,
    pub description: String,
    /// The period in microseconds, as a Rust literal.
    pub period_us: String,
    /// The period for people (`10 ms`, `500 us`).
    pub period: String,
    pub channel: usize,
}

/// An element type as the generated enum names it.
pub(crate) struct ElementView {
    pub variant: String,
    pub rust: &'static str,
    pub size: usize,
}

pub(crate) struct ParameterView {
    pub name: String,
    pub doc: Vec<String>,
    pub label: String,
    pub group: String,
    pub unit: String,
    pub description: String,
    /// The struct field's type (`f32`, `[f32; 4]`).
    pub rust_type: String,
    pub element: ElementView,
    pub scalar: bool,
    pub count: usize,
    pub offset: usize,
    /// Where element `index` starts in the page, as an expression.
    pub element_at: String,
    pub default: String,
    pub min: String,
    pub max: String,
    pub change: &'static str,
    pub increasing: bool,
    pub elements: Vec<String>,
    pub axis: Option<AxisView>,
    pub axis_of: Option<String>,
}

pub(crate) struct AxisView {
    pub label: String,
    pub unit: String,
    pub points: String,
    pub parameter: String,
    pub input: String,
}

fn element_view(element: ElementType) -> ElementView {
    let rust = element.rust();
    ElementView {
        variant: rust.to_uppercase(),
        rust,
        size: element.size(),
    }
}

/// A value as a Rust literal of the element type.
fn literal(element: ElementType, value: f64) -> String {
    if element.is_integer() {
        format!("{}", value as i64)
    } else {
        format!("{:?}", value as f32)
    }
}

fn list(element: ElementType, values: &[f64]) -> String {
    let items: Vec<String> = values.iter().map(|v| literal(element, *v)).collect();
    format!("[{}]", items.join(", "))
}

/// An address as a Rust literal, in 16-bit groups (`0x0001_0000`).
fn address(value: u32) -> String {
    format!("0x{:04X}_{:04X}", value >> 16, value & 0xFFFF)
}

/// A whole number as a Rust literal, in groups of three digits (`500_000`).
fn grouped(value: u32) -> String {
    let digits = value.to_string();
    let mut out = String::new();
    for (index, c) in digits.chars().enumerate() {
        if index > 0 && (digits.len() - index) % 3 == 0 {
            out.push('_');
        }
        out.push(c);
    }
    out
}

/// A period for people: whole milliseconds in ms, else microseconds.
/// A duration in milliseconds for people: whole seconds as seconds.
fn duration_ms(ms: u32) -> String {
    if ms % 1000 == 0 {
        format!("{} s", ms / 1000)
    } else {
        format!("{ms} ms")
    }
}

fn period(period_us: u32) -> String {
    if period_us % 1000 == 0 {
        format!("{} ms", period_us / 1000)
    } else {
        format!("{period_us} us")
    }
}

fn internal_view(index: usize, i: &Internal) -> InternalView {
    let mut doc = wrap(&i.description, DOC_WIDTH);
    doc.push(String::new());
    doc.extend(wrap(
        &format!(
            "Expected {} to {}; bytes {} to {} of the block.",
            number(i.min),
            with_unit(&number(i.max), &i.unit),
            index * INTERNAL_SIZE,
            index * INTERNAL_SIZE + INTERNAL_SIZE - 1
        ),
        DOC_WIDTH,
    ));
    InternalView {
        name: i.name.clone(),
        doc,
        unit: i.unit.clone(),
        description: i.description.clone(),
        offset: index * INTERNAL_SIZE,
        min: format!("{:?}", i.min),
        max: format!("{:?}", i.max),
    }
}

fn xcp_view(x: &Xcp, epk: &Epk) -> XcpView {
    XcpView {
        calibration_address: address(a2l::CALIBRATION_ADDRESS),
        telemetry_address: address(a2l::TELEMETRY_ADDRESS),
        internals_address: address(a2l::INTERNALS_ADDRESS),
        epk_address: address(a2l::EPK_ADDRESS),
        xcp_status_address: address(a2l::XCP_STATUS_ADDRESS),
        xcp_status_len: a2l::XCP_STATUS_LEN,
        epk: epk.text.clone(),
        command_message: x.command_message.clone(),
        response_message: x.response_message.clone(),
        bus: x.bus.clone().unwrap_or_else(|| "the DBC's".to_owned()),
        can_id_master: format!("0x{:03X}", x.can_id_master),
        can_id_slave: format!("0x{:03X}", x.can_id_slave),
        bit_rate: grouped(x.bit_rate),
        response_cycle_ms: x.response_cycle_ms,
        daq_frames_per_s: 1000 / x.response_cycle_ms.max(1),
        tcp_port: x.tcp_port,
        max_cto: a2l::MAX_CTO,
        max_dto: a2l::MAX_DTO,
        max_bs: a2l::MAX_BS,
        min_st: a2l::MIN_ST,
        checksum_name: a2l::CHECKSUM_TYPE.0,
        checksum_type: format!("0x{:02X}", a2l::CHECKSUM_TYPE.1),
        max_checksum_block: format!("0x{:04X}", a2l::MAX_CHECKSUM_BLOCK),
        a2l_name: a2l::A2L_NAME,
        timestamp_size: a2l::TIMESTAMP_SIZE.1,
        timestamp_ticks: a2l::TIMESTAMP_TICKS,
        max_daq: x.max_daq,
        odt_entries: x.odt_entries,
        max_odt_entry_size: x.max_odt_entry_size,
        idle_timeout_ms: x.idle_timeout_ms,
        idle_timeout: duration_ms(x.idle_timeout_ms),
        unlock_delay_ms: x.unlock_delay_ms,
        unlock_delay_max_ms: x.unlock_delay_max_ms,
        unlock_delays: format!(
            "{} after a wrong key, doubling with each one in a row up to {}",
            duration_ms(x.unlock_delay_ms),
            duration_ms(x.unlock_delay_max_ms)
        ),
        events: x
            .events
            .iter()
            .enumerate()
            .map(|(channel, e)| EventView {
                name: e.name.clone(),
                upper: e.name.to_uppercase(),
                description: e.description.trim_end_matches('.').to_owned(),
                period_us: grouped(e.period_us),
                period: period(e.period_us),
                channel,
            })
            .collect(),
    }
}

/// A value as people read it (`2000`, `0.07`).
fn number(value: f64) -> String {
    format!("{value}")
}

/// Numbers as people read them, comma-separated.
fn numbers(values: &[f64]) -> String {
    let items: Vec<String> = values.iter().map(|v| number(*v)).collect();
    items.join(", ")
}

/// A value with its unit, which a ratio (`1`) leaves out.
fn with_unit(value: &str, unit: &str) -> String {
    if unit == "1" {
        value.to_owned()
    } else {
        format!("{value} {unit}")
    }
}

/// `text` in lines of at most `width` characters, broken at spaces.
fn wrap(text: &str, width: usize) -> Vec<String> {
    let mut lines = Vec::new();
    let mut line = String::new();
    for word in text.split_whitespace() {
        if !line.is_empty() && line.len() + 1 + word.len() > width {
            lines.push(std::mem::take(&mut line));
        }
        if !line.is_empty() {
            line.push(' ');
        }
        line.push_str(word);
    }
    if !line.is_empty() {
        lines.push(line);
    }
    lines
}

/// Doc comments stay within rustfmt's 100 columns at the struct's indent.
const DOC_WIDTH: usize = 90;

fn view(p: &Parameter) -> ParameterView {
    let count = p.defaults.len();
    let mut summary = format!(
        "{}: {} to {}",
        p.label,
        number(p.min),
        with_unit(&number(p.max), &p.unit)
    );
    if !p.elements.is_empty() {
        summary.push_str(&format!("; elements: {}", p.elements.join(", ")));
    }
    if let Some(a) = &p.axis {
        summary.push_str(&format!(
            "; over {} ({}, tunable: `{}`, by default {})",
            a.label.to_lowercase(),
            a.unit,
            a.parameter,
            numbers(&a.points),
        ));
    }
    if p.increasing {
        summary.push_str("; increasing");
    }
    summary.push_str(&format!("; changes {}.", p.change.words()));
    let mut doc = wrap(&p.description, DOC_WIDTH);
    doc.push(String::new());
    doc.extend(wrap(&summary, DOC_WIDTH));
    ParameterView {
        name: p.name.clone(),
        doc,
        label: p.label.clone(),
        group: p.group.clone(),
        unit: p.unit.clone(),
        description: p.description.clone(),
        rust_type: if p.scalar {
            p.element.rust().to_owned()
        } else {
            format!("[{}; {count}]", p.element.rust())
        },
        element: element_view(p.element),
        scalar: p.scalar,
        count,
        offset: p.offset,
        element_at: match (p.offset, p.element.size()) {
            (0, 1) => "index".to_owned(),
            (0, size) => format!("index * {size}"),
            (offset, 1) => format!("{offset} + index"),
            (offset, size) => format!("{offset} + index * {size}"),
        },
        default: if p.scalar {
            literal(p.element, p.defaults.first().copied().unwrap_or_default())
        } else {
            list(p.element, &p.defaults)
        },
        min: format!("{:?}", p.min),
        max: format!("{:?}", p.max),
        change: p.change.variant(),
        increasing: p.increasing,
        elements: p.elements.clone(),
        axis: p.axis.as_ref().map(|a| AxisView {
            label: a.label.clone(),
            unit: a.unit.clone(),
            points: list(ElementType::F32, &a.points),
            parameter: a.parameter.clone(),
            input: a.input.clone(),
        }),
        axis_of: p.axis_of.clone(),
    }
}

pub(crate) fn render(c: &Calibration, source: &str, epk: &Epk) -> Result<String, askama::Error> {
    let mut element_types: Vec<ElementType> = Vec::new();
    for p in &c.parameters {
        if !element_types.contains(&p.element) {
            element_types.push(p.element);
        }
    }
    CalibrationTemplate {
        source,
        description: doc_lines(&c.description),
        fingerprint: format!("0x{:08X}", epk.calibration),
        page_len: c.page_len,
        parameters: c.parameters.iter().map(view).collect(),
        element_types: element_types.into_iter().map(element_view).collect(),
        curves: c.parameters.iter().any(|p| p.axis.is_some()),
        internals: c
            .internals
            .iter()
            .enumerate()
            .map(|(index, i)| internal_view(index, i))
            .collect(),
        internals_len: c.internals_len(),
        xcp: xcp_view(&c.xcp, epk),
    }
    .render()
}

#[derive(Template)]
#[template(path = "docs/calibration.md", escape = "none")]
pub(crate) struct CalibrationDoc<'a> {
    pub source: &'a str,
    pub fingerprint: String,
    pub name: &'a str,
    pub description: &'a str,
    pub page_len: usize,
    pub groups: Vec<GroupDoc>,
    pub internals: Vec<InternalDoc>,
    pub internals_len: usize,
    pub xcp: XcpView,
    /// The address map: address, bytes, what lies there.
    pub areas: Vec<(String, usize, &'static str)>,
    pub bit_rate: String,
}

pub(crate) struct InternalDoc {
    pub address: String,
    pub name: String,
    pub limits: String,
    pub unit: String,
    pub description: String,
}

/// One section of the docs: the parameters of a group, in page order.
pub(crate) struct GroupDoc {
    pub name: String,
    pub rows: Vec<RowDoc>,
}

pub(crate) struct RowDoc {
    pub offset: usize,
    pub name: String,
    pub label: String,
    pub rust_type: String,
    pub default: String,
    pub limits: String,
    pub unit: String,
    pub change: &'static str,
    pub description: String,
}

fn row(p: &Parameter) -> RowDoc {
    let mut description = p.description.replace('\n', " ").replace('|', "\\|");
    if !p.elements.is_empty() {
        description.push_str(&format!(" Elements: {}.", p.elements.join(", ")));
    }
    if let Some(axis) = &p.axis {
        description.push_str(&format!(
            " Over {} ({}) at the points `{}` holds (by default {}).",
            axis.label,
            axis.unit,
            axis.parameter,
            numbers(&axis.points)
        ));
    }
    if p.increasing {
        description.push_str(" Each element above the one before.");
    }
    RowDoc {
        offset: p.offset,
        name: p.name.clone(),
        label: p.label.clone(),
        rust_type: if p.scalar {
            p.element.rust().to_owned()
        } else {
            format!("{}[{}]", p.element.rust(), p.defaults.len())
        },
        default: numbers(&p.defaults),
        limits: format!("{} .. {}", number(p.min), number(p.max)),
        unit: p.unit.clone(),
        change: p.change.words(),
        description,
    }
}

pub(crate) fn render_docs(
    c: &Calibration,
    source: &str,
    epk: &Epk,
    telemetry_len: usize,
) -> Result<String, askama::Error> {
    let mut groups: Vec<GroupDoc> = Vec::new();
    for p in &c.parameters {
        match groups.iter_mut().find(|g| g.name == p.group) {
            Some(group) => group.rows.push(row(p)),
            None => groups.push(GroupDoc {
                name: p.group.clone(),
                rows: vec![row(p)],
            }),
        }
    }
    CalibrationDoc {
        source,
        fingerprint: format!("0x{:08X}", epk.calibration),
        name: &c.name,
        description: &c.description,
        page_len: c.page_len,
        groups,
        internals: c
            .internals
            .iter()
            .enumerate()
            .map(|(index, i)| InternalDoc {
                address: format!(
                    "0x{:X}",
                    a2l::INTERNALS_ADDRESS as usize + index * INTERNAL_SIZE
                ),
                name: i.name.clone(),
                limits: format!("{} .. {}", number(i.min), number(i.max)),
                unit: i.unit.clone(),
                description: i.description.replace('\n', " ").replace('|', "\\|"),
            })
            .collect(),
        internals_len: c.internals_len(),
        xcp: xcp_view(&c.xcp, epk),
        areas: vec![
            (
                format!("0x{:X}", a2l::CALIBRATION_ADDRESS),
                c.page_len,
                "the calibration page: XCP page 0 working (RAM, what the car runs on), page 1 \
                 reference (the defaults, read-only)",
            ),
            (
                format!("0x{:X}", a2l::TELEMETRY_ADDRESS),
                telemetry_len,
                "the telemetry packet exactly as last sent (`telemetry.md`'s layout)",
            ),
            (
                format!("0x{:X}", a2l::INTERNALS_ADDRESS),
                c.internals_len(),
                "the internals above",
            ),
            (
                format!("0x{:X}", a2l::EPK_ADDRESS),
                epk.text.len(),
                "the EPK, ASCII",
            ),
        ],
        bit_rate: format!("{} kbit/s", c.xcp.bit_rate / 1000),
    }
    .render()
}
