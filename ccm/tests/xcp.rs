//! The CCM's XCP slave over its real tables: the EPK, reads of the pages and measurements,
//! calibration locked until the seed's key (HMAC-SHA256 with the team's secret) unlocks it,
//! writes checked by the CCM (out of range, not allowed while moving: refused, value kept),
//! and STORE_CAL_REQ saving to flash only when parked. Byte layouts as ASAM MCD-1 XCP gives
//! them (Intel byte order, CAN's 8-byte packets).

use aer::calibration::xcp::{
    CALIBRATION_ADDRESS, EPK, INTERNALS_ADDRESS, INTERNALS_LEN, TELEMETRY_ADDRESS, UNLOCK_DELAY_MS,
    XCP_STATUS_ADDRESS, XCP_STATUS_LEN,
};
use aer::calibration::{INTERNALS, Internals, PARAMETERS, VehicleState};
use aer_ccm::calibration::state::CalibrationState;
use aer_ccm::calibration::store::{CalibrationStore, RamFlash, Startup};
use aer_ccm::calibration::{self, Calibration};
use aer_ccm::xcp::{SECRET_LEN, SeedKey, XcpNode, key_for};
use aer_xcp::reason;

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
    /// The slave's clock (us).
    now_us: u32,
}

impl Ecu {
    fn new() -> Self {
        let mut flash = RamFlash::default();
        let (store, loaded) = CalibrationStore::load(&mut flash, calibration::EPK);
        Self {
            node: XcpNode::new(
                SeedKey::new(Some(SECRET), Some(&[0x12; 32]), b"test"),
                store,
                flash,
            ),
            calibration: CalibrationState::new(loaded.calibration, loaded.startup),
            vehicle: PARKED,
            now_us: 0,
        }
    }

