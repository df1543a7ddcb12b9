//! The calibration schema: the car's file lays out every tuned number in one page, its
//! fingerprint follows the layout (not the file's formatting), and every mistake a student can
//! make in it is reported with its code, its line and what to do.

use std::path::{Path, PathBuf};

use aer_codegen::model::{ChangeWhen, ElementType};
use aer_codegen::{CarSchema, calibration_fingerprint, parse_calibration};

fn schema_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../schema")
}

fn car_yaml() -> String {
    std::fs::read_to_string(schema_dir().join("calibration.yaml")).expect("calibration.yaml")
}

#[test]
fn the_cars_calibration_lays_out_every_tuned_number_in_one_page() {
    let schema = CarSchema::load(&schema_dir()).expect("the car's schema");
    let c = &schema.calibration;
    assert_eq!(c.name, "ccm");
    let mut end = 0;
    for p in &c.parameters {
        assert_eq!(p.offset % p.element.size(), 0, "{} is aligned", p.name);
        assert!(
            p.offset >= end,
            "{} overlaps the parameter before it",
            p.name
        );
        end = p.offset + p.len();
        for value in &p.defaults {
            assert!(
                (p.min..=p.max).contains(value),
                "{}: default {value}",
                p.name
            );
        }
        assert!(!p.label.is_empty() && !p.unit.is_empty() && !p.description.is_empty());
    }
    assert_eq!(c.page_len, end);
    // The tuned numbers the team's focus areas name, each with the condition it changes under.
    let change = |name: &str| {
        c.parameters
            .iter()
            .find(|p| p.name == name)
            .map(|p| p.change)
            .unwrap_or_else(|| panic!("no parameter {name}"))
    };
    assert_eq!(change("launch_slip_target"), ChangeWhen::Standstill);
    assert_eq!(change("traction_slip_threshold"), ChangeWhen::Driving);
    assert_eq!(change("power_trim_gain"), ChangeWhen::Driving);
    assert_eq!(change("apps1_v"), ChangeWhen::TractiveOff);
    assert_eq!(change("brake_zero_v"), ChangeWhen::TractiveOff);
    assert_eq!(change("shock_span_v"), ChangeWhen::TractiveOff);
    let curve = c
        .parameters
        .iter()
        .find(|p| p.name == "launch_slip_target")
        .and_then(|p| p.axis.as_ref())
        .expect("the launch slip target is a curve over speed");
    assert_eq!(curve.unit, "m/s");
}

