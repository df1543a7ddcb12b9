//! Precharge sessions in closed loop: the circuit model feeds V/F pulse trains into the
//! measurement chain, BMS frames go through the generated codec into the link monitor, and
//! the state machine drives the modelled relays, every 10 ms as on the car.

use crate::Digest;
use aer::can::OrionPackStatus;
use aer_car_model::precharge::{PrechargePlant, PulseGenerator};
use aer_flexcan::CanFrame;
use aer_pcc::measurement::VoltageChannel;
use aer_pcc::{
    Inputs, Precharge, PrechargeConfig, Relays, State, TASK_PERIOD_MS, VfConfig, bms::BmsLink,
};
use core::fmt::Write;
use embedded_can::{Frame, StandardId};

/// One scripted session.
struct Scenario {
    name: &'static str,
    /// Precharge RC time constant (ms): 3,800 reaches 90 % at 8.75 s.
    precharge_tau_ms: f32,
    /// Length of the session (ms).
    duration_ms: u32,
    /// The shutdown circuit is open during [from, to) (ms).
    shutdown_open: Option<(u32, u32)>,
    /// The BMS's charger-safety output is on from this time (ms).
    charger_from_ms: Option<u32>,
    /// The BMS falls silent from this time (ms).
    bms_silent_from_ms: Option<u32>,
}

const SCENARIOS: [Scenario; 4] = [
    Scenario {
        name: "drive-shutdown-recover-charge-bms-loss",
        precharge_tau_ms: 3_800.0,
        duration_ms: 45_000,
        shutdown_open: Some((12_000, 13_000)),
        charger_from_ms: Some(32_000),
        bms_silent_from_ms: Some(38_000),
    },
    Scenario {
        name: "too-fast",
        precharge_tau_ms: 1_000.0,
        duration_ms: 6_000,
        shutdown_open: None,
        charger_from_ms: None,
        bms_silent_from_ms: None,
    },
    Scenario {
        name: "too-slow",
        precharge_tau_ms: 6_000.0,
        duration_ms: 12_000,
        shutdown_open: None,
        charger_from_ms: None,
        bms_silent_from_ms: None,
    },
    Scenario {
        name: "noisy-pack-lost",
        precharge_tau_ms: 3_900.0,
        duration_ms: 20_000,
        shutdown_open: None,
        charger_from_ms: None,
        bms_silent_from_ms: None,
    },
];

/// Runs every scenario, printing each state change and a digest of all status frames.
pub fn scenarios(out: &mut impl Write) -> core::fmt::Result {
    for scenario in &SCENARIOS {
        run(scenario, out)?;
    }
    Ok(())
}

fn run(scenario: &Scenario, out: &mut impl Write) -> core::fmt::Result {
    let vf = VfConfig::PCC_BOARD;
    let config = PrechargeConfig::CAR;
    let mut plant = PrechargePlant::new(398.4, scenario.precharge_tau_ms, 400.0);
    let mut accumulator = VoltageChannel::new(vf, TASK_PERIOD_MS);
    let mut tractive = VoltageChannel::new(vf, TASK_PERIOD_MS);
    let mut accumulator_pulses = PulseGenerator::default();
    let mut tractive_pulses = PulseGenerator::default();
    let mut pcc = Precharge::new(config, 0);
    let mut bms = BmsLink::default();
    let mut relays = Relays::ALL_OPEN;
    let mut digest = Digest::default();
    let mut last_state = None;
    let within =
        |window: Option<(u32, u32)>, t: u32| window.is_some_and(|(a, b)| (a..b).contains(&t));

    let mut now_ms = 0;
    while now_ms < scenario.duration_ms {
        let start_us = now_ms.wrapping_mul(1_000);
        now_ms += TASK_PERIOD_MS;
        let period_us = TASK_PERIOD_MS * 1_000;
        // The pack sags a little under load and ripples, as a real measurement does.
        if scenario.name == "noisy-pack-lost" && now_ms >= 15_000 {
            plant.accumulator_v = 0.0;
        }
        plant.shutdown_closed = !within(scenario.shutdown_open, now_ms);
        plant.advance(relays, TASK_PERIOD_MS as f32);
        let ripple = if now_ms % 20 == 0 { 0.6 } else { -0.6 };
        accumulator_pulses.run(
            start_us,
            period_us,
            VoltageChannel::hz_for_volts(&vf, plant.accumulator_v + ripple),
            |at_us| accumulator.on_edge(at_us),
        );
        tractive_pulses.run(
            start_us,
            period_us,
            VoltageChannel::hz_for_volts(&vf, plant.tractive_v),
            |at_us| tractive.on_edge(at_us),
        );

        let charger = scenario.charger_from_ms.is_some_and(|from| now_ms >= from);
        let bms_talks = scenario.bms_silent_from_ms.is_none_or(|from| now_ms < from);
        if bms_talks && now_ms % 100 == 0 {
            if let Some(frame) = pack_status(plant.accumulator_v, charger) {
                bms.on_frame(now_ms, &frame);
            }
        }

        let accumulator_sample = accumulator.sample(now_ms * 1_000);
        let tractive_sample = tractive.sample(now_ms * 1_000);
        let inputs = Inputs {
            now_ms,
            accumulator_v: accumulator_sample.volts,
            tractive_v: tractive_sample.volts,
            raw_v: [accumulator_sample.raw_volts, tractive_sample.raw_volts],
            pulses: [accumulator_sample.pulses, tractive_sample.pulses],
            bms_last_seen_ms: bms.last_seen_ms(),
            charger_safety: bms.charger_safety(),
            resistor_c: [Some(plant.resistor.celsius); 2],
        };
        relays = pcc.step(&inputs);
        let mut status = [0u8; 8];
        if pcc.status().encode(&mut status).is_err() {
            writeln!(
                out,
                "pcc {} t={now_ms} status did not encode",
                scenario.name
            )?;
        }
        digest.bytes(&status);

        if last_state != Some(pcc.state()) {
            last_state = Some(pcc.state());
            writeln!(
                out,
                "pcc {} t={now_ms} {:?} {:?} {:?} acc={:.3} ts={:.3} progress={:.3}",
                scenario.name,
                pcc.state(),
                pcc.errors(),
                relays,
                pcc.accumulator_v(),
                pcc.tractive_v(),
                pcc.progress_percent()
            )?;
        }
    }
    let final_state: State = pcc.state();
    writeln!(
        out,
        "pcc {} end {:?} bms-decode-errors={} status-digest={:08x}",
        scenario.name,
        final_state,
        bms.decode_errors,
        digest.value()
    )
}

/// An Orion pack-status frame, through the generated encoder.
fn pack_status(pack_v: f32, charger_safety: bool) -> Option<CanFrame> {
    let status = OrionPackStatus {
        orion_pack_current: 0.0,
        orion_pack_inst_voltage: f64::from((pack_v * 10.0) as u16) / 10.0,
        orion_pack_soc: 80.0,
        orion_relay_state: if charger_safety { 0b101 } else { 0b001 },
    };
    let mut data = [0u8; 8];
    if status.encode(&mut data).is_err() {
        data = [0xFF; 8];
    }
    CanFrame::new(StandardId::new(0x6B0)?, &data)
}
