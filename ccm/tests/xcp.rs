//! The CCM's XCP slave over its real tables: the EPK, reads of the pages and measurements,
//! calibration locked until the seed's key (HMAC-SHA256 with the team's secret) unlocks it,
//! writes checked by the CCM (out of range, not allowed while moving: refused, value kept),
//! and STORE_CAL_REQ saving to flash only when parked. Byte layouts as ASAM MCD-1 XCP gives
//! them (Intel byte order, CAN's 8-byte packets).

use aer::calibration::xcp::{CALIBRATION_ADDRESS, EPK, INTERNALS_ADDRESS, TELEMETRY_ADDRESS};
use aer::calibration::{Internals, PARAMETERS, VehicleState};
use aer_ccm::calibration::state::CalibrationState;
use aer_ccm::calibration::store::{CalibrationStore, RamFlash, Startup};
use aer_ccm::calibration::{self, Calibration};
use aer_ccm::xcp::{SECRET_LEN, SeedKey, XcpNode, key_for};

const SECRET: [u8; SECRET_LEN] = *b"test secret, not the team's one!";
const PARKED: VehicleState = VehicleState {
    moving: false,
    tractive_live: false,
};
const DRIVING: VehicleState = VehicleState {
    moving: true,
    tractive_live: true,
};

const ERR: u8 = 0xFE;
const ERR_OUT_OF_RANGE: u8 = 0x22;
const ERR_WRITE_PROTECTED: u8 = 0x23;
const ERR_ACCESS_DENIED: u8 = 0x24;
const ERR_ACCESS_LOCKED: u8 = 0x25;

struct Ecu {
    node: XcpNode<RamFlash>,
    calibration: CalibrationState,
    vehicle: VehicleState,
}

impl Ecu {
    fn new() -> Self {
        let mut flash = RamFlash::default();
        let (store, loaded) = CalibrationStore::load(&mut flash, calibration::EPK);
        Self {
            node: XcpNode::new(SeedKey::new(Some(SECRET), 0x1234_5678), store, flash),
            calibration: CalibrationState::new(loaded.calibration, loaded.startup),
            vehicle: PARKED,
        }
    }

    fn command(&mut self, packet: &[u8]) -> Vec<u8> {
        let mut reply = [0u8; 8];
        let len = self
            .node
            .command(&mut self.calibration, self.vehicle, packet, 0, &mut reply)
            .unwrap_or(0);
        reply[..len].to_vec()
    }

    fn ok(&mut self, packet: &[u8]) -> Vec<u8> {
        let reply = self.command(packet);
        assert_eq!(
            reply.first(),
            Some(&0xFF),
            "{packet:02X?} answered {reply:02X?}"
        );
        reply
    }

    fn set_mta(&mut self, address: u32) {
        let mut packet = vec![0xF6, 0, 0, 0];
        packet.extend_from_slice(&address.to_le_bytes());
        self.ok(&packet);
    }

    fn read(&mut self, address: u32, len: u8) -> Vec<u8> {
        let mut packet = vec![0xF4, len, 0, 0];
        packet.extend_from_slice(&address.to_le_bytes());
        self.command(&packet)
    }

    fn write(&mut self, address: u32, data: &[u8]) -> Vec<u8> {
        self.set_mta(address);
        let mut packet = vec![0xF0, data.len() as u8];
        packet.extend_from_slice(data);
        self.command(&packet)
    }

    fn unlock(&mut self, secret: &[u8; SECRET_LEN]) -> Vec<u8> {
        let seed = self.ok(&[0xF8, 0, 0x01]);
        let key = key_for(secret, &seed[2..2 + usize::from(seed[1])]);
        let mut remaining = key.len();
        let mut reply = Vec::new();
        for chunk in key.chunks(6) {
            let mut packet = vec![0xF7, remaining as u8];
            packet.extend_from_slice(chunk);
            reply = self.command(&packet);
            remaining -= chunk.len();
        }
        reply
    }
}

fn address_of(name: &str) -> u32 {
    let parameter = PARAMETERS
        .iter()
        .find(|p| p.name == name)
        .unwrap_or_else(|| panic!("no parameter {name}"));
    CALIBRATION_ADDRESS + parameter.offset as u32
}

#[test]
fn the_epk_is_the_schemas_and_every_parameter_reads_its_default() {
    let mut ecu = Ecu::new();
    ecu.ok(&[0xFF, 0]);
    // GET_ID type 5 (EPK), then UPLOAD it in packets of up to 7 bytes.
    let id = ecu.ok(&[0xFA, 5]);
    let len = u32::from_le_bytes([id[4], id[5], id[6], id[7]]) as usize;
    let mut epk = Vec::new();
    while epk.len() < len {
        let chunk = (len - epk.len()).min(7) as u8;
        epk.extend_from_slice(&ecu.ok(&[0xF5, chunk])[1..=usize::from(chunk)]);
    }
    assert_eq!(epk, EPK.as_bytes());
    let defaults = Calibration::DEFAULT.to_page();
    for parameter in &PARAMETERS {
        for (index, element) in defaults[parameter.offset..parameter.offset + parameter.len()]
            .chunks(4)
            .enumerate()
        {
            let address = CALIBRATION_ADDRESS + (parameter.offset + 4 * index) as u32;
            assert_eq!(ecu.read(address, 4)[1..], *element, "{}", parameter.name);
        }
    }
}

