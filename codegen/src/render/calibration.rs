//! Renders the CCM's calibration (`calibration.rs`): the struct with its defaults, the page
//! calibration tools address (every parameter little-endian at a fixed offset), each
//! parameter's limits and change condition, and the typed curve lookups.

use askama::Template;

use super::doc_lines;
use crate::model::{Calibration, ElementType, Parameter};

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
}

/// An element type as the generated enum names it.
pub(crate) struct ElementView {
    pub variant: String,
    pub rust: &'static str,
    pub size: usize,
}

pub(crate) struct ParameterView {
    pub name: String,
    /// The `PARAMETERS` entry's constant prefix (`LAUNCH_SLIP_TARGET`).
    pub upper: String,
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
}

pub(crate) struct AxisView {
    pub label: String,
    pub unit: String,
    pub points: String,
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
            "; over {} at {} {}",
            a.label.to_lowercase(),
            numbers(&a.points),
            a.unit
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
        upper: p.name.to_uppercase(),
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
        }),
    }
}

pub(crate) fn render(
    c: &Calibration,
    source: &str,
    fingerprint: u32,
) -> Result<String, askama::Error> {
    let mut element_types: Vec<ElementType> = Vec::new();
    for p in &c.parameters {
        if !element_types.contains(&p.element) {
            element_types.push(p.element);
        }
    }
    CalibrationTemplate {
        source,
        description: doc_lines(&c.description),
        fingerprint: format!("0x{fingerprint:08X}"),
        page_len: c.page_len,
        parameters: c.parameters.iter().map(view).collect(),
        element_types: element_types.into_iter().map(element_view).collect(),
        curves: c.parameters.iter().any(|p| p.axis.is_some()),
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
            " Over {} ({}) at {}.",
            axis.label,
            axis.unit,
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
    fingerprint: u32,
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
        fingerprint: format!("0x{fingerprint:08X}"),
        name: &c.name,
        description: &c.description,
        page_len: c.page_len,
        groups,
    }
    .render()
}
