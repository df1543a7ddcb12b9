//! Operations whose cost on the Cortex-M7 the emulated run measures (instructions under QEMU's
//! instruction counting); the host run does not print them.

use aer::calibration::xcp::{EVENT_CONTROL, INTERNALS_ADDRESS, TELEMETRY_ADDRESS};
use aer::telemetry::{Telemetry, TelemetryHeader};
use aer_ccm::calibration::Calibration;
use aer_ccm::calibration::state::CalibrationState;
use aer_ccm::calibration::store::{CalibrationStore, RamFlash, Startup};
use aer_ccm::xcp::{SeedKey, XcpNode};
use aer_ccm::{Ccm, DriverInputs, SensorSample};
use aer_pcc::measurement::Pulses;
use aer_pcc::{Inputs, Precharge, PrechargeConfig};

/// A measured operation: `run` performs it `iterations` times.
pub struct Cost {
    /// What it is.
    pub name: &'static str,
    /// Repetitions per measurement.
    pub iterations: u32,
    /// Runs the operation `iterations` times.
    pub run: fn(u32),
}

/// Everything measured.
pub const COSTS: [Cost; 8] = [
    Cost {
        name: "ccm 100 Hz control step (DRIVING, throttle)",
        iterations: 1_000,
        run: ccm_control,
    },
    Cost {
        name: "ccm XCP control event, no DAQ list running",
        iterations: 1_000,
        run: xcp_event_idle,
    },
    Cost {
        name: "ccm XCP control event, a full DAQ list (2 ODTs x 7 bytes: the frame budget at 100 Hz)",
        iterations: 1_000,
        run: xcp_event_full,
    },
    Cost {
        name: "ccm XCP command: SHORT_UPLOAD of a parameter",
        iterations: 1_000,
        run: xcp_upload,
    },
    Cost {
        name: "ccm 1 kHz sensor step",
        iterations: 1_000,
        run: ccm_sample,
    },
    Cost {
        name: "telemetry snapshot + pack",
        iterations: 1_000,
        run: telemetry_pack,
    },
    Cost {
        name: "pcc 10 ms control step",
        iterations: 1_000,
        run: pcc_step,
    },
    Cost {
        name: "ccm panic: the published stop frames into CAN2's mailboxes (panic to first frame queued)",
        iterations: 1_000,
        run: panic_stop,
    },
];

fn ccm_control(iterations: u32) {
    // Full throttle, 2 s into the acceleration run: the power ceiling binds.
    let (mut ccm, now) = crate::ccm::ccm_driving(2_000);
    // Fresh bus data stays valid within its timeouts, so step at the same time repeatedly.
    for _ in 0..iterations {
        let outputs = ccm.control(DriverInputs::default(), now, now.wrapping_mul(1_000));
        core::hint::black_box(outputs);
    }
}

fn ccm_sample(iterations: u32) {
    let mut ccm = Ccm::new(Calibration::DEFAULT);
    let sample = SensorSample {
        apps_v: [Some(0.75), Some(1.125)],
        brake_v: (0.6, 0.6),
        shock_raw: [4000; 4],
    };
    for i in 0..iterations {
        ccm.sample(core::hint::black_box(&sample), i);
    }
}

fn telemetry_pack(iterations: u32) {
    let (ccm, _) = crate::ccm::ccm_driving(2_000);
    let mut packet = [0u8; Telemetry::LEN];
    for i in 0..iterations {
        let snapshot = ccm.snapshot();
        let header = TelemetryHeader {
            sequence: i as u16,
            timestamp_us: i,
        };
        core::hint::black_box(snapshot.pack(header, &mut packet));
    }
}

/// The panic handler's work before the reset, on RAM laid out as FlexCAN's register block (the
/// emulated Cortex-M7 has no FlexCAN): take the newest published stop frames, build the CAN
/// frames, check every transmit mailbox for a pending frame (none here: a pending one adds its
/// abort's bounded wait), write them into the mailboxes. The frames then need their wire time
/// (an 8-byte extended frame is at most about 0.3 ms at 500 kbit/s).
fn panic_stop(iterations: u32) {
    use aer_ccm::stop::StopFrames;
    use aer_flexcan::emergency::EmergencyTx;
    let (ccm, _) = crate::ccm::ccm_driving(2_000);
    let stop = StopFrames::new();
    if let Ok(frames) = ccm.stop_frames() {
        stop.publish(&frames);
    }
    // DBG1 (0x58) reads 0: no ERR006032 wait.
    let mut block = [0u32; 0x80 / 4 + 16 * 4];
    for _ in 0..iterations {
        let can = stop.latest_frames();
        // The mailboxes free again for the next round (the frames "left").
        block.iter_mut().for_each(|word| *word = 0);
        // SAFETY: `block` is laid out as the register block and only this loop touches it.
        let mut tx = unsafe { EmergencyTx::new(block.as_mut_ptr()) };
        core::hint::black_box(tx.queue(can, 1));
    }
    assert!(
        stop.latest().len() >= 2,
        "the DTI's stop frames were published"
    );
}