#[test]
fn measurements_read_the_last_telemetry_and_internals_and_nothing_else_is_mapped() {
    let mut ecu = Ecu::new();
    ecu.node.measurements.telemetry[6] = 0xAB;
    ecu.node.measurements.internals = Internals {
        slip_ratio: 0.125,
        ..Internals::default()
    }
    .to_bytes();
    ecu.ok(&[0xFF, 0]);
    assert_eq!(ecu.read(TELEMETRY_ADDRESS + 6, 1), [0xFF, 0xAB]);
    assert_eq!(
        ecu.read(INTERNALS_ADDRESS + 16, 4)[1..],
        0.125f32.to_le_bytes()
    );
    for unmapped in [
        0,
        0x2000_0000,
        TELEMETRY_ADDRESS - 1,
        INTERNALS_ADDRESS + 34,
    ] {
        assert_eq!(
            ecu.read(unmapped, 4),
            [ERR, ERR_ACCESS_DENIED],
            "{unmapped:#X}"
        );
    }
}

#[test]
fn calibration_is_locked_until_the_seeds_key_unlocks_it() {
    let mut ecu = Ecu::new();
    ecu.ok(&[0xFF, 0]);
    let gain = address_of("traction_kp");
    assert_eq!(
        ecu.write(gain, &650.0f32.to_le_bytes()),
        [ERR, ERR_ACCESS_LOCKED]
    );
    // The wrong secret's key is refused (and ends the session, as XCP says).
    let reply = ecu.unlock(b"not the secret, just 32 bytes!!!");
    assert_eq!(reply, [ERR, ERR_ACCESS_LOCKED]);
    ecu.ok(&[0xFF, 0]);
    let reply = ecu.unlock(&SECRET);
    assert_eq!(reply[0], 0xFF);
    assert_eq!(reply[1] & 0x01, 0, "CAL/PAG unlocked");
    assert_eq!(ecu.write(gain, &650.0f32.to_le_bytes()), [0xFF]);
    assert_eq!(ecu.calibration.active().traction_kp, 650.0);
    // Locked again at the next connect.
    ecu.ok(&[0xFF, 0]);
    assert_eq!(
        ecu.write(gain, &700.0f32.to_le_bytes()),
        [ERR, ERR_ACCESS_LOCKED]
    );
    assert_eq!(ecu.calibration.active().traction_kp, 650.0);
}

#[test]
fn an_image_without_a_secret_never_unlocks() {
    let mut ecu = Ecu::new();
    ecu.node.keys = SeedKey::new(None, 7);
    ecu.ok(&[0xFF, 0]);
    assert_eq!(ecu.unlock(&SECRET), [ERR, ERR_ACCESS_LOCKED]);
}

#[test]
fn refused_writes_keep_the_value_and_answer_what_a_master_reports() {
    let mut ecu = Ecu::new();
    ecu.ok(&[0xFF, 0]);
    assert_eq!(ecu.unlock(&SECRET)[0], 0xFF);
    let launch_gain = address_of("launch_kp");
    // Out of the schema's limits.
    assert_eq!(
        ecu.write(launch_gain, &1.0e6f32.to_le_bytes()),
        [ERR, ERR_OUT_OF_RANGE]
    );
    // A standstill-only parameter while the car moves.
    ecu.vehicle = DRIVING;
    assert_eq!(
        ecu.write(launch_gain, &150.0f32.to_le_bytes()),
        [ERR, ERR_WRITE_PROTECTED]
    );
    assert_eq!(
        ecu.read(launch_gain, 4)[1..],
        Calibration::DEFAULT.launch_kp.to_le_bytes()
    );
    // The telemetry is read-only; nothing unmapped is written.
    assert_eq!(
        ecu.write(TELEMETRY_ADDRESS, &[0]),
        [ERR, ERR_WRITE_PROTECTED]
    );
    assert_eq!(ecu.write(0x0800_0000, &[0]), [ERR, ERR_ACCESS_DENIED]);
    assert_eq!(*ecu.calibration.active(), Calibration::DEFAULT);
}

#[test]
fn store_cal_req_saves_only_when_parked_and_start_up_loads_it() {
    let mut ecu = Ecu::new();
    ecu.ok(&[0xFF, 0]);
    assert_eq!(ecu.unlock(&SECRET)[0], 0xFF);
    assert_eq!(
        ecu.write(address_of("traction_kp"), &650.0f32.to_le_bytes()),
        [0xFF]
    );
    ecu.vehicle = DRIVING;
    assert_eq!(ecu.command(&[0xF9, 0x01, 0, 0]), [ERR, ERR_WRITE_PROTECTED]);
    ecu.vehicle = PARKED;
    ecu.ok(&[0xF9, 0x01, 0, 0]);
    assert!(!ecu.calibration.status().ccm_cal_unsaved);
    let (_, loaded) = CalibrationStore::load(&mut ecu.node.flash, calibration::EPK);
    assert_eq!(
        loaded.startup,
        Startup::Saved {
            slot: aer_ccm::calibration::store::Slot::A,
            generation: 1
        }
    );
    assert_eq!(loaded.calibration.traction_kp, 650.0);
}
