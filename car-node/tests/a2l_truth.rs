//! The A2L tells the truth about the slave: the CCM's slave (in the car model) is asked
//! everything a calibration tool asks at connection (CONNECT, GET_COMM_MODE_INFO, the DAQ
//! processor, resolution and event information, the paging information, GET_ID) and every
//! command the standard names; `tools/check_a2l_slave.py` parses `generated/aer.a2l`'s
//! IF_DATA with pya2ldb and compares each answer with what the file promises, and every
//! OPTIONAL_CMD with what the slave really answers.
//!
//! Needs the venv's Python with pya2ldb (`.ci/run` installs it); without it the test says
//! SKIPPED, unless `AER_REQUIRE_PYTHON` is set (CI sets it), when it fails.

use aer::calibration::xcp::{A2L_NAME, CAN_ID_MASTER, CAN_ID_SLAVE, TCP_PORT};
use aer_car_model::chassis::Mode;
use aer_car_model::driver::Cycle;
use aer_car_model::faults::FaultPlan;
use aer_car_model::{ClosedLoop, ModelParams, XcpCar};
use aer_ccm::calibration::store::RamFlash;
use aer_xcp::protocol::cmd;
use serde_json::{Value, json};
use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The venv's Python (or `AER_PYTHON`), when it imports pya2ldb.
fn python() -> Option<PathBuf> {
    let venv = root().join(".venv/bin/python");
    let python = std::env::var_os("AER_PYTHON").map_or(venv, PathBuf::from);
    let usable = Command::new(&python)
        .args(["-c", "import pya2l"])
        .output()
        .is_ok_and(|o| o.status.success());
    if usable {
        return Some(python);
    }
    assert!(
        std::env::var_os("AER_REQUIRE_PYTHON").is_none(),
        "AER_REQUIRE_PYTHON is set but {} cannot import pya2l",
        python.display()
    );
    eprintln!(
        "SKIPPED: comparing the A2L with the slave needs {} with pya2ldb \
         (python3 -m venv .venv && .venv/bin/pip install -r tools/requirements.txt)",
        python.display()
    );
    None
}

struct Master(XcpCar);

impl Master {
    fn ask(&mut self, packet: &[u8]) -> Vec<u8> {
        let mut reply = [0u8; aer_xcp::MAX_CTO];
        let len = self.0.command(packet, &mut reply).unwrap_or(0);
        reply[..len].to_vec()
    }

    /// A text the slave put behind the MTA (GET_ID, an event's name), read by UPLOAD.
    fn upload_text(&mut self, len: usize) -> String {
        let mut text = Vec::new();
        while text.len() < len {
            let chunk = (len - text.len()).min(7) as u8;
            let answer = self.ask(&[cmd::UPLOAD, chunk]);
            assert_eq!(answer[0], 0xFF, "UPLOAD: {answer:02X?}");
            text.extend_from_slice(&answer[1..=usize::from(chunk)]);
        }
        String::from_utf8(text).expect("ASCII")
    }
}