fn pcc_step(iterations: u32) {
    let mut pcc = Precharge::new(PrechargeConfig::CAR, 0);
    for i in 0..iterations {
        let relays = pcc.step(&Inputs {
            now_ms: i * 10,
            accumulator_v: 400.0,
            tractive_v: (i % 400) as f32,
            raw_v: [400.0, (i % 400) as f32],
            pulses: [Pulses::Live; 2],
            bms_last_seen_ms: Some(i * 10),
            charger_safety: false,
            resistor_c: [Some(25.0); 2],
        });
        core::hint::black_box(relays);
    }
}

/// An XCP node connected to a master, with the measurements of a driving CCM; `daq` sets up
/// and starts the full DAQ list on the control event first.
fn xcp_node(daq: bool) -> (XcpNode<RamFlash>, CalibrationState) {
    let (ccm, _) = crate::ccm::ccm_driving(2_000);
    let mut node = XcpNode::new(
        SeedKey::new(None, None, &[]),
        CalibrationStore::default(),
        RamFlash::default(),
    );
    node.measurements = ccm.measurements();
    let mut calibration = CalibrationState::new(Calibration::DEFAULT, Startup::NoneSaved);
    let vehicle = ccm.vehicle_state();
    let mut command = |node: &mut XcpNode<RamFlash>, packet: &[u8]| {
        let mut reply = [0u8; 8];
        node.command(&mut calibration, vehicle, packet, 0, &mut reply);
    };
    command(&mut node, &[0xFF, 0]);
    if daq {
        let entry = |address: u32, size: u8| {
            let [a0, a1, a2, a3] = address.to_le_bytes();
            [0xE1, 0xFF, size, 0, a0, a1, a2, a3]
        };
        let setup: [&[u8]; 16] = [
            &[0xD6],
            &[0xD5, 0, 1, 0],
            &[0xD4, 0, 0, 0, 2],
            &[0xD3, 0, 0, 0, 0, 3],
            &[0xD3, 0, 0, 0, 1, 3],
            &[0xE2, 0, 0, 0, 0, 0],
            &entry(INTERNALS_ADDRESS, 4),
            &entry(TELEMETRY_ADDRESS + 4, 2),
            &entry(TELEMETRY_ADDRESS + 10, 1),
            &[0xE2, 0, 0, 0, 1, 0],
            &entry(INTERNALS_ADDRESS + 16, 4),
            &entry(TELEMETRY_ADDRESS + 6, 2),
            &entry(TELEMETRY_ADDRESS + 11, 1),
            &[0xE0, 0, 0, 0, EVENT_CONTROL as u8, 0, 1, 0],
            &[0xDE, 2, 0, 0],
            &[0xDD, 1],
        ];
        for packet in setup {
            command(&mut node, packet);
        }
        assert!(node.slave.is_daq_running(), "the DAQ list runs");
    }
    (node, calibration)
}

fn xcp_event(iterations: u32, daq: bool) {
    let (mut node, mut calibration) = xcp_node(daq);
    let mut sent = 0u32;
    for i in 0..iterations {
        let report = node.event(&mut calibration, EVENT_CONTROL, i, &mut |dto| {
            core::hint::black_box(dto);
            true
        });
        sent += report.sent;
    }
    // Two packets per event with the list running, none without.
    assert_eq!(sent, if daq { 2 * iterations } else { 0 });
}

fn xcp_event_idle(iterations: u32) {
    xcp_event(iterations, false);
}

fn xcp_event_full(iterations: u32) {
    xcp_event(iterations, true);
}

fn xcp_upload(iterations: u32) {
    let (mut node, mut calibration) = xcp_node(false);
    let [a0, a1, a2, a3] = aer::calibration::xcp::CALIBRATION_ADDRESS.to_le_bytes();
    let packet = [0xF4, 4, 0, 0, a0, a1, a2, a3];
    let vehicle = aer::calibration::VehicleState {
        moving: true,
        tractive_live: true,
    };
    for i in 0..iterations {
        let mut reply = [0u8; 8];
        let answer = node.command(&mut calibration, vehicle, &packet, i, &mut reply);
        core::hint::black_box((answer, reply));
    }
}

#[cfg(test)]
mod tests {
    use super::COSTS;

    /// Every cost runs on the host too (its assertions: the DAQ list runs, two packets per
    /// event), so a broken set-up fails here before QEMU measures it.
    #[test]
    fn every_cost_runs() {
        for cost in &COSTS {
            (cost.run)(3);
        }
    }
}
