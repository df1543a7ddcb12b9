//! What the service writes to the journal: under systemd its output is a pipe, so it must
//! carry no ANSI colour codes, and subscribers that connect and simply go away (a dashboard
//! closed, a laptop's Wi-Fi) must not show up as errors.

#![cfg(unix)]

use std::io::Read;
use std::net::TcpListener;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("a free port")
}

fn write_configs(dir: &Path, port: u16) -> std::path::PathBuf {
    let broker = dir.join("rumqttd.toml");
    let template =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("config/rumqttd.toml"))
            .expect("the bundled broker config");
    std::fs::write(
        &broker,
        template.replace("127.0.0.1:1883", &format!("127.0.0.1:{port}")),
    )
    .expect("broker config");
    let config = dir.join("aer-raspi.toml");
    std::fs::write(
        &config,
        format!(
            "[mqtt]\nport = {port}\n[broker]\nconfig = \"{}\"\n[store]\npath = \"{}\"\n[raw_log]\ndir = \"{}\"\n",
            broker.display(),
            dir.join("store.sqlite").display(),
            dir.join("raw").display()
        ),
    )
    .expect("config");
    config
}

#[test]
fn piped_output_has_no_colour_codes_and_subscribers_leaving_are_not_errors() {
    let dir = tempfile::tempdir().expect("temp dir");
    let port = free_port();
    let config = write_configs(dir.path(), port);
    let mut service = Command::new(env!("CARGO_BIN_EXE_aer-raspi"))
        .arg("--config")
        .arg(&config)
        .args(["replay", "--loop"])
        .env_remove("RUST_LOG")
        .env_remove("NO_COLOR")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start aer-raspi");

    // Five subscribers, one after the other, each taking one packet and leaving.
    let deadline = Instant::now() + Duration::from_secs(120);
    let mut received = 0;
    while received < 5 {
        assert!(
            Instant::now() < deadline,
            "no telemetry reached a subscriber"
        );
        let out = Command::new("mosquitto_sub")
            .args(["-h", "127.0.0.1", "-p", &port.to_string()])
            .args(["-t", "aer/+/telemetry", "-C", "1", "-W", "10"])
            .output()
            .expect("mosquitto_sub (Debian: mosquitto-clients)");
        if out.status.success() && !out.stdout.is_empty() {
            received += 1;
        }
    }
    // Every topic's description is retained: a late subscriber finds labels and units.
    let topics = aer::mqtt::SUFFIXES.len();
    let schemas = Command::new("mosquitto_sub")
        .args(["-h", "127.0.0.1", "-p", &port.to_string(), "-v"])
        .args([
            "-t",
            "aer/+/schema/#",
            "-C",
            &topics.to_string(),
            "-W",
            "10",
        ])
        .output()
        .expect("mosquitto_sub");
    let schemas = String::from_utf8_lossy(&schemas.stdout);
    assert_eq!(schemas.lines().count(), topics, "{schemas}");
    let mcu1 = schemas
        .lines()
        .find(|l| l.contains("/schema/can/mcu1 "))
        .expect("the description of can/mcu1");
    assert!(
        mcu1.contains("\"unit\":\"rpm\"") && mcu1.contains("\"title\":\"Motor speed\""),
        "{mcu1}"
    );
    let status = Command::new("kill")
        .args(["-TERM", &service.id().to_string()])
        .status()
        .expect("kill");
    assert!(status.success());
    let mut log = String::new();
    service
        .stdout
        .take()
        .expect("stdout")
        .read_to_string(&mut log)
        .expect("read stdout");
    service
        .stderr
        .take()
        .expect("stderr")
        .read_to_string(&mut log)
        .expect("read stderr");
    let exit = service.wait().expect("wait");
    assert!(exit.success(), "exit {exit}; log:\n{log}");
    assert!(
        log.contains("MQTT listener open"),
        "the log is empty:\n{log}"
    );
    assert!(
        !log.contains('\u{1b}'),
        "ANSI escape codes in piped output:\n{log}"
    );
    let errors: Vec<&str> = log.lines().filter(|l| l.contains("ERROR")).collect();
    assert!(
        errors.is_empty(),
        "errors for normal client comings and goings:\n{}",
        errors.join("\n")
    );
}
