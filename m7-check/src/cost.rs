//! Operations whose cost on the Cortex-M7 the emulated run measures (instructions under QEMU's
//! instruction counting); the host run does not print them.

use aer::telemetry::{Telemetry, TelemetryHeader};
use aer_ccm::calibration::Calibration;
use aer_ccm::{Ccm, DriverInputs, SensorSample};
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
pub const COSTS: [Cost; 4] = [
    Cost {
        name: "ccm 100 Hz control step (DRIVING, throttle)",
        iterations: 1_000,
        run: ccm_control,
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

fn pcc_step(iterations: u32) {
    let mut pcc = Precharge::new(PrechargeConfig::CAR, 0);
    for i in 0..iterations {
        let relays = pcc.step(&Inputs {
            now_ms: i * 10,
            accumulator_v: 400.0,
            tractive_v: (i % 400) as f32,
            bms_last_seen_ms: Some(i * 10),
            charger_safety: false,
        });
        core::hint::black_box(relays);
    }
}
