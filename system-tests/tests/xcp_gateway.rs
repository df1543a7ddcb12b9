//! The Pi's XCP gateway between a master on the pit's network and the CCM's slave on CAN:
//! pyxcp plays every calibration scenario through it against the closed-loop car model; a
//! stranger and a second master are refused and counted; a master that vanishes in the middle
//! of a block download leaves the calibration page as it was, its session ended, and the next
//! master connects. The CAN side here is the gateway's channel pair, which on the Pi its
//! SocketCAN task serves (the virtual Pi runs that on vcan).

use aer::calibration::xcp::CALIBRATION_ADDRESS;
use aer_car_model::driver::Cycle;
use aer_car_node::link::Link;
use aer_car_node::masters::{self, Inbound, Outbox, Transport};
use aer_car_node::{checks, scenarios, serve};
use aer_dashboard::config::{Config, View};
use aer_dashboard::screenshot::PIT_SIZE;
use aer_dashboard::tune_worker::{Control, Event, Request, Worker};
use aer_dashboard::ui::tune::Action;
use aer_dashboard::ui::{App, Message};
use aer_host::reports::counters::Counters;
use aer_raspi::store::calibration::{self, Kind};
use aer_raspi::store::session::{self, Metadata};
use aer_raspi::store::{self, NoteSender, StoreWriter};
use aer_raspi::xcp_gateway::{self, Gateway, Settings, SlaveLink};
use aer_xcp::transport::{CAN_DLC, TCP_FRAME_MAX, TcpDecoder, TcpEncoder, can_frame};
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use iced_test::Simulator;
use iced_test::selector::Candidate;
use std::time::{Duration, Instant};
use tokio::sync::mpsc;
use tokio_util::sync::CancellationToken;

/// The slave's end of the gateway's CAN side, as car-node's links are: commands in, the
/// slave's packets out as 8-byte frames (what XCP on CAN carries).
struct GatewayLink {
    commands: std::sync::mpsc::Receiver<[u8; CAN_DLC]>,
    /// Every command code the slave was sent, in order.
    seen: Arc<std::sync::Mutex<Vec<u8>>>,
    answers: mpsc::Sender<Vec<u8>>,
    gateway: SocketAddr,
}

impl Link for GatewayLink {
    fn receive(&mut self) -> anyhow::Result<Option<Vec<u8>>> {
        match self.commands.recv_timeout(Duration::from_millis(1)) {
            Ok(frame) => {
                if let Ok(mut seen) = self.seen.lock() {
                    seen.push(frame[0]);
                }
                Ok(Some(frame.to_vec()))
            }
            Err(std::sync::mpsc::RecvTimeoutError::Timeout) => Ok(None),
            Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => {
                anyhow::bail!("the gateway ended")
            }
        }
    }

    fn send(&mut self, packet: &[u8]) -> bool {
        can_frame(packet).is_some_and(|frame| self.answers.blocking_send(frame.to_vec()).is_ok())
    }

    fn await_master(
        &mut self,
        _still_waiting: &mut dyn FnMut() -> anyhow::Result<()>,
    ) -> anyhow::Result<()> {
        Ok(())
    }

    fn drop_master(&mut self) {}

    fn take_lost(&mut self) -> bool {
        false
    }

    fn malformed(&self) -> u64 {
        0
    }

    fn script_env(&self) -> Vec<(String, String)> {
        // The master reaches the slave through the gateway (`Script::through`).
        Vec::new()
    }

    fn describe(&self) -> String {
        format!("the Pi's XCP gateway at {}", self.gateway)
    }
}

