//! Checks `calibration.yaml` and lays the page out: every parameter named, typed and limited
//! so that the generated range checks mean what the file says, with file:line diagnostics.

use std::collections::HashSet;
use std::path::Path;

use serde_saphyr::Spanned;

use super::names::{check_item_name, line_of};
use crate::diagnostic::{Code, Diagnostic, Diagnostics, Reporter};
use crate::load::calibration::{
    AxisSpec, DefaultSpec, InternalSpec, LoadedCalibration, ParameterSpec,
};
use crate::model::{Axis, Calibration, ChangeWhen, Database, ElementType, Internal, Parameter};
use crate::naming::{is_keyword, snake};

/// A curve or list longer than this is not a tuning parameter (and would not fit one XCP
/// transfer the master can check at a glance).
const MAX_ELEMENTS: usize = 32;

/// Validates the calibration schema and lays out its page; the XCP messages it names are
/// looked up in `db`.
pub(crate) fn validate(
    path: &Path,
    loaded: &LoadedCalibration,
    db: &Database,
) -> Result<(Calibration, Vec<Diagnostic>), Diagnostics> {
    let mut r = Reporter::new(path, &loaded.text);
    let spec = &loaded.file.calibration;
    let name = &spec.value.name;
    if snake(&name.value) != name.value || name.value.is_empty() {
        r.report(
            Code::ParameterName,
            line_of(name),
            format!("the calibration's name `{}` is not snake_case", name.value),
            "use lower-case letters, digits and underscores (`ccm`)",
        );
    }
    let internals = check_internals(&mut r, &loaded.file.internals);
    let mut seen = HashSet::new();
    let mut parameters = Vec::new();
    let mut offset: usize = 0;
    for parameter in &loaded.file.parameters {
        let Some(checked) = check_parameter(&mut r, parameter, &mut seen, &internals) else {
            continue;
        };
        // A curve's axis points follow it in the page, as a parameter of their own.
        let axis = checked
            .axis
            .as_ref()
            .map(|axis| axis_parameter(&checked, axis));
        for mut placed in core::iter::once(checked).chain(axis) {
            if !seen.insert(placed.name.clone()) && placed.axis_of.is_some() {
                r.report(
                    Code::ParameterName,
                    line_of(parameter),
                    format!(
                        "`{}` is taken: a curve's axis points take that name",
                        placed.name
                    ),
                    "rename the parameter that has it",
                );
            }
            let align = placed.element.size();
            offset = offset.div_ceil(align) * align;
            placed.offset = offset;
            offset += placed.len();
            parameters.push(placed);
        }
    }
    if loaded.file.parameters.is_empty() {
        r.report(
            Code::ParameterShape,
            line_of(spec),
            "the calibration has no parameters".to_owned(),
            "declare the tuned numbers under `parameters:`",
        );
    }
    let xcp = super::xcp::check(&mut r, &loaded.file.xcp, db);
    if r.has_errors() {
        return Err(Diagnostics(r.diagnostics));
    }
    let Some(xcp) = xcp else {
        return Err(Diagnostics(r.diagnostics));
    };
    let calibration = Calibration {
        name: name.value.clone(),
        description: spec.value.description.clone(),
        parameters,
        page_len: offset,
        internals,
        xcp,
    };
    Ok((calibration, r.diagnostics))
}

/// One parameter, or `None` with its problems reported.
fn check_parameter(
    r: &mut Reporter<'_>,
    spanned: &Spanned<ParameterSpec>,
    seen: &mut HashSet<String>,
    internals: &[Internal],
) -> Option<Parameter> {
    let p = &spanned.value;
    let line = line_of(spanned);
    let name = p.name.value.as_str();
    let mut ok = check_name(r, &p.name, seen);
    let element = element_type(r, &p.element);
    let change = change_when(r, &p.change);
    ok &= check_text(r, line, name, "label", p.label.as_deref());
    ok &= check_text(r, line, name, "unit", p.unit.as_deref());
    ok &= check_text(r, line, name, "description", p.description.as_deref());
    ok &= check_text(r, line, name, "group", p.group.as_deref());
    let (element, change) = (element?, change?);
    let (min, max) = limits(r, p, element)?;
    let (scalar, defaults) = match &p.default.value {
        DefaultSpec::One(value) => (true, vec![*value]),
        DefaultSpec::Many(values) => (false, values.clone()),
    };
    let axis = p
        .axis
        .as_ref()
        .and_then(|axis| check_axis(r, name, axis, internals));
    if p.axis.is_some() && element != ElementType::F32 {
        r.report(
            Code::ParameterShape,
            line_of(&p.element),
            format!("curve `{name}` is of type {}", element.rust()),
            "a curve interpolates: make it f32",
        );
        ok = false;
    }
    ok &= check_shape(r, p, scalar, &defaults, p.axis.is_some() && axis.is_none());
    ok &= check_defaults(r, p, element, &defaults, (min, max));
    if !ok {
        return None;
    }
    Some(Parameter {
        name: name.to_owned(),
        label: p.label.clone().unwrap_or_default(),
        group: p.group.clone().unwrap_or_default(),
        description: p.description.clone().unwrap_or_default(),
        unit: p.unit.clone().unwrap_or_default(),
        element,
        scalar,
        defaults,
        min,
        max,
        increasing: p.increasing,
        elements: p
            .elements
            .as_ref()
            .map(|e| e.value.clone())
            .unwrap_or_default(),
        axis,
        axis_of: None,
        change,
        offset: 0,
    })
}

