//! The CCM's XCP slave proven with a master no one on the team wrote: pyxcp (PyPI) plays
//! `tools/xcp_scenarios.py` over XCP on TCP against the slave in the closed-loop car model,
//! the same slave core the firmware serves on CAN (the virtual Pi plays the same scenarios
//! over XCP on CAN on a vcan, `tools/virtual_pi.sh`).
//!
//! Needs the venv's Python with pyxcp (`.ci/run` installs it); without it the test says
//! SKIPPED, unless `AER_REQUIRE_PYTHON` is set (CI sets it), when it fails.

use aer_car_model::driver::Cycle;
use aer_car_node::link::{Link, TcpLink};
use aer_car_node::{checks, scenarios, serve};
use aer_xcp::transport::{TCP_FRAME_MAX, TcpDecoder, TcpEncoder};
use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The venv's Python (or `AER_PYTHON`), when it imports pyxcp and pya2ldb.
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

#[test]
fn pyxcp_calibrates_and_measures_the_ccm_in_the_car_model() {
    let Some(python) = python() else {
        return;
    };
    let mut link = TcpLink::bind("127.0.0.1:0".parse().unwrap()).unwrap();
    let script = scenarios::in_checkout(&root(), python);
    let outcome = scenarios::play(&mut link, &script).unwrap();
    let verdicts = checks::judge(&outcome);
    for verdict in &verdicts {
        eprintln!("{verdict}");
    }
    assert!(verdicts.len() >= 20, "{} checks", verdicts.len());
    let failed = checks::failed(&verdicts);
    assert!(failed.is_empty(), "{failed:#?}");
}

/// The desk server answers a master in real time: CONNECT gets its positive response with
/// MAX_CTO 8, and the server stops when told.
#[test]
fn the_desk_server_answers_connect_over_tcp() {
    let mut link = TcpLink::bind("127.0.0.1:0".parse().unwrap()).unwrap();
    let address = link.address();
    let answered = Arc::new(AtomicBool::new(false));
    let master = {
        let answered = Arc::clone(&answered);
        std::thread::spawn(move || {
            let mut stream = TcpStream::connect(address).unwrap();
            let mut frame = [0u8; TCP_FRAME_MAX];
            // CONNECT, normal mode.
            let len = TcpEncoder::new().encode(&[0xFF, 0x00], &mut frame).unwrap();
            stream.write_all(&frame[..len]).unwrap();
            let mut decoder = TcpDecoder::new();
            let mut buffer = [0u8; 64];
            let response = loop {
                let read = stream.read(&mut buffer).unwrap();
                assert!(read > 0, "the server closed the connection");
                let (_, packet) = decoder.decode(&buffer[..read]);
                if let Some(packet) = packet {
                    break packet.unwrap().data.to_vec();
                }
            };
            answered.store(true, Ordering::Release);
            response
        })
    };
    let ran_ms = serve::serve(&mut link, Cycle::Acceleration, None, |_| {
        !answered.load(Ordering::Acquire)
    })
    .unwrap();
    let response = master.join().unwrap();
    assert_eq!(
        response.first(),
        Some(&0xFF),
        "positive response: {response:02x?}"
    );
    assert_eq!(response.get(3), Some(&8), "MAX_CTO: {response:02x?}");
    assert!(link.describe().contains("XCP on TCP"));
    eprintln!("served {ran_ms} model ms before the master had its answer");
}
