//! Layouts for the tools people open the session's MCAP in, generated from the schema beside
//! `session.mcap`: `foxglove-layout.json` (Foxglove: Layouts > Import from file) and
//! `plotjuggler-layout.xml` (PlotJuggler: File > Load layout, after loading the MCAP). Four
//! tabs: driver inputs, powertrain, temperatures, faults; a field added to the schema lands in
//! its tab by its group, unit and type.

use super::mcap::topic;
use super::{ExportError, Written};
use crate::markup::escape;
use aer::runtime::SignalMeta;
use aer::telemetry::Telemetry;
use serde_json::{Value, json};
use std::fmt::Write as _;
use std::path::Path;

/// One plot: a title and the telemetry fields it draws.
#[derive(Debug, Clone, PartialEq)]
pub struct Plot {
    pub title: String,
    pub fields: Vec<&'static str>,
    /// Flags and states (drawn as state transitions where the tool can).
    pub states: bool,
}

/// One tab and its plots.
#[derive(Debug, Clone, PartialEq)]
pub struct Tab {
    pub title: &'static str,
    pub plots: Vec<Plot>,
}

fn is_state(meta: &SignalMeta) -> bool {
    meta.len == 1 || !meta.labels.is_empty()
}

/// The tabs, from the telemetry's fields: driver inputs (the pedals and the torque asked
/// for), powertrain (motor, inverter, accumulator; a plot per unit), temperatures (every
/// field in degC), faults (the vehicle state and every fault or limit flag).
pub fn tabs() -> Vec<Tab> {
    let fields: Vec<(&SignalMeta, &'static str)> = Telemetry::FIELDS
        .iter()
        .zip(Telemetry::DISPLAY)
        .map(|(meta, display)| (meta, display.group))
        .collect();
    let by_unit = |groups: &[&str], skip: &dyn Fn(&SignalMeta) -> bool| -> Vec<Plot> {
        let mut plots: Vec<Plot> = Vec::new();
        for (meta, group) in &fields {
            if !groups.contains(group) || is_state(meta) || skip(meta) {
                continue;
            }
            let title = format!("{} ({})", group, meta.unit);
            match plots.iter_mut().find(|p| p.title == title) {
                Some(plot) => plot.fields.push(meta.name),
                None => plots.push(Plot {
                    title,
                    fields: vec![meta.name],
                    states: false,
                }),
            }
        }
        plots
    };
    let mut driver = by_unit(&["pedals"], &|_| false);
    driver.push(Plot {
        title: "torque asked for (Nm)".into(),
        fields: fields
            .iter()
            .filter(|(m, _)| m.name == "torque_command")
            .map(|(m, _)| m.name)
            .collect(),
        states: false,
    });
    let temperatures = Plot {
        title: "temperatures (degC)".into(),
        fields: fields
            .iter()
            .filter(|(m, _)| m.unit == "degC")
            .map(|(m, _)| m.name)
            .collect(),
        states: false,
    };
    let faults = Plot {
        title: "vehicle state, faults and limits".into(),
        fields: fields
            .iter()
            .filter(|(m, group)| {
                m.name == "vehicle_state"
                    || (is_state(m) && (group.ends_with("_faults") || group.ends_with("_limits")))
            })
            .map(|(m, _)| m.name)
            .collect(),
        states: true,
    };
    vec![
        Tab {
            title: "Driver inputs",
            plots: driver,
        },
        Tab {
            title: "Powertrain",
            plots: by_unit(&["motor", "inverter", "accumulator"], &|m| m.unit == "degC"),
        },
        Tab {
            title: "Temperatures",
            plots: vec![temperatures],
        },
        Tab {
            title: "Faults",
            plots: vec![faults],
        },
    ]
    .into_iter()
    .map(|mut tab| {
        tab.plots.retain(|p| !p.fields.is_empty());
        tab
    })
    .collect()
}

/// Writes both layouts for the MCAP whose topics are below `topic_root`.
pub fn write(dir: &Path, topic_root: &str) -> Result<Vec<Written>, ExportError> {
    std::fs::create_dir_all(dir).map_err(|e| ExportError::write(dir, e))?;
    let telemetry = topic(topic_root, "telemetry");
    let tabs = tabs();
    let mut written = Vec::new();
    let foxglove = dir.join("foxglove-layout.json");
    let text = serde_json::to_string_pretty(&foxglove_layout(&telemetry, &tabs))
        .map_err(|_| ExportError::Internal("a layout is always JSON"))?;
    std::fs::write(&foxglove, text).map_err(|e| ExportError::write(&foxglove, e))?;
    written.push(Written::file(&foxglove, 0)?);
    let plotjuggler = dir.join("plotjuggler-layout.xml");
    std::fs::write(&plotjuggler, plotjuggler_layout(&telemetry, &tabs))
        .map_err(|e| ExportError::write(&plotjuggler, e))?;
    written.push(Written::file(&plotjuggler, 0)?);
    Ok(written)
}

/// A Foxglove layout: a Tab panel, each tab a column of Plot (or State Transitions) panels,
/// each path `<topic>.<field>` on the message's receive time.
pub fn foxglove_layout(telemetry: &str, tabs: &[Tab]) -> Value {
    let mut config = serde_json::Map::new();
    let mut tab_configs = Vec::new();
    for (t, tab) in tabs.iter().enumerate() {
        let mut ids = Vec::new();
        for (p, plot) in tab.plots.iter().enumerate() {
            let kind = if plot.states {
                "StateTransitions"
            } else {
                "Plot"
            };
            let id = format!("{kind}!t{t}p{p}");
            let paths: Vec<Value> = plot
                .fields
                .iter()
                .map(|field| {
                    json!({
                        "value": format!("{telemetry}.{field}"),
                        "enabled": true,
                        "timestampMethod": "receiveTime",
                    })
                })
                .collect();
            config.insert(
                id.clone(),
                json!({
                    "foxglovePanelTitle": plot.title,
                    "paths": paths,
                    "showLegend": true,
                    "isSynced": true,
                }),
            );
            ids.push(id);
        }
        tab_configs.push(json!({"title": tab.title, "layout": mosaic(&ids)}));
    }
    config.insert(
        "Tab!aer".into(),
        json!({"activeTabIdx": 0, "tabs": tab_configs}),
    );
    json!({
        "configById": config,
        "globalVariables": {},
        "userNodes": {},
        "playbackConfig": {"speed": 1},
        "layout": "Tab!aer",
    })
}

/// Panels stacked in a column, split evenly.
fn mosaic(ids: &[String]) -> Value {
    match ids {
        [] => Value::Null,
        [only] => json!(only),
        [first, rest @ ..] => json!({
            "first": first,
            "second": mosaic(rest),
            "direction": "column",
            "splitPercentage": 100.0 / ids.len() as f64,
        }),
    }
}

/// A PlotJuggler layout: a tab per [`Tab`], its plots stacked, each curve
/// `<topic>/<field>` as PlotJuggler names the JSON messages' fields.
pub fn plotjuggler_layout(telemetry: &str, tabs: &[Tab]) -> String {
    const COLORS: [&str; 6] = [
        "#1f77b4", "#d62728", "#1ac938", "#ff7f0e", "#f14cc1", "#9467bd",
    ];
    let mut out = String::from(
        "<?xml version='1.0' encoding='UTF-8'?>\n<root>\n <tabbed_widget name=\"Main Window\" parent=\"main_window\">\n",
    );
    for tab in tabs {
        let count = tab.plots.len().max(1);
        let sizes = vec![format!("{:.6}", 1.0 / count as f64); count].join(";");
        let _ = writeln!(
            out,
            "  <Tab tab_name=\"{}\" containers=\"1\">\n   <Container>\n    <DockSplitter orientation=\"-\" count=\"{count}\" sizes=\"{sizes}\">",
            escape(tab.title)
        );
        for plot in &tab.plots {
            let _ = writeln!(
                out,
                "     <DockArea name=\"{}\">\n      <plot mode=\"TimeSeries\" style=\"{}\" flip_x=\"false\" flip_y=\"false\">\n       <range left=\"0\" right=\"1\" top=\"1\" bottom=\"0\"/>\n       <limitY/>",
                escape(&plot.title),
                if plot.states { "Steps" } else { "Lines" }
            );
            for (i, field) in plot.fields.iter().enumerate() {
                let _ = writeln!(
                    out,
                    "       <curve name=\"{}/{field}\" color=\"{}\"/>",
                    escape(telemetry),
                    COLORS[i % COLORS.len()]
                );
            }
            out.push_str("      </plot>\n     </DockArea>\n");
        }
        out.push_str("    </DockSplitter>\n   </Container>\n  </Tab>\n");
    }
    out.push_str("  <currentTabIndex index=\"0\"/>\n </tabbed_widget>\n <use_relative_time_offset enabled=\"1\"/>\n <previouslyLoaded_Datafiles>\n  <fileInfo filename=\"session.mcap\" prefix=\"\">\n   <selected_datasources value=\"\"/>\n  </fileInfo>\n </previouslyLoaded_Datafiles>\n</root>\n");
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_tab_draws_fields_of_the_telemetry_and_every_section_is_there() {
        let tabs = tabs();
        let titles: Vec<&str> = tabs.iter().map(|t| t.title).collect();
        assert_eq!(
            titles,
            ["Driver inputs", "Powertrain", "Temperatures", "Faults"]
        );
        let names: Vec<&str> = Telemetry::FIELDS.iter().map(|f| f.name).collect();
        for tab in &tabs {
            assert!(!tab.plots.is_empty(), "{}", tab.title);
            for plot in &tab.plots {
                for field in &plot.fields {
                    assert!(names.contains(field), "{field}");
                }
            }
        }
        let all: Vec<&str> = tabs
            .iter()
            .flat_map(|t| t.plots.iter().flat_map(|p| p.fields.iter().copied()))
            .collect();
        for expected in ["apps_travel", "motor_speed", "motor_temp", "vehicle_state"] {
            assert!(all.contains(&expected), "{expected}");
        }
    }

    #[test]
    fn the_foxglove_layout_names_each_panel_it_places() {
        let layout = foxglove_layout("aer/car1/telemetry", &tabs());
        let config = layout["configById"].as_object().expect("panels");
        let tabs = config["Tab!aer"]["tabs"].as_array().expect("tabs");
        let mut placed = Vec::new();
        fn collect(node: &Value, into: &mut Vec<String>) {
            match node {
                Value::String(id) => into.push(id.clone()),
                Value::Object(split) => {
                    collect(&split["first"], into);
                    collect(&split["second"], into);
                }
                _ => {}
            }
        }
        for tab in tabs {
            collect(&tab["layout"], &mut placed);
        }
        assert_eq!(placed.len(), config.len() - 1, "every panel placed once");
        for id in &placed {
            let paths = config[id]["paths"].as_array().expect("paths");
            assert!(paths.iter().all(|p| {
                p["value"]
                    .as_str()
                    .is_some_and(|v| v.starts_with("aer/car1/telemetry."))
            }));
        }
    }
}