/// The parameter holding `curve`'s axis points: tunable under the curve's change condition,
/// within the axis's limits, strictly increasing (the firmware's lookup needs it).
fn axis_parameter(curve: &Parameter, axis: &Axis) -> Parameter {
    Parameter {
        name: axis.parameter.clone(),
        label: format!("{} axis", curve.label),
        group: curve.group.clone(),
        description: format!(
            "The {} points {}'s values apply at, strictly increasing (the curve is interpolated between them and held at the ends).",
            axis.label.to_lowercase(),
            curve.label.to_lowercase()
        ),
        unit: axis.unit.clone(),
        element: ElementType::F32,
        scalar: false,
        defaults: axis.points.clone(),
        min: axis.min,
        max: axis.max,
        increasing: true,
        elements: (1..=axis.points.len())
            .map(|n| format!("point {n}"))
            .collect(),
        axis: None,
        axis_of: Some(curve.name.clone()),
        change: curve.change,
        offset: 0,
    }
}

fn check_name(r: &mut Reporter<'_>, name: &Spanned<String>, seen: &mut HashSet<String>) -> bool {
    let text = name.value.as_str();
    let line = line_of(name);
    let usable = !text.is_empty()
        && text.starts_with(|c: char| c.is_ascii_lowercase())
        && text
            .chars()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_');
    if !usable {
        r.report(
            Code::ParameterName,
            line,
            format!("parameter name `{text}` is not a snake_case identifier"),
            "start with a lower-case letter; use lower-case letters, digits and underscores",
        );
        return false;
    }
    if is_keyword(text) {
        r.report(
            Code::ParameterName,
            line,
            format!("parameter name `{text}` is a Rust keyword"),
            "choose another name (it becomes a field of the generated struct)",
        );
        return false;
    }
    if !seen.insert(text.to_owned()) {
        r.report(
            Code::ParameterName,
            line,
            format!("parameter `{text}` is declared twice"),
            "give each parameter its own name",
        );
        return false;
    }
    true
}

fn element_type(r: &mut Reporter<'_>, element: &Spanned<String>) -> Option<ElementType> {
    let known = [
        ElementType::F32,
        ElementType::U8,
        ElementType::U16,
        ElementType::U32,
        ElementType::I16,
        ElementType::I32,
    ];
    let found = known.into_iter().find(|t| t.rust() == element.value);
    if found.is_none() {
        r.report(
            Code::ParameterType,
            line_of(element),
            format!("unknown parameter type `{}`", element.value),
            "use f32, u8, u16, u32, i16 or i32",
        );
    }
    found
}

fn change_when(r: &mut Reporter<'_>, change: &Spanned<String>) -> Option<ChangeWhen> {
    let known = [
        ChangeWhen::Driving,
        ChangeWhen::Standstill,
        ChangeWhen::TractiveOff,
    ];
    let found = known.into_iter().find(|c| c.schema_name() == change.value);
    if found.is_none() {
        r.report(
            Code::ChangeCondition,
            line_of(change),
            format!("unknown change condition `{}`", change.value),
            "use driving, standstill or tractive_off",
        );
    }
    found
}

fn check_text(
    r: &mut Reporter<'_>,
    line: usize,
    name: &str,
    key: &str,
    text: Option<&str>,
) -> bool {
    if text.is_some_and(|t| !t.trim().is_empty()) {
        return true;
    }
    r.report(
        Code::ParameterText,
        line,
        format!("parameter `{name}` has no {key}"),
        format!(
            "add `{key}:` (the calibration tool and the docs show it; `1` is the unit of a ratio)"
        ),
    );
    false
}