/// The desk server's transport over `link`: the gateway's CAN side is one client, the bus.
fn desk_transport(link: GatewayLink) -> Transport {
    let (events, inbound) = std::sync::mpsc::sync_channel(masters::INBOUND_LEN);
    let (queue, outgoing) = std::sync::mpsc::sync_channel::<Vec<u8>>(masters::OUTBOX_LEN);
    let describe = link.describe();
    let opened = Inbound::Opened {
        client: 0,
        peer: describe.clone(),
        outbox: Outbox::new(queue, Box::new(|| {})),
    };
    events.send(opened).expect("the transport");
    let GatewayLink {
        commands,
        seen,
        answers,
        ..
    } = link;
    std::thread::spawn(move || {
        while let Ok(frame) = commands.recv() {
            if let Ok(mut seen) = seen.lock() {
                seen.push(frame[0]);
            }
            let packet = Inbound::Packet {
                client: 0,
                packet: frame.to_vec(),
            };
            if events.send(packet).is_err() {
                return;
            }
        }
    });
    std::thread::spawn(move || {
        while let Ok(packet) = outgoing.recv() {
            let Some(frame) = can_frame(&packet) else {
                continue;
            };
            if answers.blocking_send(frame.to_vec()).is_err() {
                return;
            }
        }
    });
    Transport::new(inbound, describe)
}

