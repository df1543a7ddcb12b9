//! The gateway's calibration record against the CCM's own slave: whatever a master writes,
//! reverts, switches or saves (accepted or refused, parked or driving), the record replays to
//! exactly the page the CCM holds, its checksum is the one `CCM_Calibration` carries, and
//! every refusal says why.

use aer::calibration::xcp::CALIBRATION_ADDRESS;
use aer::calibration::{PAGE_LEN, PARAMETERS};
use aer_car_model::faults::FaultPlan;
use aer_car_model::{ModelParams, NoTap, XcpCar};
use aer_car_node::scenarios::{SECRET, power_up};
use aer_ccm::calibration::state::Page;
use aer_ccm::calibration::store::RamFlash;
use aer_raspi::store::calibration::{ECU_PAGE, Entry, Kind, number, values_at_end};
use aer_raspi::xcp_gateway::record::Recorder;
use aer_xcp::MAX_CTO;
use proptest::prelude::*;

/// A master on the slave, with the recorder watching as the gateway does.
struct Watched {
    car: XcpCar,
    recorder: Recorder,
    entries: Vec<Entry>,
}

impl Watched {
    /// Sends `packet`; the answer, if the slave gives one.
    fn send(&mut self, packet: &[u8]) -> Option<Vec<u8>> {
        self.recorder.command(packet);
        let mut reply = [0u8; MAX_CTO];
        let len = self.car.command(packet, &mut reply)?;
        let answer = reply[..len].to_vec();
        let at_us = i64::from(self.car.run.now_ms()) * 1000;
        let entries = self.recorder.answer(&answer, at_us, "127.0.0.1:5000");
        self.entries.extend(entries);
        Some(answer)
    }

    /// What the gateway does when a master connects: CONNECT, then the page read.
    fn connect(car: XcpCar) -> Self {
        let mut watched = Self {
            car,
            recorder: Recorder::new(),
            entries: Vec::new(),
        };
        watched.reconnect();
        watched
    }

    /// CONNECT and the gateway's page read.
    fn reconnect(&mut self) {
        let watched = self;
        assert_eq!(watched.send(&[0xFF, 0]).expect("CONNECT")[0], 0xFF);
        let mut page = [0u8; PAGE_LEN];
        for start in (0..PAGE_LEN).step_by(7) {
            let len = 7.min(PAGE_LEN - start);
            let mut upload = vec![0xF4, len as u8, 0, 0];
            upload.extend((CALIBRATION_ADDRESS + start as u32).to_le_bytes());
            let mut reply = [0u8; MAX_CTO];
            let got = watched.car.command(&upload, &mut reply).expect("answered");
            assert_eq!(reply[0], 0xFF, "SHORT_UPLOAD {got}");
            page[start..start + len].copy_from_slice(&reply[1..=len]);
        }
        let mut reply = [0u8; MAX_CTO];
        watched.car.command(&[0xEA, 0x01, 0], &mut reply);
        let found = watched
            .recorder
            .found(page, Some(reply[3]), 0, "127.0.0.1:5000");
        watched.entries.extend(found);
    }

    fn unlock(&mut self) {
        let seed = self.send(&[0xF8, 0, 0x01]).expect("GET_SEED");
        let key = aer_ccm::xcp::key_for(&SECRET, &seed[2..2 + usize::from(seed[1])]);
        let mut remaining = key.len();
        for chunk in key.chunks(6) {
            let mut unlock = vec![0xF7, remaining as u8];
            unlock.extend_from_slice(chunk);
            assert_eq!(self.send(&unlock).expect("UNLOCK")[0], 0xFF);
            remaining -= chunk.len();
        }
    }

    /// SET_MTA, then `data` as one DOWNLOAD or a master block.
    fn write(&mut self, offset: usize, data: &[u8]) {
        let mut set_mta = vec![0xF6, 0, 0, 0];
        set_mta.extend((CALIBRATION_ADDRESS + offset as u32).to_le_bytes());
        self.send(&set_mta);
        let mut remaining = data.len();
        for (i, chunk) in data.chunks(6).enumerate() {
            let mut packet = vec![if i == 0 { 0xF0 } else { 0xEF }, remaining as u8];
            packet.extend_from_slice(chunk);
            self.send(&packet);
            remaining -= chunk.len();
        }
    }
}