/// The limits, checked against each other and the type.
fn limits(r: &mut Reporter<'_>, p: &ParameterSpec, element: ElementType) -> Option<(f64, f64)> {
    let (min, max) = (p.min.value, p.max.value);
    let (low, high) = element.range();
    let mut ok = true;
    for (key, value, line) in [("min", min, line_of(&p.min)), ("max", max, line_of(&p.max))] {
        let whole = !element.is_integer() || value.fract() == 0.0;
        if !value.is_finite() || value < low || value > high || !whole {
            r.report(
                Code::ParameterLimits,
                line,
                format!("{key} {value} is not a value {} holds", element.rust()),
                format!(
                    "keep it within {low}..={high}{}",
                    if element.is_integer() {
                        ", a whole number"
                    } else {
                        ""
                    }
                ),
            );
            ok = false;
        }
    }
    if ok && min >= max {
        r.report(
            Code::ParameterLimits,
            line_of(&p.max),
            format!("max {max} is not above min {min}"),
            "swap them, or give the parameter room to be tuned",
        );
        ok = false;
    }
    ok.then_some((min, max))
}

fn check_axis(
    r: &mut Reporter<'_>,
    name: &str,
    axis: &Spanned<AxisSpec>,
    internals: &[Internal],
) -> Option<Axis> {
    let spec = &axis.value;
    let (min, max) = (spec.min.value, spec.max.value);
    let f32_range = -f64::from(f32::MAX)..=f64::from(f32::MAX);
    if !(f32_range.contains(&min) && f32_range.contains(&max) && min < max) {
        r.report(
            Code::ParameterLimits,
            line_of(&spec.max),
            format!("the axis of `{name}` has limits {min}..{max}"),
            "give finite f32 limits, min below max, that the tuned points must keep",
        );
        return None;
    }
    match internals.iter().find(|i| i.name == spec.input.value) {
        None => {
            r.report(
                Code::ParameterShape,
                line_of(&spec.input),
                format!(
                    "the axis of `{name}` names input `{}`, which is not an internal",
                    spec.input.value
                ),
                "name the internal the firmware looks the curve up with (declare it under `internals:`)",
            );
            return None;
        }
        Some(input) if input.unit != spec.unit => {
            r.report(
                Code::ParameterShape,
                line_of(&spec.input),
                format!(
                    "the axis of `{name}` is in {} but its input `{}` in {}",
                    spec.unit, input.name, input.unit
                ),
                "give the axis its input's unit",
            );
            return None;
        }
        Some(_) => {}
    }
    let points = &axis.value.points.value;
    let increasing = points.windows(2).all(|w| matches!(w, [a, b] if a < b));
    let finite = points
        .iter()
        .all(|p| p.is_finite() && p.abs() <= f64::from(f32::MAX));
    let within = points.iter().all(|p| (min..=max).contains(p));
    if points.len() < 2 || points.len() > MAX_ELEMENTS || !increasing || !finite || !within {
        r.report(
            Code::ParameterShape,
            line_of(&axis.value.points),
            format!(
                "the axis of `{name}` is not 2 to {MAX_ELEMENTS} strictly increasing points within {min}..={max}"
            ),
            "list the input points in increasing order, each once",
        );
        return None;
    }
    Some(Axis {
        label: spec.label.clone(),
        unit: spec.unit.clone(),
        points: points.clone(),
        parameter: format!("{name}_axis"),
        input: spec.input.value.clone(),
        min,
        max,
    })
}

