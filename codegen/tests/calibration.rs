//! The calibration schema: the car's file lays out every tuned number in one page, declares
//! the controllers' internals and the XCP slave's settings, its fingerprint follows the layout
//! (not the file's formatting), and every mistake a student can make in it is reported with its
//! code, its line and what to do.

use std::path::{Path, PathBuf};

use aer_codegen::diagnostic::{Diagnostic, Diagnostics};
use aer_codegen::model::{Calibration, ChangeWhen, Database, ElementType};
use aer_codegen::{CarSchema, calibration_fingerprint};

fn schema_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../schema")
}

fn car_yaml() -> String {
    std::fs::read_to_string(schema_dir().join("calibration.yaml")).expect("calibration.yaml")
}

fn car_dbc_text() -> String {
    std::fs::read_to_string(schema_dir().join("aer.dbc")).expect("aer.dbc")
}

fn dbc(text: String) -> Database {
    aer_codegen::parse_dbc(Path::new("aer.dbc"), text, &[])
        .expect("a valid DBC")
        .0
}

/// `yaml` checked against the car's DBC.
fn parse_calibration(
    path: &Path,
    yaml: String,
) -> Result<(Calibration, Vec<Diagnostic>), Diagnostics> {
    aer_codegen::parse_calibration(path, yaml, &dbc(car_dbc_text()))
}

/// What every calibration file declares besides its parameters: an internal and the XCP
/// settings of the car's DBC.
const INTERNALS_AND_XCP: &str = "internals:\n  - { name: x, unit: V, min: 0, max: 1, description: X. }\n\
xcp:\n  bus: inverter\n  command_message: XCP_Cmd\n  response_message: XCP_Res\n  tcp_port: 5555\n  \
max_daq: 4\n  odt_entries: 64\n  max_odt_entry_size: 4\n  idle_timeout_s: 60\n  unlock_delay_s: 1\n  \
unlock_delay_max_s: 300\n  events:\n    \
- { name: control, period_ms: 10, description: After each step. }\n";

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
    assert_eq!(change("shock_compressed_v"), ChangeWhen::TractiveOff);
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
    let yaml = format!(
        "calibration: {{ name: ccm }}\nparameters:\n  - {{ name: teeth, label: Teeth, group: wheels, \
         type: u8, unit: teeth, default: 24, min: 1, max: 255, change: tractive_off, \
         description: Encoder teeth. }}\n{INTERNALS_AND_XCP}"
    );
    let (c, _) = parse_calibration(path, yaml.clone()).expect("valid");
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
            "the axis of `launch_slip_target` is not 2 to 32 strictly increasing points within 0..=40",
        ),
        (
            "      input: front_wheel_speed\n",
            "      input: wheel_speed\n",
            "E0305",
            "the axis of `launch_slip_target` names input `wheel_speed`, which is not an internal",
        ),
        (
            "      input: front_wheel_speed\n",
            "      input: slip_ratio\n",
            "E0305",
            "the axis of `launch_slip_target` is in m/s but its input `slip_ratio` in 1",
        ),
        (
            "      points: [0, 5, 10, 20]\n",
            "      points: [0, 5, 10, 50]\n",
            "E0305",
            "the axis of `launch_slip_target` is not 2 to 32 strictly increasing points within 0..=40",
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
        // The internals.
        (
            "  - name: launch_torque_nm\n",
            "  - name: driver_torque_nm\n",
            "E0310",
            "internal `driver_torque_nm` is declared twice",
        ),
        (
            "  - name: slip_ratio\n",
            "  - name: match\n",
            "E0310",
            "internal name `match` is a Rust keyword",
        ),
        (
            "  - name: slip_ratio\n",
            "  - name: SlipRatio\n",
            "E0310",
            "internal name `SlipRatio` is not a snake_case identifier",
        ),
        (
            "    min: -1\n    max: 5\n",
            "    min: -1\n    max: -2\n",
            "E0311",
            "internal `slip_ratio`'s max -2 is not above its min -1",
        ),
        (
            "    min: -260\n",
            "    min: -1e39\n",
            "E0311",
            "is not a value f32 holds",
        ),
        (
            "    unit: Nm\n    min: -260\n",
            "    min: -260\n",
            "E0312",
            "internal `torque_command_nm` has no unit",
        ),
        (
            "    description: The power monitor's efficiency bound.\n",
            "    description: \"\"\n",
            "E0312",
            "internal `monitor_efficiency` has no description",
        ),
        // The XCP slave.
        (
            "  command_message: XCP_Cmd\n",
            "  command_message: XCP_Command\n",
            "E0313",
            "the XCP command message `XCP_Command` is not in the DBC",
        ),
        (
            "  command_message: XCP_Cmd\n",
            "  command_message: DTI_Control\n",
            "E0313",
            "the XCP command message `DTI_Control` has an extended id",
        ),
        (
            "  response_message: XCP_Res\n",
            "  response_message: XCP_Cmd\n",
            "E0313",
            "`XCP_Cmd` is both the command and the response message",
        ),
        (
            "  bus: inverter\n",
            "  bus: vehicle\n",
            "E0313",
            "the XCP command message `XCP_Cmd` is not sent on bus `vehicle`",
        ),
        (
            "  tcp_port: 5555\n",
            "  tcp_port: 0\n",
            "E0314",
            "tcp_port 0 is not a whole number in 1..=65535",
        ),
        (
            "  tcp_port: 5555\n",
            "  tcp_port: 5555.5\n",
            "E0314",
            "tcp_port 5555.5 is not a whole number in 1..=65535",
        ),
        (
            "  max_daq: 4\n",
            "  max_daq: 300\n",
            "E0314",
            "max_daq 300 is not a whole number in 1..=252",
        ),
        (
            "  idle_timeout_s: 60\n",
            "  idle_timeout_s: 0\n",
            "E0314",
            "idle_timeout_s 0 is not a whole number in 1..=3600",
        ),
        (
            "  unlock_delay_max_s: 300\n",
            "  unlock_delay_max_s: 0.5\n",
            "E0314",
            "unlock_delay_max_s 0.5 is not a whole number in 1..=3600",
        ),
        (
            "  unlock_delay_s: 1\n  unlock_delay_max_s: 300\n",
            "  unlock_delay_s: 60\n  unlock_delay_max_s: 30\n",
            "E0314",
            "unlock_delay_max_s 30 is below unlock_delay_s 60",
        ),
        (
            "  odt_entries: 64\n",
            "  odt_entries: 2\n",
            "E0314",
            "odt_entries 2 is below max_daq 4",
        ),
        (
            "  max_odt_entry_size: 4\n",
            "  max_odt_entry_size: 8\n",
            "E0314",
            "max_odt_entry_size 8 is not a whole number in 4..=7",
        ),
        (
            "    - name: sensors\n",
            "    - name: control\n",
            "E0315",
            "event `control` is declared twice",
        ),
        (
            "    - name: sensors\n",
            "    - name: type\n",
            "E0315",
            "event name `type` is a Rust keyword",
        ),
        (
            "      period_ms: 10\n",
            "      period_ms: 0\n",
            "E0315",
            "event `control`'s period_ms 0 is not a period an A2L event states",
        ),
        (
            "      period_ms: 1\n",
            "      period_ms: 257\n",
            "E0315",
            "event `sensors`'s period_ms 257 is not a period an A2L event states",
        ),
        (
            "      description: after each sensor sample\n",
            "      description: \" \"\n",
            "E0315",
            "event `sensors` has no description",
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
            .rposition(|l| l.trim_start().starts_with("- name: "))
            .map(|i| i + 1)
            .expect("its parameter");
        assert!(
            d.line == at || d.line == owner,
            "{to:?}: reported at line {}, the edit is at {at} (parameter at {owner}): {d}",
            d.line
        );
    }
}