/// A gateway on a free loopback port that allows `allow`, and the slave's link to it; its
/// calibration record goes to `record`.
fn gateway(
    runtime: &tokio::runtime::Runtime,
    allow: &str,
    counters: &Arc<Counters>,
    record: Option<NoteSender>,
) -> (Gateway, GatewayLink) {
    let (to_slave, mut commands) = mpsc::channel(xcp_gateway::TO_SLAVE_FRAMES);
    let (answers, from_slave) = mpsc::channel(xcp_gateway::TO_SLAVE_FRAMES);
    let settings = Settings {
        listen: "127.0.0.1:0".parse().expect("address"),
        allow: vec![allow.parse().expect("network")],
        interface: "can0".into(),
        idle: Duration::from_secs(60),
    };
    let gateway = runtime
        .block_on(xcp_gateway::spawn(
            settings,
            SlaveLink {
                to_slave,
                from_slave,
            },
            counters.clone(),
            record,
            CancellationToken::new(),
        ))
        .expect("listening");
    // The car's side reads with a timeout, as car-node's links do.
    let (forward, commands_for_car) = std::sync::mpsc::channel();
    runtime.spawn(async move {
        while let Some(frame) = commands.recv().await {
            if forward.send(frame).is_err() {
                return;
            }
        }
    });
    let link = GatewayLink {
        commands: commands_for_car,
        seen: Arc::default(),
        answers,
        gateway: gateway.address,
    };
    (gateway, link)
}

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The venv's Python with pyxcp and pya2ldb (`.ci/run` installs them).
fn python() -> Option<PathBuf> {
    let python = std::env::var_os("AER_PYTHON")
        .map_or_else(|| root().join(".venv/bin/python"), PathBuf::from);
    let usable = Command::new(&python)
        .args(["-c", "import pyxcp, pya2l"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !usable {
        assert!(
            std::env::var_os("AER_REQUIRE_PYTHON").is_none(),
            "AER_REQUIRE_PYTHON is set but {} cannot import pyxcp",
            python.display()
        );
        eprintln!(
            "SKIPPED: pyxcp through the gateway needs {}",
            python.display()
        );
        return None;
    }
    Some(python)
}

#[test]
fn pyxcp_calibrates_and_measures_the_ccm_through_the_pis_gateway() {
    let Some(python) = python() else { return };
    let runtime = tokio::runtime::Runtime::new().expect("runtime");
    let counters = Arc::new(Counters::default());
    // The service's store, its session open, taking the gateway's calibration record.
    let dir = tempfile::tempdir().expect("temp dir");
    let store_path = dir.path().join("store.sqlite");
    let db = store::open(&store_path).expect("store");
    let session = session::begin(&db, &Metadata::default(), "live", 1).expect("session");
    let writer = StoreWriter::start(db, counters.clone());
    let (gateway, mut link) = gateway(
        &runtime,
        "127.0.0.1/32",
        &counters,
        Some(writer.note_sender()),
    );
    let script = scenarios::Script {
        through: Some(gateway.address),
        ..scenarios::in_checkout(&root(), python)
    };
    let outcome = scenarios::play(&mut link, &script).expect("the scenarios played");
    let verdicts = checks::judge(&outcome);
    for verdict in &verdicts {
        eprintln!("{verdict}");
    }
    assert!(verdicts.len() >= 20, "{} checks", verdicts.len());
    let failed = checks::failed(&verdicts);
    assert!(failed.is_empty(), "{failed:#?}");
    let seen = counters.snapshot();
    eprintln!(
        "through the gateway: {} commands, {} responses and DAQ packets",
        seen.xcp_commands, seen.xcp_responses
    );
    assert!(seen.xcp_commands > 100 && seen.xcp_responses > seen.xcp_commands);
    assert_eq!(seen.xcp_refused, 0);
    let status = gateway.state.snapshot();
    assert_eq!(status.listen, gateway.address.to_string());

    // Every change the scenarios made, in the session's record, as the status and the
    // counters saw them.
    drop(gateway);
    writer.finish();
    let db = store::open(&store_path).expect("store");
    let entries = calibration::list(&db, Some(session), None, None).expect("record");
    let changes: Vec<String> = entries
        .iter()
        .filter(|e| e.kind != Kind::Found)
        .map(|e| e.to_string())
        .collect();
    for change in &changes {
        eprintln!("{change}");
    }
    let has = |text: &str| changes.iter().any(|c| c.contains(text));
    let defaults = aer::calibration::Calibration::DEFAULT.to_page();
    let default = |name: &str| {
        let parameter = aer::calibration::PARAMETERS
            .iter()
            .find(|p| p.name == name)
            .expect("in the schema");
        calibration::number(parameter.value(&defaults, 0).expect("value"))
    };
    let (kp, launch_kp) = (default("traction_kp"), default("launch_kp"));
    let (slip, apps) = (default("launch_slip_target"), default("apps1_v"));
    for expected in [
        format!("write traction_kp {kp} -> 1000 refused: calibration is locked"),
        format!("write launch_kp {launch_kp} -> 1000000 refused: out of range 0-2000"),
        format!("write launch_slip_target[0] {slip} -> 0.03 accepted"),
        format!("write launch_slip_target[3] {slip} -> 0.03 accepted"),
        "save  accepted".to_owned(),
        format!(
            "write apps1_v[0] {apps} -> {} refused: only at standstill with the tractive system off",
            calibration::number(f64::from(apps.parse::<f32>().expect("number") + 0.01))
        ),
        format!("write launch_kp {launch_kp} -> 210 refused: only at standstill"),
        format!("write traction_kp {kp} -> 650 accepted"),
        "page ecu_page 0 -> 1 refused: not in this vehicle state".to_owned(),
        format!("revert launch_slip_target[0] 0.03 -> {slip} accepted"),
    ] {
        assert!(
            has(&expected),
            "no {expected:?} in the record: {changes:#?}"
        );
    }
    assert!(
        !has("apps1_v[1]"),
        "an element the write left as it was is no entry: {changes:#?}"
    );
    let counted = counters.snapshot();
    let accepted = entries
        .iter()
        .filter(|e| e.kind != Kind::Found && e.accepted)
        .count();
    assert_eq!(counted.calibration_changes, accepted as u64);
    assert_eq!(
        counted.calibration_refusals,
        (changes.len() - accepted) as u64
    );
    assert_eq!(counted.calibration_unrecorded, 0);
    assert_eq!(
        status.last_change.as_deref(),
        changes.last().map(String::as_str)
    );
    // After the last start-up (both saved copies corrupt) the CCM runs on the defaults.
    let defaults = crc32fast::hash(&aer::calibration::Calibration::DEFAULT.to_page());
    assert_eq!(status.checksum, Some(format!("{defaults:08X}")));
    assert_eq!(entries.last().and_then(|e| e.checksum), Some(defaults));
}

/// One master's connection, speaking XCP on TCP.
struct Master {
    stream: TcpStream,
    encoder: TcpEncoder,
    decoder: TcpDecoder,
}

impl Master {
    fn connect(address: SocketAddr) -> Self {
        let stream = TcpStream::connect(address).expect("connect");
        stream
            .set_read_timeout(Some(Duration::from_secs(10)))
            .expect("timeout");
        Self {
            stream,
            encoder: TcpEncoder::new(),
            decoder: TcpDecoder::new(),
        }
    }

    fn send(&mut self, packet: &[u8]) {
        let mut frame = [0u8; TCP_FRAME_MAX];
        let len = self.encoder.encode(packet, &mut frame).expect("encoded");
        self.stream.write_all(&frame[..len]).expect("sent");
    }

    /// Sends `packet` and returns the response (positive or error).
    fn command(&mut self, packet: &[u8]) -> Vec<u8> {
        self.send(packet);
        let mut byte = [0u8; 1];
        loop {
            let read = self.stream.read(&mut byte).expect("a response");
            assert_eq!(read, 1, "the gateway closed the connection");
            if let (_, Some(packet)) = self.decoder.decode(&byte) {
                return packet.expect("XCP on TCP").data.to_vec();
            }
        }
    }

    /// True once the gateway has closed the connection.
    fn closed(&mut self) -> bool {
        let mut byte = [0u8; 1];
        matches!(self.stream.read(&mut byte), Ok(0) | Err(_))
    }

    fn read_calibration(&mut self, len: usize) -> Vec<u8> {
        let mut bytes = Vec::new();
        while bytes.len() < len {
            let n = (len - bytes.len()).min(7);
            let address = CALIBRATION_ADDRESS + bytes.len() as u32;
            let mut upload = vec![0xF4, n as u8, 0, 0];
            upload.extend_from_slice(&address.to_le_bytes());
            let response = self.command(&upload);
            assert_eq!(response[0], 0xFF, "SHORT_UPLOAD: {response:02x?}");
            bytes.extend_from_slice(&response[1..=n]);
        }
        bytes
    }

    /// GET_SEED and UNLOCK for calibration with the scenarios' secret.
    fn unlock(&mut self) {
        let seed = self.command(&[0xF8, 0, 0x01]);
        assert_eq!(seed[0], 0xFF, "GET_SEED: {seed:02x?}");
        let key = aer_ccm::xcp::key_for(&scenarios::SECRET, &seed[2..2 + usize::from(seed[1])]);
        let mut remaining = key.len();
        for chunk in key.chunks(6) {
            let mut unlock = vec![0xF7, remaining as u8];
            unlock.extend_from_slice(chunk);
            let answer = self.command(&unlock);
            assert_eq!(answer[0], 0xFF, "UNLOCK: {answer:02x?}");
            remaining -= chunk.len();
        }
    }
}

#[test]
fn strangers_and_second_masters_are_refused_and_a_vanished_master_leaves_the_ccm_consistent() {
    let runtime = tokio::runtime::Runtime::new().expect("runtime");
    let counters = Arc::new(Counters::default());

    // Only the pit's network may connect: a master from elsewhere is closed at once.
    let (elsewhere, _unused) = gateway(&runtime, "10.9.0.0/24", &counters, None);
    let mut stranger = Master::connect(elsewhere.address);
    assert!(stranger.closed(), "a stranger is closed");
    assert_eq!(counters.snapshot().xcp_refused, 1);
    let refusal = elsewhere.state.snapshot().last_refusal.expect("named");
    assert!(
        refusal.contains("not in the gateway's allow list"),
        "{refusal}"
    );

    // The car, with its slave behind the pit's gateway.
    let (gateway, link) = gateway(&runtime, "127.0.0.1/32", &counters, None);
    let seen = link.seen.clone();
    let stop = Arc::new(AtomicBool::new(false));
    let car = {
        let stop = stop.clone();
        std::thread::spawn(move || {
            let transport = desk_transport(link);
            serve::serve(
                &transport,
                Cycle::Acceleration,
                Some(scenarios::SECRET),
                &[0x5E; 32],
                |_| !stop.load(Ordering::Relaxed),
            )
        })
    };

    let mut first = Master::connect(gateway.address);
    let connected = first.command(&[0xFF, 0x00]);
    assert_eq!(connected[0], 0xFF, "CONNECT: {connected:02x?}");
    assert!(
        gateway.state.snapshot().session,
        "the status shows the session"
    );
    let before = first.read_calibration(16);
    first.unlock();

    // One master at a time.
    let mut second = Master::connect(gateway.address);
    assert!(second.closed(), "a second master is closed");
    assert_eq!(counters.snapshot().xcp_refused, 2);
    let refusal = gateway.state.snapshot().last_refusal.expect("named");
    assert!(refusal.contains("another master is connected"), "{refusal}");

    // A block download of the first 16 bytes, cut off after its first packet.
    let mut set_mta = vec![0xF6, 0, 0, 0];
    set_mta.extend_from_slice(&CALIBRATION_ADDRESS.to_le_bytes());
    assert_eq!(first.command(&set_mta)[0], 0xFF, "SET_MTA");
    first.send(&[0xF0, 16, 0x00, 0x00, 0x80, 0x3F, 0x00, 0x00]);
    drop(first);

    // The gateway notices, ends the session with the CCM, and the next master connects.
    let deadline = std::time::Instant::now() + Duration::from_secs(10);
    while gateway.state.snapshot().master.is_some() {
        assert!(
            std::time::Instant::now() < deadline,
            "the gateway never noticed"
        );
        std::thread::sleep(Duration::from_millis(1));
    }
    // It ended the vanished master's session: DISCONNECT was the slave's last command.
    let deadline = std::time::Instant::now() + Duration::from_secs(10);
    while seen.lock().expect("seen").last() != Some(&0xFE) {
        assert!(
            std::time::Instant::now() < deadline,
            "no DISCONNECT reached the slave"
        );
        std::thread::sleep(Duration::from_millis(1));
    }
    assert!(!gateway.state.snapshot().session);
    let mut next = Master::connect(gateway.address);
    let connected = next.command(&[0xFF, 0x00]);
    assert_eq!(
        connected[0], 0xFF,
        "CONNECT after the vanished master: {connected:02x?}"
    );
    // Calibration is locked again (bit 0 of the resource protection status).
    let status = next.command(&[0xFD]);
    assert_eq!(status[0], 0xFF, "GET_STATUS: {status:02x?}");
    assert_eq!(status[2] & 0x01, 0x01, "calibration locked: {status:02x?}");
    assert_eq!(
        next.read_calibration(16),
        before,
        "the half-sent block never landed"
    );
    drop(next);

    stop.store(true, Ordering::Relaxed);
    car.join().expect("the car ran").expect("served");
}

/// The car for the Tune page: parked with the tractive system off until `drive` is set, then
/// driving; its slave answers the gateway's frames between model milliseconds. Says `moving`
/// once it rolls at 5 m/s.
fn tune_car(
    mut link: GatewayLink,
    drive: Arc<AtomicBool>,
    stop: Arc<AtomicBool>,
    moving: std::sync::mpsc::Sender<()>,
) -> std::thread::JoinHandle<()> {
    std::thread::spawn(move || {
        let mut car = scenarios::power_up(aer_ccm::calibration::store::RamFlash::default());
        let mut said = false;
        let mut retuned = false;
        while !stop.load(Ordering::Relaxed) {
            if let Ok(Some(packet)) = link.receive() {
                let mut reply = [0u8; aer_xcp::MAX_CTO];
                if let Some(len) = car.command(&packet, &mut reply) {
                    link.send(&reply[..len]);
                }
            }
            if drive.load(Ordering::Relaxed) {
                if !retuned {
                    car.run.retune(
                        aer_car_model::ModelParams::NOMINAL,
                        aer_car_model::faults::FaultPlan::NONE,
                    );
                    retuned = true;
                }
                // Ten model milliseconds per command slot: the car drives off in a second or
                // two rather than in real time.
                for _ in 0..10 {
                    car.step(&mut aer_car_model::NoTap, &mut |_| true);
                }
                if !said && car.run.car.chassis.speed_m_s > 5.0 {
                    said = moving.send(()).is_ok();
                }
            }
        }
    })
}

/// Carries out every request the Tune page made, in order, and hands it the answers.
fn pump(app: &mut App, requests: &std::sync::mpsc::Receiver<Request>, worker: &mut Worker) {
    while let Ok(request) = requests.try_recv() {
        let event = worker.handle(request);
        app.update(Message::TuneWorker(event));
    }
}

/// Clicks the button labelled `label` on the page as it stands and applies what it sends.
fn click(app: &mut App, label: &str) {
    let messages: Vec<Message> = {
        let mut ui = Simulator::with_size(iced::Settings::default(), PIT_SIZE, app.view());
        ui.click(label)
            .unwrap_or_else(|_| panic!("no `{label}` on the page"));
        ui.into_messages().collect()
    };
    assert!(!messages.is_empty(), "`{label}` is not enabled");
    for message in messages {
        app.update(message);
    }
}

fn on_page(app: &App, part: &str) -> bool {
    let part = part.to_owned();
    Simulator::with_size(iced::Settings::default(), PIT_SIZE, app.view())
        .find(move |candidate: Candidate<'_>| match candidate {
            Candidate::Text { content, .. } if content.contains(part.as_str()) => Some(()),
            _ => None,
        })
        .is_ok()
}

#[test]
fn the_tune_page_calibrates_the_ccm_through_the_pis_gateway() {
    let runtime = tokio::runtime::Runtime::new().expect("runtime");
    let counters = Arc::new(Counters::default());
    let (gateway, link) = gateway(&runtime, "127.0.0.1/32", &counters, None);
    let (drive, stop) = (
        Arc::new(AtomicBool::new(false)),
        Arc::new(AtomicBool::new(false)),
    );
    let (moving_tx, moving) = std::sync::mpsc::channel();
    let car = tune_car(link, drive.clone(), stop.clone(), moving_tx);

    // The dashboard on the Tune page, its XCP worker driven here step by step.
    let mut config = Config::default();
    config.tune.gateway = gateway.address.to_string();
    let mut app = App::new(&config, Instant::now());
    let (control, requests) = Control::channel();
    let mut worker = Worker::new(aer_dashboard::tune_worker::Settings {
        gateway: gateway.address,
        secret: Some(scenarios::SECRET),
        no_secret: String::new(),
        timeout: Duration::from_secs(10),
    });
    app.update(Message::TuneWorker(Event::Ready(control)));
    for _ in 0..2 {
        app.update(Message::ToggleView); // driver -> pit -> tune, which connects
    }
    assert_eq!(app.current_view(), View::Tune);
    pump(&mut app, &requests, &mut worker);
    assert!(
        on_page(&app, "connected, LOCKED"),
        "{:?}",
        app.tune().session
    );
    let parameter = |name: &str| {
        aer::calibration::PARAMETERS
            .iter()
            .position(|p| p.name == name)
            .expect("in the schema")
    };
    let (launch_kp, traction_kp) = ((parameter("launch_kp"), 0), (parameter("traction_kp"), 0));
    let write = |app: &mut App, at, typed: &str| {
        app.update(Message::Tune(Action::Edit(at, typed.into())));
        app.update(Message::Tune(Action::Write(at)));
    };

    // Locked: a write is refused with the reason.
    write(&mut app, launch_kp, "210");
    pump(&mut app, &requests, &mut worker);
    assert!(on_page(&app, "refused: calibration is locked"));

    // Parked, tractive system off: unlock, a standstill-only gain written and read back,
    // saved to flash.
    click(&mut app, "Unlock");
    pump(&mut app, &requests, &mut worker);
    assert!(on_page(&app, "calibration unlocked"));
    write(&mut app, launch_kp, "210");
    pump(&mut app, &requests, &mut worker);
    assert!(on_page(&app, "read back 210 Nm"));
    click(&mut app, "Save to flash");
    pump(&mut app, &requests, &mut worker);
    assert!(on_page(&app, "saved to flash"), "{:?}", app.tune().note);

    // Driving: the standstill-only gain refused (the value stays), the while-driving gain
    // written and read back, a value outside the limits refused with them, text that is no
    // number never sent, the revert refused (it would change the launch gain while moving).
    drive.store(true, Ordering::Relaxed);
    moving
        .recv_timeout(Duration::from_secs(60))
        .expect("the car drives off");
    write(&mut app, launch_kp, "220");
    pump(&mut app, &requests, &mut worker);
    assert!(on_page(&app, "refused: only at standstill"));
    assert_eq!(app.tune().value(launch_kp), Some(210.0));
    write(&mut app, traction_kp, "650");
    pump(&mut app, &requests, &mut worker);
    assert!(on_page(&app, "read back 650 Nm"));
    // A curve whose points must rise, both moved past the old upper point: written whole, in
    // one block (point by point the first would be refused, above the second).
    let ramp = parameter("pump_ramp_degc");
    app.update(Message::Tune(Action::Edit((ramp, 0), "65".into())));
    write(&mut app, (ramp, 1), "80");
    pump(&mut app, &requests, &mut worker);
    assert_eq!(
        (app.tune().value((ramp, 0)), app.tune().value((ramp, 1))),
        (Some(65.0), Some(80.0)),
        "{:?}",
        app.tune().outcome((ramp, 0))
    );
    assert!(on_page(&app, "read back 80 degC"));
    let threshold = (parameter("traction_slip_threshold"), 0);
    write(&mut app, threshold, "0.75");
    pump(&mut app, &requests, &mut worker);
    assert!(on_page(&app, "refused: out of range 0.02-0.5"));
    let sent = counters.snapshot().xcp_commands;
    write(&mut app, threshold, "O.2");
    pump(&mut app, &requests, &mut worker);
    assert!(on_page(&app, "not sent: `O.2` is not a number"));
    assert_eq!(counters.snapshot().xcp_commands, sent, "nothing sent");
    click(&mut app, "Revert to defaults");
    pump(&mut app, &requests, &mut worker);
    assert!(
        on_page(&app, "revert: not in this vehicle state"),
        "{:?}",
        app.tune().note
    );

    // The page at both screen sizes, for the docs and a reviewer's eye.
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("tune");
    let mut offscreen = aer_dashboard::screenshot::Offscreen::new().expect("software renderer");
    let shots = aer_dashboard::screenshot::every_size(&mut offscreen, &app, &dir, "tune")
        .expect("screenshots written");
    for shot in &shots {
        eprintln!("screenshot: {}", shot.display());
    }

    // Disconnecting ends the session; the gateway is free for the next master.
    click(&mut app, "Disconnect");
    pump(&mut app, &requests, &mut worker);
    assert!(on_page(&app, "not connected: disconnected"));
    assert!(gateway.state.snapshot().master.is_none() || !gateway.state.snapshot().session);
    stop.store(true, Ordering::Relaxed);
    car.join().expect("the car ran");
}

#[test]
fn a_ccm_that_stops_answering_the_page_read_ends_the_master_and_keeps_late_answers_from_the_next() {
    let runtime = tokio::runtime::Runtime::new().expect("runtime");
    let counters = Arc::new(Counters::default());
    let (gateway, link) = gateway(&runtime, "127.0.0.1/32", &counters, None);
    // A slave that answers CONNECT and then falls silent (its answers to the page read come
    // far too late: held back here until the master is gone).
    let slave = std::thread::spawn(move || {
        let frame = link.commands.recv().expect("CONNECT");
        assert_eq!(frame[0], 0xFF);
        link.answers
            .blocking_send(
                can_frame(&[0xFF, 0x05, 0x00, 8, 8, 0, 1, 1])
                    .expect("8")
                    .to_vec(),
            )
            .expect("answered");
        let upload = link.commands.recv().expect("the page read");
        assert_eq!(upload[0], 0xF4, "the gateway reads the page");
        link
    });
    let mut master = Master::connect(gateway.address);
    master.send(&[0xFF, 0x00]);
    assert!(master.closed(), "no CONNECT answer: the master is ended");
    let link = slave.join().expect("the slave");
    // The late answer to the page read: no master is there to take it as its own.
    link.answers
        .blocking_send(can_frame(&[0xFF, 1, 2, 3, 4, 5, 6, 7]).expect("8").to_vec())
        .expect("sent");
    let mut next = Master::connect(gateway.address);
    assert!(
        next.closed(),
        "a new master waits until the CCM's late answers are past"
    );
    let refusal = gateway.state.snapshot().last_refusal.expect("named");
    assert!(
        refusal.contains("the CCM just stopped answering"),
        "{refusal}"
    );
}
