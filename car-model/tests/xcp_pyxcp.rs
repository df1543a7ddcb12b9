//! The CCM's XCP slave proven with a master no one on the team wrote: `pyxcp` (PyPI) plays
//! `tools/xcp_scenarios.py` over XCP on TCP against the slave running in the closed-loop car
//! model, the same slave core the firmware serves on CAN. The script asks this harness to
//! start the car, drive, power-cycle the CCM (its flash kept) or corrupt the saved copies,
//! and reports what it saw; the assertions are here.
//!
//! Needs the venv's Python with pyxcp (`.ci/run` installs it); without it the test says
//! SKIPPED, unless `AER_REQUIRE_PYTHON` is set (CI sets it), when it fails.

use aer::calibration::xcp::{CALIBRATION_ADDRESS, EPK, INTERNALS_ADDRESS, TELEMETRY_ADDRESS};
use aer::calibration::{ChangeWhen, INTERNALS, PAGE_LEN, PARAMETERS};
use aer_car_model::chassis::Mode;
use aer_car_model::driver::Cycle;
use aer_car_model::faults::{Fault, FaultPlan, Injection};
use aer_car_model::{ClosedLoop, ModelParams, NoTap, XcpCar};
use aer_ccm::calibration::Calibration;
use aer_ccm::calibration::store::{RamFlash, Slot, Startup};
use aer_ccm::launch::LaunchState;
use aer_ccm::xcp::SECRET_LEN;
use aer_xcp::MAX_CTO;
use aer_xcp::transport::{TCP_FRAME_MAX, TcpDecoder, TcpEncoder};
use serde_json::{Value, json};
use std::collections::HashMap;
use std::io::{BufRead, BufReader, ErrorKind, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc::{Receiver, TryRecvError, channel};
use std::time::Duration;

const SECRET: [u8; SECRET_LEN] = *b"the pyxcp test's secret (32 B)!!";
/// Offset of the header's sequence number in the telemetry packet (after the fingerprint).
const SEQUENCE_OFFSET: usize = 4;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The venv's Python (or `AER_PYTHON`), when it imports pyxcp.
fn python() -> Option<PathBuf> {
    let venv = root().join(".venv/bin/python");
    let python = std::env::var_os("AER_PYTHON").map_or(venv, PathBuf::from);
    let usable = Command::new(&python)
        .args(["-c", "import pyxcp, pya2l"])
        .output()
        .is_ok_and(|o| o.status.success());
    if usable {
        return Some(python);
    }
    assert!(
        std::env::var_os("AER_REQUIRE_PYTHON").is_none(),
        "AER_REQUIRE_PYTHON is set but {} cannot import pyxcp",
        python.display()
    );
    eprintln!(
        "SKIPPED: the pyxcp scenarios need {} with pyxcp \
         (python3 -m venv .venv && .venv/bin/pip install -r tools/requirements.txt)",
        python.display()
    );
    None
}

/// What the script needs to know about the schema, from the generated crate.
fn expected(dir: &Path) -> PathBuf {
    let defaults = Calibration::DEFAULT.to_page();
    let parameters: Vec<Value> = PARAMETERS
        .iter()
        .map(|p| {
            json!({
                "name": p.name,
                "address": CALIBRATION_ADDRESS + p.offset as u32,
                "count": p.count,
                "defaults": (0..p.count).map(|i| p.value(&defaults, i)).collect::<Vec<_>>(),
                "min": p.min,
                "max": p.max,
                "change": match p.change {
                    ChangeWhen::Driving => "driving",
                    ChangeWhen::Standstill => "standstill",
                    ChangeWhen::TractiveOff => "tractive_off",
                },
            })
        })
        .collect();
    let internals: Vec<Value> = INTERNALS
        .iter()
        .map(|i| json!({"name": i.name, "offset": i.offset}))
        .collect();
    let expected = json!({
        "epk": EPK,
        "a2l": root().join("generated/aer.a2l"),
        "page_len": PAGE_LEN,
        "calibration_address": CALIBRATION_ADDRESS,
        "telemetry_address": TELEMETRY_ADDRESS,
        "internals_address": INTERNALS_ADDRESS,
        "telemetry_sequence_offset": SEQUENCE_OFFSET,
        "parameters": parameters,
        "internals": internals,
    });
    let path = dir.join("expected.json");
    std::fs::write(&path, expected.to_string()).expect("expected.json");
    path
}

/// A CCM and car at power-up with `flash`, parked with the tractive system off (the
/// shutdown circuit held open until `start_up`), after 100 ms (the CCM has heard the car).
fn power_up(flash: RamFlash) -> XcpCar {
    let parked = FaultPlan::NONE.with(Injection {
        fault: Fault::ShutdownOpen,
        from_ms: 0,
        until_ms: u32::MAX,
    });
    let run = ClosedLoop::new(
        ModelParams::NOMINAL,
        Mode::Road,
        Cycle::Acceleration,
        parked,
    );
    let mut car = XcpCar::new(run, flash, Some(SECRET), 0x5EED_0001);
    for _ in 0..100 {
        car.step(&mut NoTap, &mut |_| true);
    }
    car
}

/// What the control events measured, by the telemetry packet's sequence number (one per
/// control step): the internals.
#[derive(Default)]
struct Recorded {
    by_sequence: HashMap<u16, aer::calibration::Internals>,
    launch_torque: Vec<f32>,
}

/// The harness: the car with its slave, the master's connection, and the script.
struct Harness {
    car: XcpCar,
    listener: TcpListener,
    stream: Option<TcpStream>,
    decoder: TcpDecoder,
    encoder: TcpEncoder,
    script: Child,
    to_script: ChildStdin,
    from_script: Receiver<String>,
    results: HashMap<String, Value>,
    recorded: Recorded,
    /// The run at ready-to-drive with the defaults, to drive beside the tuned one.
    twin: Option<ClosedLoop>,
    driven_ms: u32,
}

impl Harness {
    /// Waits for the master's connection (the script may have died instead).
    fn accept(&mut self) {
        self.listener.set_nonblocking(true).expect("nonblocking");
        loop {
            match self.listener.accept() {
                Ok((stream, _)) => {
                    stream
                        .set_read_timeout(Some(Duration::from_millis(1)))
                        .expect("timeout");
                    stream.set_nodelay(true).expect("nodelay");
                    self.stream = Some(stream);
                    self.decoder.reset();
                    self.encoder = TcpEncoder::new();
                    return;
                }
                Err(error) if error.kind() == ErrorKind::WouldBlock => {
                    if let Some(status) = self.script.try_wait().expect("script") {
                        panic!("the script ended ({status}) before connecting");
                    }
                    // Waiting for a connection, not for time: the loop ends on an event.
                    std::thread::yield_now();
                }
                Err(error) => panic!("accept: {error}"),
            }
        }
    }

    fn send_packet(stream: &mut TcpStream, encoder: &mut TcpEncoder, packet: &[u8]) {
        let mut frame = [0u8; TCP_FRAME_MAX];
        let len = encoder.encode(packet, &mut frame).expect("frame");
        // The master may be gone (after its DISCONNECT): nothing to deliver then.
        let _ = stream.write_all(&frame[..len]);
    }

    /// Answers every command the master has sent.
    fn serve(&mut self) {
        let Some(stream) = self.stream.as_mut() else {
            return;
        };
        let mut buffer = [0u8; 512];
        let read = match stream.read(&mut buffer) {
            Ok(0) => {
                self.stream = None;
                return;
            }
            Ok(read) => read,
            Err(error) if matches!(error.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {
                return;
            }
            Err(_) => {
                self.stream = None;
                return;
            }
        };
        let mut input = &buffer[..read];
        while !input.is_empty() {
            let (used, packet) = self.decoder.decode(input);
            input = &input[used..];
            match packet {
                Some(Ok(packet)) => {
                    let packet = packet.data.to_vec();
                    let mut reply = [0u8; MAX_CTO];
                    if let Some(len) = self.car.command(&packet, &mut reply) {
                        Self::send_packet(stream, &mut self.encoder, &reply[..len]);
                    }
                }
                Some(Err(error)) => panic!("the master's stream broke: {error:?}"),
                None => {}
            }
        }
    }

    /// One model millisecond: DAQ packets to the master, the control events recorded.
    fn step(&mut self) {
        let mut dtos: Vec<Vec<u8>> = Vec::new();
        self.car.step(&mut NoTap, &mut |packet| {
            dtos.push(packet.to_vec());
            true
        });
        if let Some(stream) = self.stream.as_mut() {
            for dto in &dtos {
                Self::send_packet(stream, &mut self.encoder, dto);
            }
        }
        let now_ms = self.car.run.now_ms();
        if now_ms % 10 == 0 {
            let measured = self.car.run.ccm.measurements();
            let sequence = u16::from_le_bytes([
                measured.telemetry[SEQUENCE_OFFSET],
                measured.telemetry[SEQUENCE_OFFSET + 1],
            ]);
            let internals = self.car.run.ccm.internals();
            self.recorded.by_sequence.insert(sequence, internals);
            let torque = self.car.run.last_outputs().torque;
            if torque.launch == LaunchState::Active {
                self.recorded.launch_torque.push(torque.torque_nm);
            }
        }
        if self.twin.is_some() {
            self.driven_ms += 1;
        }
    }

    fn answer(&mut self, answer: Value) {
        writeln!(self.to_script, "{answer}").expect("answer the script");
        self.to_script.flush().expect("flush");
    }

    fn restart(&mut self, corrupt: bool) {
        self.stream = None;
        let mut flash = self.car.flash_mut().clone();
        if corrupt {
            for slot in [Slot::A, Slot::B] {
                flash.slot_mut(slot)[40] ^= 0x01;
            }
        }
        self.car = power_up(flash);
        let startup = self.car.startup().to_string();
        self.answer(json!({"ok": true, "startup": startup}));
        self.accept();
    }

    /// Handles one request of the script; false at the end.
    fn request(&mut self, line: &str) -> bool {
        let request: Value = serde_json::from_str(line)
            .unwrap_or_else(|error| panic!("the script wrote {line:?}: {error}"));
        let now = |h: &Self| json!({"ok": true, "now_us": h.car.run.now_ms() * 1_000});
        match request["cmd"].as_str() {
            Some("start_up") => {
                self.car.run.retune(ModelParams::NOMINAL, FaultPlan::NONE);
                while !self.car.run.car.driver.driving() {
                    assert!(self.car.run.now_ms() < 60_000, "start-up within 60 s");
                    self.step();
                }
                let mut twin = self.car.run.clone();
                twin.ccm
                    .set_calibration(Calibration::DEFAULT, Startup::NoneSaved);
                self.twin = Some(twin);
                let answer = now(self);
                self.answer(answer);
            }
            Some("drive_until_moving") => {
                while self.car.run.car.chassis.speed_m_s < 5.0 {
                    assert!(self.driven_ms < 20_000, "moving within 20 s");
                    self.step();
                }
                let answer = now(self);
                self.answer(answer);
            }
            Some("drive") => {
                let ms = request["ms"].as_u64().expect("ms");
                for _ in 0..ms {
                    self.step();
                }
                let answer = now(self);
                self.answer(answer);
            }
            Some("restart") => self.restart(false),
            Some("corrupt") => self.restart(true),
            Some("result") => {
                let name = request["name"].as_str().expect("name").to_owned();
                eprintln!("pyxcp: {name} = {}", request["value"]);
                self.results.insert(name, request["value"].clone());
                self.answer(json!({"ok": true}));
            }
            Some("done") => {
                self.answer(json!({"ok": true}));
                return false;
            }
            other => panic!("unknown request {other:?}"),
        }
        true
    }

    fn run(&mut self) {
        self.accept();
        loop {
            self.serve();
            match self.from_script.try_recv() {
                Ok(line) => {
                    if !self.request(&line) {
                        break;
                    }
                }
                Err(TryRecvError::Empty) => {}
                Err(TryRecvError::Disconnected) => {
                    let status = self.script.wait().expect("script");
                    panic!("the script ended ({status}) before `done`");
                }
            }
        }
        let status = self.script.wait().expect("script");
        assert!(status.success(), "the script failed: {status}");
    }

    fn result(&self, name: &str) -> &Value {
        self.results
            .get(name)
            .unwrap_or_else(|| panic!("the script reported no {name}"))
    }
}

fn floats(value: &Value) -> Vec<f64> {
    value
        .as_array()
        .unwrap_or_else(|| panic!("{value} is not a list"))
        .iter()
        .map(|v| v.as_f64().expect("number"))
        .collect()
}

fn f32s(values: &[f32]) -> Vec<f64> {
    values.iter().map(|&v| f64::from(v)).collect()
}

#[test]
fn pyxcp_calibrates_and_measures_the_ccm_in_the_car_model() {
    let Some(python) = python() else {
        return;
    };
    let dir = tempfile::tempdir().expect("tempdir");
    let listener = TcpListener::bind("127.0.0.1:0").expect("bind");
    let port = listener.local_addr().expect("addr").port();
    let mut script = Command::new(python)
        .arg(root().join("tools/xcp_scenarios.py"))
        .env("AER_XCP_PORT", port.to_string())
        .env(
            "AER_XCP_SECRET",
            SECRET
                .iter()
                .map(|b| format!("{b:02x}"))
                .collect::<String>(),
        )
        .env("AER_XCP_EXPECTED", expected(dir.path()))
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("start the script");
    let to_script = script.stdin.take().expect("stdin");
    let stdout = script.stdout.take().expect("stdout");
    let (lines, from_script) = channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines() {
            let Ok(line) = line else { break };
            if lines.send(line).is_err() {
                break;
            }
        }
    });
    let mut harness = Harness {
        car: power_up(RamFlash::default()),
        listener,
        stream: None,
        decoder: TcpDecoder::new(),
        encoder: TcpEncoder::new(),
        script,
        to_script,
        from_script,
        results: HashMap::new(),
        recorded: Recorded::default(),
        twin: None,
        driven_ms: 0,
    };
    harness.run();

    // 1-2: the EPK is the schema's and the A2L's; every parameter reads its default.
    assert_eq!(harness.result("epk"), EPK);
    assert_eq!(harness.result("a2l_epk"), EPK);
    let defaults = harness.result("defaults");
    let page = Calibration::DEFAULT.to_page();
    for p in &PARAMETERS {
        let expected: Vec<f64> = (0..p.count).map(|i| p.value(&page, i).unwrap()).collect();
        assert_eq!(floats(&defaults[p.name]), expected, "{}", p.name);
    }
    // 3-4: locked until unlocked; out of range refused, value kept.
    assert_eq!(harness.result("locked_write"), 0x25);
    assert_eq!(harness.result("unlocked"), true);
    let out_of_range = harness.result("out_of_range");
    assert_eq!(out_of_range["code"], 0x22);
    assert_eq!(
        out_of_range["after"].as_f64(),
        Some(f64::from(Calibration::DEFAULT.launch_kp))
    );
    // 5: BUILD_CHECKSUM is CRC-16-CCITT of the page the master read.
    let checksum = harness.result("checksum");
    assert_eq!(checksum["slave"], checksum["computed"]);
    // 6-7: the launch slip target written as one block, and saved while parked.
    assert_eq!(floats(harness.result("launch_target")), f32s(&[0.03; 4]));
    assert_eq!(harness.result("stored"), true);
    // 8-9: refusals in the car's state, the value kept; a driving parameter changes.
    assert_eq!(harness.result("tractive_off_write"), 0x23);
    let standstill = harness.result("moving_standstill_write");
    assert_eq!(standstill["code"], 0x23);
    assert_eq!(
        standstill["after"].as_f64(),
        Some(f64::from(Calibration::DEFAULT.launch_kp))
    );
    let driving = harness.result("moving_driving_write");
    assert!(driving["code"].is_null(), "{driving}");
    assert_eq!(driving["after"].as_f64(), Some(650.0));
    assert_eq!(harness.result("moving_page_switch"), 0x23);

    // 9: the DAQ list at the control rate: every sample equals what the CCM measured at that
    // control step (named by the telemetry packet's sequence number), none missing.
    let daq = harness.result("daq").as_array().expect("daq samples");
    assert!(daq.len() >= 30, "{} DAQ samples", daq.len());
    let mut previous: Option<u64> = None;
    for sample in daq {
        let sequence = sample["sequence"].as_u64().expect("sequence");
        let internals = harness
            .recorded
            .by_sequence
            .get(&(sequence as u16))
            .unwrap_or_else(|| panic!("no control step sent telemetry packet {sequence}"));
        assert_eq!(
            sample["launch_slip_target"].as_f64(),
            Some(f64::from(internals.launch_slip_target))
        );
        assert_eq!(
            sample["torque_command_nm"].as_f64(),
            Some(f64::from(internals.torque_command_nm))
        );
        if let Some(previous) = previous {
            assert_eq!(sequence, previous + 1, "one sample per control step");
        }
        previous = Some(sequence);
    }
    // The written target is the one launch control aimed at ...
    assert!(
        daq.iter()
            .any(|s| s["launch_slip_target"].as_f64() == Some(f64::from(0.03f32))),
        "launch control ran on the written target"
    );
    // ... and it took torque away: the same launch with the defaults commands more.
    let mut twin = harness.twin.take().expect("twin");
    let mut twin_torque = Vec::new();
    for _ in 0..harness.driven_ms {
        twin.step(&mut NoTap);
        let torque = twin.last_outputs().torque;
        if twin.now_ms() % 10 == 0 && torque.launch == LaunchState::Active {
            twin_torque.push(torque.torque_nm);
        }
    }
    let mean = |v: &[f32]| v.iter().sum::<f32>() / v.len().max(1) as f32;
    let (tuned, default) = (mean(&harness.recorded.launch_torque), mean(&twin_torque));
    eprintln!(
        "launch: mean torque {tuned:.1} Nm with the written target, {default:.1} Nm with the defaults"
    );
    assert!(tuned < default - 5.0, "{tuned} vs {default}");

    // 10-12: saved, restored after a power cycle (the unsaved gain is not); the reference
    // page reverts; a corrupt copy loads the defaults and says so.
    assert_eq!(
        harness.result("restart_startup"),
        "calibration: saved copy A (generation 1)"
    );
    let restored = harness.result("restored");
    assert_eq!(floats(&restored["launch_slip_target"]), f32s(&[0.03; 4]));
    assert_eq!(
        restored["traction_kp"].as_f64(),
        Some(f64::from(Calibration::DEFAULT.traction_kp))
    );
    assert_eq!(
        floats(harness.result("reverted")),
        f32s(&Calibration::DEFAULT.launch_slip_target)
    );
    assert_eq!(
        harness.result("corrupt_startup"),
        "calibration: the schema's defaults (saved copy corrupt)"
    );
    assert_eq!(
        floats(harness.result("after_corrupt")),
        f32s(&Calibration::DEFAULT.launch_slip_target)
    );
}