#[test]
fn the_cars_calibration_declares_its_internals_and_xcp_slave() {
    let schema = CarSchema::load(&schema_dir()).expect("the car's schema");
    let c = &schema.calibration;
    let names: Vec<&str> = c.internals.iter().map(|i| i.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "driver_torque_nm",
            "launch_torque_nm",
            "launch_slip_target",
            "front_wheel_speed",
            "traction_torque_nm",
            "slip_ratio",
            "power_allowed_nm",
            "power_efficiency",
            "monitor_efficiency",
            "torque_command_nm",
        ]
    );
    assert_eq!(c.internals_len(), 40);
    for i in &c.internals {
        assert!(i.min < i.max && !i.unit.is_empty() && !i.description.is_empty());
    }
    let x = &c.xcp;
    assert_eq!((x.can_id_master, x.can_id_slave), (0x6F0, 0x6F1));
    assert_eq!((x.bit_rate, x.response_cycle_ms), (500_000, 4));
    assert_eq!(x.bus.as_deref(), Some("inverter"));
    assert_eq!(
        (x.tcp_port, x.max_daq, x.odt_entries, x.max_odt_entry_size),
        (5555, 4, 64, 4)
    );
    // The session's ends and the wrong-key delay, as the A2L and the slave state them.
    assert_eq!(
        (x.idle_timeout_ms, x.unlock_delay_ms, x.unlock_delay_max_ms),
        (60_000, 1_000, 300_000)
    );
    let events: Vec<(&str, u32)> = x
        .events
        .iter()
        .map(|e| (e.name.as_str(), e.period_us))
        .collect();
    assert_eq!(events, [("control", 10_000), ("sensors", 1_000)]);
    // As the A2L states them and the slave's GET_DAQ_EVENT_INFO answers: the finest unit
    // (code 3 = 1 us, 4 = 10 us, 5 = 100 us) that holds the period in at most 255.
    assert_eq!(x.events[0].time_cycle(), Some((100, 5)));
    assert_eq!(x.events[1].time_cycle(), Some((100, 4)));
    assert_eq!(aer_codegen::model::time_cycle(255), Some((255, 3)));
    assert_eq!(aer_codegen::model::time_cycle(257_000), None);
}