/// A scalar has neither elements nor an axis; a list has one of them, as long as its default.
fn check_shape(
    r: &mut Reporter<'_>,
    p: &ParameterSpec,
    scalar: bool,
    defaults: &[f64],
    bad_axis: bool,
) -> bool {
    let name = &p.name.value;
    let line = line_of(&p.default);
    let expected = match (&p.elements, &p.axis) {
        (Some(_), Some(_)) => {
            r.report(
                Code::ParameterShape,
                line,
                format!("`{name}` has both `elements` and an `axis`"),
                "a curve's elements are its axis points: keep one of them",
            );
            return false;
        }
        (Some(elements), None) => Some(elements.value.len()),
        (None, Some(axis)) => Some(axis.value.points.value.len()),
        (None, None) => None,
    };
    match (scalar, expected) {
        (true, None) => true,
        (true, Some(_)) => {
            r.report(
                Code::ParameterShape,
                line,
                format!("`{name}` declares a list but its default is one number"),
                "give one default per element (a list in brackets)",
            );
            false
        }
        (false, None) => {
            r.report(
                Code::ParameterShape,
                line,
                format!("`{name}` has a list default but neither `elements` nor an `axis`"),
                "name its elements (`elements: [at rest, at full travel]`) or give it an axis",
            );
            false
        }
        (false, Some(_)) if bad_axis => false,
        (false, Some(count)) if count != defaults.len() || count == 0 || count > MAX_ELEMENTS => {
            r.report(
                Code::ParameterShape,
                line,
                format!(
                    "`{name}` has {} defaults for {count} elements",
                    defaults.len()
                ),
                format!("give one default per element (1 to {MAX_ELEMENTS})"),
            );
            false
        }
        (false, Some(_)) => true,
    }
}

fn check_defaults(
    r: &mut Reporter<'_>,
    p: &ParameterSpec,
    element: ElementType,
    defaults: &[f64],
    (min, max): (f64, f64),
) -> bool {
    let name = &p.name.value;
    let line = line_of(&p.default);
    for (index, value) in defaults.iter().enumerate() {
        let whole = !element.is_integer() || value.fract() == 0.0;
        if !(value.is_finite() && (min..=max).contains(value) && whole) {
            r.report(
                Code::ParameterDefault,
                line,
                format!("`{name}`'s default {value} (element {index}) is outside {min}..={max}"),
                format!(
                    "keep the default within the limits{}",
                    if element.is_integer() {
                        ", a whole number"
                    } else {
                        ""
                    }
                ),
            );
            return false;
        }
    }
    if p.increasing && !defaults.windows(2).all(|w| matches!(w, [a, b] if a < b)) {
        r.report(
            Code::ParameterDefault,
            line,
            format!("`{name}` must increase but its defaults do not"),
            "list each element above the one before",
        );
        return false;
    }
    if p.increasing && defaults.len() < 2 {
        r.report(
            Code::ParameterShape,
            line,
            format!("`{name}` is `increasing` but is not a list"),
            "drop `increasing:` or make it a list",
        );
        return false;
    }
    true
}

/// The controllers' internal values, each an f32 with a unit, limits and a description.
fn check_internals(
    r: &mut Reporter<'_>,
    internals: &Spanned<Vec<Spanned<InternalSpec>>>,
) -> Vec<Internal> {
    if internals.value.is_empty() {
        r.report(
            Code::InternalName,
            line_of(internals),
            "the calibration declares no internals".to_owned(),
            "list the controllers' values a tuner samples under `internals:` (name, unit, min, max, description)",
        );
    }
    let mut seen = HashSet::new();
    let mut checked = Vec::new();
    for spanned in &internals.value {
        let spec = &spanned.value;
        let name = spec.name.value.as_str();
        let mut ok = check_item_name(r, Code::InternalName, "internal", &spec.name, &mut seen);
        for (key, text) in [("unit", &spec.unit), ("description", &spec.description)] {
            if text.as_deref().is_none_or(|t| t.trim().is_empty()) {
                r.report(
                    Code::InternalText,
                    line_of(spanned),
                    format!("internal `{name}` has no {key}"),
                    format!(
                        "add `{key}:` (the calibration tool shows it; `1` is the unit of a ratio)"
                    ),
                );
                ok = false;
            }
        }
        let (min, max) = (spec.min.value, spec.max.value);
        let f32_range = -f64::from(f32::MAX)..=f64::from(f32::MAX);
        for (key, value, line) in [
            ("min", min, line_of(&spec.min)),
            ("max", max, line_of(&spec.max)),
        ] {
            if !f32_range.contains(&value) {
                r.report(
                    Code::InternalLimits,
                    line,
                    format!("internal `{name}`'s {key} {value} is not a value f32 holds"),
                    "give a finite number within f32's range",
                );
                ok = false;
            }
        }
        if ok && min >= max {
            r.report(
                Code::InternalLimits,
                line_of(&spec.max),
                format!("internal `{name}`'s max {max} is not above its min {min}"),
                "give the range the value is expected in, lowest first",
            );
            ok = false;
        }
        if ok {
            checked.push(Internal {
                name: name.to_owned(),
                unit: spec.unit.clone().unwrap_or_default(),
                min,
                max,
                description: spec.description.clone().unwrap_or_default(),
            });
        }
    }
    checked
}