#[test]
fn the_fingerprint_follows_the_layout_not_the_formatting() {
    let path = Path::new("calibration.yaml");
    let yaml = car_yaml();
    let (car, _) = parse_calibration(path, yaml.clone()).expect("the car's calibration");
    // Comments and descriptions are not the layout.
    let reworded: String = yaml
        .lines()
        .filter(|l| !l.trim_start().starts_with('#'))
        .map(|l| {
            if l.starts_with("    label:") {
                "    label: Renamed"
            } else {
                l
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    let (same, _) = parse_calibration(path, reworded).expect("still valid");
    assert_eq!(
        calibration_fingerprint(&car),
        calibration_fingerprint(&same)
    );
    // A new limit is: a saved page may not keep it.
    let edited = yaml.replacen("    max: 0.25\n", "    max: 0.3\n", 1);
    assert_ne!(edited, yaml, "fixture moved");
    let (changed, _) = parse_calibration(path, edited).expect("still valid");
    assert_ne!(
        calibration_fingerprint(&car),
        calibration_fingerprint(&changed)
    );
}

#[test]
fn an_integer_parameter_takes_only_whole_numbers_within_its_type() {
    let path = Path::new("calibration.yaml");
    let yaml = "calibration: { name: ccm }\nparameters:\n  - { name: teeth, label: Teeth, group: wheels, \
                type: u8, unit: teeth, default: 24, min: 1, max: 255, change: tractive_off, \
                description: Encoder teeth. }\n";
    let (c, _) = parse_calibration(path, yaml.into()).expect("valid");
    assert_eq!(c.parameters[0].element, ElementType::U8);
    assert_eq!(c.page_len, 1);
    for (from, to, text) in [
        ("max: 255", "max: 256", "max 256 is not a value u8 holds"),
        (
            "default: 24",
            "default: 24.5",
            "default 24.5 (element 0) is outside",
        ),
        ("min: 1", "min: -1", "min -1 is not a value u8 holds"),
    ] {
        let Err(diags) = parse_calibration(path, yaml.replacen(from, to, 1)) else {
            panic!("{to} was accepted");
        };
        assert!(
            diags.0.iter().any(|d| d.message.contains(text)),
            "{to}: {diags}"
        );
    }
}

#[test]
fn calibration_mistakes_are_reported_with_lines() {
    let yaml = car_yaml();
    let path = Path::new("calibration.yaml");
    // (from, to, code, message): the line reported is the first line of `to`, unless the
    // finding concerns the whole parameter (its `- name:` line).
    let cases = [
        (
            "  - name: launch_ki\n",
            "  - name: launch_kp\n",
            "E0303",
            "`launch_kp` is declared twice",
        ),
        (
            "  - name: launch_kp\n",
            "  - name: Launch_kp\n",
            "E0303",
            "`Launch_kp` is not a snake_case identifier",
        ),
        (
            "  - name: launch_kp\n",
            "  - name: loop\n",
            "E0303",
            "`loop` is a Rust keyword",
        ),
        (
            "    type: f32\n    unit: Nm\n    default: 200\n",
            "    type: f64\n    unit: Nm\n    default: 200\n",
            "E0304",
            "unknown parameter type `f64`",
        ),
        (
            "    default: [0.02, 0.03]\n",
            "    default: [0.02, 0.03, 0.04]\n",
            "E0305",
            "`launch_slip_band` has 3 defaults for 2 elements",
        ),
        (
            "      points: [0, 5, 10, 20]\n",
            "      points: [0, 10, 5, 20]\n",
            "E0305",
            "the axis of `launch_slip_target` is not 2 to 32 finite, strictly increasing points",
        ),
        (
            "    default: 200\n    min: 0\n    max: 2000\n",
            "    default: 200\n    min: 0\n    max: -1\n",
            "E0306",
            "max -1 is not above min 0",
        ),
        (
            "    default: 0.3\n",
            "    default: 1.3\n",
            "E0307",
            "`pump_base_duty`'s default 1.3 (element 0) is outside 0.2..=1",
        ),
        (
            "    default: [40, 60]\n",
            "    default: [60, 40]\n",
            "E0307",
            "`pump_ramp_degc` must increase but its defaults do not",
        ),
        (
            "    change: driving\n",
            "    change: whenever\n",
            "E0308",
            "unknown change condition `whenever`",
        ),
        (
            "    unit: 1/s\n",
            "    unit: \"\"\n",
            "E0309",
            "parameter `power_trim_gain` has no unit",
        ),
        (
            "    change: standstill\n",
            "    chnage: standstill\n",
            "E0302",
            "chnage",
        ),
    ];
    for (from, to, code, text) in cases {
        assert!(yaml.contains(from), "fixture moved: {from}");
        let edited = yaml.replacen(from, to, 1);
        let Err(diags) = parse_calibration(path, edited.clone()) else {
            panic!("{to:?} was accepted");
        };
        let d = diags
            .0
            .iter()
            .find(|d| d.code == code)
            .unwrap_or_else(|| panic!("no {code} for {to:?}: {diags}"));
        assert!(d.message.contains(text), "{to:?}: {d}");
        assert!(!d.help.is_empty(), "{to:?}: a finding says what to do");
        if code == "E0302" {
            continue;
        }
        // The line the edit is on, or the parameter's own line for findings about it whole.
        let edited_lines: Vec<&str> = edited.lines().collect();
        // The first line the edit changed.
        let at = edited_lines
            .iter()
            .zip(yaml.lines())
            .position(|(edited, original)| edited != &original)
            .map(|i| i + 1)
            .expect("the edited line");
        let owner = edited_lines[..at]
            .iter()
            .rposition(|l| l.starts_with("  - name: "))
            .map(|i| i + 1)
            .expect("its parameter");
        assert!(
            d.line == at || d.line == owner,
            "{to:?}: reported at line {}, the edit is at {at} (parameter at {owner}): {d}",
            d.line
        );
    }
}