/// What the slave answers a tool at connection, raw, and which commands it does not know.
fn answers() -> Value {
    let run = ClosedLoop::new(
        ModelParams::NOMINAL,
        Mode::Road,
        Cycle::Acceleration,
        FaultPlan::NONE,
    );
    let mut master = Master(XcpCar::new(run, RamFlash::default(), None, &[1; 32]));
    let connect = master.ask(&[cmd::CONNECT, 0]);
    let comm_mode_info = master.ask(&[cmd::GET_COMM_MODE_INFO]);
    let daq_processor = master.ask(&[cmd::GET_DAQ_PROCESSOR_INFO]);
    let daq_resolution = master.ask(&[cmd::GET_DAQ_RESOLUTION_INFO]);
    let max_events = u16::from_le_bytes([daq_processor[4], daq_processor[5]]);
    let events: Vec<Value> = (0..max_events)
        .map(|channel| {
            let [low, high] = channel.to_le_bytes();
            let info = master.ask(&[cmd::GET_DAQ_EVENT_INFO, 0, low, high]);
            let name = master.upload_text(usize::from(info[3]));
            json!({"info": info, "name": name})
        })
        .collect();
    let pag_processor = master.ask(&[cmd::GET_PAG_PROCESSOR_INFO]);
    let segments: Vec<Value> = (0..pag_processor[1])
        .map(|segment| {
            let standard = master.ask(&[cmd::GET_SEGMENT_INFO, 1, segment, 0]);
            let pages: Vec<Value> = (0..standard[1])
                .map(|page| json!(master.ask(&[cmd::GET_PAGE_INFO, 0, segment, page])))
                .collect();
            json!({"standard": standard, "pages": pages})
        })
        .collect();
    let id = master.ask(&[cmd::GET_ID, 1]);
    let a2l_name = master.upload_text(u32::from_le_bytes([id[4], id[5], id[6], id[7]]) as usize);
    // BUILD_CHECKSUM over the first byte of the calibration page: its checksum type.
    let mut set_mta = vec![cmd::SET_MTA, 0, 0, 0];
    set_mta.extend_from_slice(&aer::calibration::xcp::CALIBRATION_ADDRESS.to_le_bytes());
    master.ask(&set_mta);
    let checksum = master.ask(&[cmd::BUILD_CHECKSUM, 0, 0, 0, 1, 0, 0, 0]);
    // Every command the standard names, to a fresh session: which the slave does not know.
    let unknown: Vec<&str> = cmd::NAMES
        .iter()
        .filter(|(code, _)| *code >= 0xC0)
        .filter(|(code, _)| {
            master.ask(&[cmd::CONNECT, 0]);
            master.ask(&[*code, 0, 0, 0, 0, 0, 0, 0]) == [0xFE, 0x20]
        })
        .map(|(_, name)| *name)
        .collect();
    json!({
        "connect": connect,
        "comm_mode_info": comm_mode_info,
        "daq_processor": daq_processor,
        "daq_resolution": daq_resolution,
        "events": events,
        "pag_processor": pag_processor,
        "segments": segments,
        "a2l_name": a2l_name,
        "a2l_name_constant": A2L_NAME,
        "checksum": checksum,
        "unknown": unknown,
        "can_id_master": CAN_ID_MASTER,
        "can_id_slave": CAN_ID_SLAVE,
        "tcp_port": TCP_PORT,
    })
}

#[test]
fn the_a2l_promises_what_the_slave_answers() {
    let Some(python) = python() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("answers.json");
    std::fs::write(&path, answers().to_string()).unwrap();
    let output = Command::new(&python)
        .arg(root().join("tools/check_a2l_slave.py"))
        .arg(root().join("generated/aer.a2l"))
        .arg(&path)
        .output()
        .expect("running tools/check_a2l_slave.py");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    eprintln!("{text}");
    assert!(output.status.success(), "{text}");
    assert!(text.contains("as the slave answers"), "{text}");

    // The checker itself: a description that promises more than the slave does fails,
    // naming each difference.
    let a2l = std::fs::read_to_string(root().join("generated/aer.a2l")).unwrap();
    let edits = [
        ("BLOCK MASTER 32 0", "BLOCK MASTER 31 0"),
        (
            "OPTIONAL_CMD GET_ID\n",
            "OPTIONAL_CMD GET_ID\n        OPTIONAL_CMD SHORT_DOWNLOAD\n",
        ),
        ("/begin DAQ DYNAMIC 4 2 0", "/begin DAQ DYNAMIC 255 2 0"),
    ];
    let mut tampered = a2l.clone();
    for (from, to) in edits {
        assert!(tampered.contains(from), "fixture moved: {from}");
        tampered = tampered.replacen(from, to, 1);
    }
    let tampered_dir = tempfile::tempdir().unwrap();
    let tampered_path = tampered_dir.path().join("aer.a2l");
    std::fs::write(&tampered_path, tampered).unwrap();
    let output = Command::new(&python)
        .arg(root().join("tools/check_a2l_slave.py"))
        .arg(&tampered_path)
        .arg(&path)
        .output()
        .expect("running tools/check_a2l_slave.py");
    let text = String::from_utf8_lossy(&output.stdout);
    assert!(!output.status.success(), "{text}");
    for difference in [
        "MAX_BS: the A2L says 31, the slave answers 32",
        "OPTIONAL_CMD SHORT_DOWNLOAD: the slave answers ERR_CMD_UNKNOWN",
        "MAX_DAQ: the A2L says 255, the slave answers 4",
    ] {
        assert!(text.contains(difference), "{difference:?} not in:\n{text}");
    }
}