#[test]
fn the_fingerprint_follows_the_internals_and_the_xcp_settings() {
    let path = Path::new("calibration.yaml");
    let yaml = car_yaml();
    let (car, _) = parse_calibration(path, yaml.clone()).expect("the car's calibration");
    let fingerprint = |edited: String| {
        assert_ne!(edited, yaml, "fixture moved");
        calibration_fingerprint(&parse_calibration(path, edited).expect("still valid").0)
    };
    // What a tool's description must agree on changes it ...
    for (from, to) in [
        ("  - name: slip_ratio\n", "  - name: slip_estimate\n"),
        ("    min: -1\n    max: 5\n", "    min: -1\n    max: 6\n"),
        ("  tcp_port: 5555\n", "  tcp_port: 5556\n"),
        ("  max_daq: 4\n", "  max_daq: 3\n"),
        ("      period_ms: 1\n", "      period_ms: 2\n"),
        ("  idle_timeout_s: 60\n", "  idle_timeout_s: 30\n"),
    ] {
        assert_ne!(
            fingerprint(yaml.replacen(from, to, 1)),
            calibration_fingerprint(&car),
            "{to:?}"
        );
    }
    // ... words do not.
    let reworded = yaml.replacen(
        "      description: after each sensor sample\n",
        "      description: after every sensor sample\n",
        1,
    );
    assert_eq!(fingerprint(reworded), calibration_fingerprint(&car));
}

/// The car's calibration with the block from `start` up to `end` (or the end of the file)
/// replaced by `with`.
fn with_block(start: &str, end: Option<&str>, with: &str) -> String {
    let yaml = car_yaml();
    let from = yaml.find(start).expect("block start");
    let to = end.map_or(yaml.len(), |end| {
        from + yaml[from..].find(end).expect("block end")
    });
    format!("{}{with}{}", &yaml[..from], &yaml[to..])
}

fn first(diags: &Diagnostics, code: &str) -> Diagnostic {
    diags
        .0
        .iter()
        .find(|d| d.code == code)
        .cloned()
        .unwrap_or_else(|| panic!("no {code}: {diags}"))
}

#[test]
fn a_calibration_without_internals_or_events_is_refused_at_its_line() {
    let path = Path::new("calibration.yaml");
    let yaml = with_block("internals:\n", Some("\n# --- XCP"), "internals: []\n");
    let line = yaml
        .lines()
        .position(|l| l == "internals: []")
        .expect("edited")
        + 1;
    let diags = parse_calibration(path, yaml).expect_err("no internals");
    let d = first(&diags, "E0310");
    assert!(d.message.contains("declares no internals"), "{d}");
    assert_eq!(d.line, line, "{d}");

    let yaml = with_block("  events:\n", None, "  events: []\n");
    let line = yaml
        .lines()
        .position(|l| l == "  events: []")
        .expect("edited")
        + 1;
    let diags = parse_calibration(path, yaml).expect_err("no events");
    let d = first(&diags, "E0315");
    assert!(d.message.contains("has no events"), "{d}");
    assert_eq!(d.line, line, "{d}");

    // Both blocks are required: a file without them does not parse.
    let yaml = with_block("\n# --- Internals", Some("\n# --- XCP"), "\n");
    let diags = parse_calibration(path, yaml).expect_err("no internals block");
    assert!(
        first(&diags, "E0302").message.contains("internals"),
        "{diags}"
    );
}

#[test]
fn xcp_messages_the_slave_cannot_use_are_refused_at_their_line() {
    let path = Path::new("calibration.yaml");
    let yaml = car_yaml();
    let response_line = yaml
        .lines()
        .position(|l| l == "  response_message: XCP_Res")
        .expect("response_message")
        + 1;
    let command_line = response_line - 1;
    let text = car_dbc_text();
    for (from, to, message, line) in [
        (
            "BO_ 1777 XCP_Res: 8 CCM",
            "BO_ 1777 XCP_Res: 6 CCM",
            "the XCP response message `XCP_Res` is 6 bytes",
            response_line,
        ),
        (
            "BA_ \"GenMsgCycleTime\" BO_ 1777 4;\n",
            "",
            "response message `XCP_Res` has no cycle time",
            response_line,
        ),
        (
            "BA_ \"Baudrate\" 500000;\n",
            "",
            "the DBC gives no bit rate",
            command_line,
        ),
    ] {
        assert!(text.contains(from), "fixture moved: {from}");
        let db = dbc(text.replacen(from, to, 1));
        let diags = aer_codegen::parse_calibration(path, yaml.clone(), &db).expect_err(message);
        let d = first(&diags, "E0313");
        assert!(d.message.contains(message), "{d}");
        assert_eq!(d.line, line, "{d}");
        assert!(!d.help.is_empty());
    }
}