/// What a master does.
#[derive(Debug, Clone)]
enum Step {
    /// One parameter's element (or all of it) set to a value (in or out of its limits).
    Set {
        parameter: usize,
        element: usize,
        whole: bool,
        value: f32,
    },
    /// Any bytes anywhere in the page.
    Raw {
        offset: usize,
        bytes: Vec<u8>,
    },
    Revert,
    EcuPage(u8),
    XcpPage(u8),
    Save,
    /// The car runs on.
    Run(u32),
    /// BUILD_CHECKSUM over the page's first `len` bytes, then a DOWNLOAD with no SET_MTA: it
    /// lands where the checksum left the MTA.
    ChecksumThenWrite {
        len: u8,
        bytes: Vec<u8>,
    },
    /// GET_ID (the MTA on a text), then a DOWNLOAD with no SET_MTA (refused: not memory).
    IdThenWrite(Vec<u8>),
    /// A wrong key, which ends the session; then the master connects again, as the gateway
    /// sees it (the page read anew), and unlocks.
    WrongKey,
}

fn step() -> impl Strategy<Value = Step> {
    prop_oneof![
        6 => (0..PARAMETERS.len(), 0usize..16, any::<bool>(), -50.0f32..5000.0).prop_map(
            |(parameter, element, whole, value)| Step::Set { parameter, element, whole, value }
        ),
        2 => (0..PAGE_LEN, proptest::collection::vec(any::<u8>(), 1..20))
            .prop_map(|(offset, bytes)| Step::Raw { offset, bytes }),
        1 => Just(Step::Revert),
        1 => (0u8..2).prop_map(Step::EcuPage),
        1 => (0u8..2).prop_map(Step::XcpPage),
        1 => Just(Step::Save),
        2 => (1u32..200).prop_map(Step::Run),
        1 => (1u8..100, proptest::collection::vec(any::<u8>(), 1..6))
            .prop_map(|(len, bytes)| Step::ChecksumThenWrite { len, bytes }),
        1 => proptest::collection::vec(any::<u8>(), 1..6).prop_map(Step::IdThenWrite),
        1 => Just(Step::WrongKey),
    ]
}

/// A parked car, or one 5 m/s into an acceleration run.
fn car(driving: bool) -> XcpCar {
    let mut car = power_up(RamFlash::default());
    if driving {
        car.run.retune(ModelParams::NOMINAL, FaultPlan::NONE);
        while car.run.car.chassis.speed_m_s < 5.0 {
            assert!(car.run.now_ms() < 20_000, "the car never moved");
            car.step(&mut NoTap, &mut |_| true);
        }
    }
    car
}

fn play(watched: &mut Watched, step: &Step) {
    match step {
        Step::Set {
            parameter,
            element,
            whole,
            value,
        } => {
            let p = &PARAMETERS[*parameter];
            let element = element % p.count;
            if *whole {
                // Every element, increasing from `value` where the parameter must.
                let bytes: Vec<u8> = (0..p.count)
                    .flat_map(|i| (value + i as f32).to_le_bytes())
                    .collect();
                watched.write(p.offset, &bytes);
            } else {
                watched.write(p.offset + element * 4, &value.to_le_bytes());
            }
        }
        Step::Raw { offset, bytes } => {
            let end = (offset + bytes.len()).min(PAGE_LEN);
            watched.write(*offset, &bytes[..end - offset]);
        }
        Step::Revert => {
            watched.send(&[0xE4, 0, 1, 0, 0]);
        }
        Step::EcuPage(page) => {
            watched.send(&[0xEB, 0x01, 0, *page]);
        }
        Step::XcpPage(page) => {
            watched.send(&[0xEB, 0x02, 0, *page]);
        }
        Step::Save => {
            watched.send(&[0xF9, 0x01, 0, 0]);
        }
        Step::Run(ms) => {
            for _ in 0..*ms {
                watched.car.step(&mut NoTap, &mut |_| true);
            }
        }
        Step::ChecksumThenWrite { len, bytes } => {
            let mut set_mta = vec![0xF6, 0, 0, 0];
            set_mta.extend(CALIBRATION_ADDRESS.to_le_bytes());
            watched.send(&set_mta);
            let mut checksum = vec![0xF3, 0, 0, 0];
            checksum.extend(u32::from(*len).to_le_bytes());
            watched.send(&checksum);
            let mut download = vec![0xF0, bytes.len() as u8];
            download.extend(bytes);
            watched.send(&download);
        }
        Step::IdThenWrite(bytes) => {
            watched.send(&[0xFA, 1]);
            let mut download = vec![0xF0, bytes.len() as u8];
            download.extend(bytes);
            watched.send(&download);
        }
        Step::WrongKey => {
            let seed = watched.send(&[0xF8, 0, 0x01]).expect("GET_SEED");
            if seed[0] == 0xFF && seed[1] > 0 {
                // Sixteen key bytes, every one wrong.
                for (remaining, chunk) in [(16u8, [0u8; 6]), (10, [0; 6]), (4, [0; 6])] {
                    let mut unlock = vec![0xF7, remaining];
                    unlock.extend(&chunk[..usize::from(remaining.min(6))]);
                    watched.send(&unlock);
                }
            }
            watched.reconnect();
            watched.unlock();
        }
    }
}