    fn command(&mut self, packet: &[u8]) -> Vec<u8> {
        let mut reply = [0u8; 8];
        let len = self
            .node
            .command(
                &mut self.calibration,
                self.vehicle,
                packet,
                self.now_us,
                &mut reply,
            )
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
    let slip = INTERNALS
        .iter()
        .find(|i| i.name == "slip_ratio")
        .expect("slip_ratio");
    assert_eq!(
        ecu.read(INTERNALS_ADDRESS + slip.offset as u32, 4)[1..],
        0.125f32.to_le_bytes()
    );
    // The slave's own block is readable, never writable.
    assert_eq!(ecu.read(XCP_STATUS_ADDRESS + 48, 4)[0], 0xFF);
    assert_eq!(
        ecu.write(XCP_STATUS_ADDRESS, &[0; 4]),
        [ERR, ERR_ACCESS_LOCKED],
        "locked first"
    );
    for unmapped in [
        0,
        0x2000_0000,
        TELEMETRY_ADDRESS - 1,
        INTERNALS_ADDRESS + INTERNALS_LEN as u32 - 2,
        XCP_STATUS_ADDRESS + XCP_STATUS_LEN as u32 - 2,
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
    // The wrong secret's key is refused (and ends the session, as XCP says); the next seed
    // only after the delay.
    let reply = ecu.unlock(b"not the secret, just 32 bytes!!!");
    assert_eq!(reply, [ERR, ERR_ACCESS_LOCKED]);
    ecu.ok(&[0xFF, 0]);
    assert_eq!(ecu.command(&[0xF8, 0, 0x01]), [ERR, 0x33], "too soon");
    ecu.now_us += UNLOCK_DELAY_MS * 1_000;
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
    ecu.node.keys = SeedKey::new(None, Some(&[7; 32]), b"test");
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

/// Status-block offsets (`aer_xcp::status`): the last refusal's fields, then the counters.
const REFUSED_REASON: usize = 6;
const REFUSED_ELEMENT: usize = 7;
const REFUSED_ITEM: usize = 8;
const REFUSED_VALUE: usize = 12;
const REFUSED_LIMIT: usize = 16;

impl Ecu {
    /// The slave's status block, read over XCP as a tool reads it.
    fn status(&mut self) -> Vec<u8> {
        let mut block = Vec::new();
        let mut address = XCP_STATUS_ADDRESS;
        while block.len() < XCP_STATUS_LEN {
            let len = (XCP_STATUS_LEN - block.len()).min(4) as u8;
            let reply = self.read(address, len);
            assert_eq!(reply[0], 0xFF, "{reply:02X?}");
            block.extend_from_slice(&reply[1..]);
            address += u32::from(len);
        }
        block
    }

    fn refused(&mut self) -> (u8, u16, u8, f32, f32) {
        let block = self.status();
        let f32_at = |at: usize| f32::from_le_bytes(block[at..at + 4].try_into().unwrap());
        (
            block[REFUSED_REASON],
            u16::from_le_bytes([block[REFUSED_ITEM], block[REFUSED_ITEM + 1]]),
            block[REFUSED_ELEMENT],
            f32_at(REFUSED_VALUE),
            f32_at(REFUSED_LIMIT),
        )
    }
}

fn item(name: &str) -> u16 {
    PARAMETERS.iter().position(|p| p.name == name).unwrap() as u16
}

/// Every refusal says why in the status block a tool reads as measurements: the parameter
/// (its index in the A2L's `xcp.item` table), the element, the value and the limit; the
/// condition a write needs; a read-only address.
#[test]
fn the_status_block_names_each_refusals_parameter_element_value_and_limit() {
    let mut ecu = Ecu::new();
    ecu.ok(&[0xFF, 0]);
    ecu.unlock(&SECRET);
    let kp = PARAMETERS.iter().find(|p| p.name == "traction_kp").unwrap();
    assert_eq!(
        ecu.write(
            address_of("traction_kp"),
            &(kp.max as f32 + 1.0).to_le_bytes()
        ),
        [ERR, ERR_OUT_OF_RANGE]
    );
    assert_eq!(
        ecu.refused(),
        (
            reason::ABOVE_MAX,
            item("traction_kp"),
            0,
            kp.max as f32 + 1.0,
            kp.max as f32
        )
    );
    // A subnormal is not a number the car can use.
    assert_eq!(
        ecu.write(address_of("traction_kp"), &1e-45f32.to_le_bytes()),
        [ERR, ERR_OUT_OF_RANGE]
    );
    assert_eq!(ecu.refused().0, reason::NOT_A_NUMBER);
    // The launch curve's axis must increase: its third point at the second's value.
    let axis = address_of("launch_slip_target_axis");
    let second = Calibration::DEFAULT.launch_slip_target_axis[1];
    assert_eq!(
        ecu.write(axis + 8, &second.to_le_bytes()),
        [ERR, ERR_OUT_OF_RANGE]
    );
    assert_eq!(
        ecu.refused(),
        (
            reason::NOT_INCREASING,
            item("launch_slip_target_axis"),
            2,
            second,
            second
        )
    );
    // A sensor cross-check: a shock's compressed end on its extended one.
    let extended = Calibration::DEFAULT.shock_extended_v[3];
    assert_eq!(
        ecu.write(
            address_of("shock_compressed_v") + 12,
            &extended.to_le_bytes()
        ),
        [ERR, ERR_OUT_OF_RANGE]
    );
    let (why, which, element, span, least) = ecu.refused();
    assert_eq!(
        (why, which, element),
        (reason::CROSS_CHECK, item("shock_compressed_v"), 3)
    );
    assert_eq!(span, 0.0);
    assert!(least > 0.0);
    // A condition: the launch gains change at standstill only.
    ecu.vehicle = DRIVING;
    assert_eq!(
        ecu.write(address_of("launch_kp"), &100.0f32.to_le_bytes()),
        [ERR, ERR_WRITE_PROTECTED]
    );
    assert_eq!(ecu.refused().0, reason::NEEDS_STANDSTILL);
    assert_eq!(ecu.refused().1, item("launch_kp"));
    // Read-only memory.
    assert_eq!(
        ecu.write(TELEMETRY_ADDRESS, &[0; 4]),
        [ERR, ERR_WRITE_PROTECTED]
    );
    assert_eq!(ecu.refused().0, reason::READ_ONLY);
    // The count of refusals and the command code are there too.
    let block = ecu.status();
    assert_eq!(u32::from_le_bytes(block[0..4].try_into().unwrap()), 6);
    assert_eq!(block[4], 0xF0, "DOWNLOAD");
    assert_eq!(block[5], ERR_WRITE_PROTECTED);
}