/// The record's values at the end are the CCM's page, element for element, and its page.
fn assert_record_matches_the_ccm(watched: &Watched) {
    let state = watched.car.run.ccm.calibration_state();
    let working = state.page(Page::Working);
    let recorded = values_at_end(&watched.entries);
    for p in &PARAMETERS {
        for index in 0..p.count {
            let element = (p.count > 1).then_some(index as u32);
            let expected = p.value(working, index).expect("in the page");
            let found = recorded
                .iter()
                .find(|(name, e, _)| name == p.name && *e == element)
                .map(|(_, _, v)| *v);
            assert_eq!(found, Some(expected), "{}[{index}]", p.name);
        }
    }
    let page = watched
        .entries
        .iter()
        .rev()
        .find(|e| e.parameter == ECU_PAGE && e.accepted)
        .and_then(|e| e.new);
    assert_eq!(page, Some(f64::from(state.ecu_page().number())), "ECU page");
    assert_eq!(
        watched.recorder.checksum(),
        Some(state.status().ccm_cal_checksum),
        "the checksum CCM_Calibration carries"
    );
    for entry in &watched.entries {
        assert_eq!(
            entry.accepted,
            entry.reason.is_empty(),
            "a refusal says why, an acceptance nothing: {entry}"
        );
        if entry.kind != Kind::Found {
            assert!(entry.checksum.is_some(), "{entry}");
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    #[test]
    fn the_record_replays_to_the_ccms_page(
        driving in any::<bool>(),
        steps in proptest::collection::vec(step(), 1..24),
    ) {
        let mut watched = Watched::connect(car(driving));
        watched.unlock();
        for step in &steps {
            play(&mut watched, step);
        }
        assert_record_matches_the_ccm(&watched);
    }
}

#[test]
fn a_refused_change_names_its_reason_and_an_accepted_one_its_old_and_new_value() {
    let position = |name: &str| {
        PARAMETERS
            .iter()
            .position(|p| p.name == name)
            .expect("in the schema")
    };
    let set = |parameter, value| Step::Set {
        parameter,
        element: 0,
        whole: false,
        value,
    };
    let (threshold, launch_kp) = (position("traction_slip_threshold"), position("launch_kp"));
    let mut watched = Watched::connect(car(true));
    play(&mut watched, &set(threshold, 0.12)); // locked
    watched.unlock();
    play(&mut watched, &set(threshold, 0.12));
    play(&mut watched, &set(threshold, 0.75)); // beyond 0.5
    play(&mut watched, &set(launch_kp, 300.0)); // standstill only
    let defaults = aer::calibration::Calibration::DEFAULT.to_page();
    let default = |p: usize| number(PARAMETERS[p].value(&defaults, 0).expect("value"));
    let changes: Vec<String> = watched
        .entries
        .iter()
        .filter(|e| e.kind != Kind::Found)
        .map(|e| e.to_string())
        .collect();
    let master = "(127.0.0.1:5000)";
    assert_eq!(
        changes,
        [
            format!(
                "write traction_slip_threshold {} -> 0.12 refused: calibration is locked (unlock with seed and key first) {master}",
                default(threshold)
            ),
            format!(
                "write traction_slip_threshold {} -> 0.12 accepted {master}",
                default(threshold)
            ),
            format!(
                "write traction_slip_threshold 0.12 -> 0.75 refused: out of range 0.02-0.5 {master}"
            ),
            format!(
                "write launch_kp {} -> 300 refused: only at standstill {master}",
                default(launch_kp)
            ),
        ]
    );
    assert_record_matches_the_ccm(&watched);
}
