//! The closed-loop car model as a live source: the CCM's own logic drives a simulated car
//! round an autocross course (`aer-car-model`), and every frame on both buses, the telemetry
//! over ISO-TP included, is handed on stamped with the time it goes out. At `rate` packets per
//! second the model runs rate / 100 times as fast as real time; when its pack runs low the
//! car starts a new stint (a fresh model, precharge and all).

use super::{Batcher, BusNames, Input, Sender};
use aer_car_model::chassis::Mode;
use aer_car_model::driver::Cycle;
use aer_car_model::faults::FaultPlan;
use aer_car_model::{BusTap, ClosedLoop, ModelParams};
use aer_flexcan::CanFrame;
use aer_host::candump::LoggedFrame;
use aer_host::clock::now_us;
use embedded_can::Frame;
use std::time::Duration;
use tokio::time::Instant;
use tokio_util::sync::CancellationToken;

/// Interface names of the model's buses, as on the car's Pi.
const BUSES: [&str; 2] = ["can0", "can1"];
/// Telemetry period of the CCM, the model's step per packet (ms).
const PACKET_MS: u32 = 10;
/// SOC below which the car goes in for a fresh pack.
const NEW_STINT_SOC: f32 = 0.3;

/// Collects one packet period's frames with their model time.
#[derive(Default)]
struct Collected(Vec<(u64, usize, CanFrame)>);

impl BusTap for Collected {
    fn frame(&mut self, at_us: u64, bus: usize, frame: &CanFrame) {
        self.0.push((at_us, bus, *frame));
    }
}

fn new_stint(stint: u32) -> ClosedLoop {
    let params = ModelParams {
        seed: stint.wrapping_add(1),
        ..ModelParams::NOMINAL
    };
    ClosedLoop::new(params, Mode::Road, Cycle::Autocross, FaultPlan::NONE)
}

/// Runs the model into `out` at `rate_hz` telemetry packets per second until `cancel`,
/// `limit` packets, or nothing downstream listening; returns the packets sent.
pub async fn synthetic(
    rate_hz: f64,
    out: Sender,
    cancel: &CancellationToken,
    limit: Option<u64>,
) -> u64 {
    let mut batcher = Batcher::new(out);
    let mut names = BusNames::default();
    for name in BUSES {
        if let (_, Some(announcement)) = names.index(name) {
            batcher.push(announcement).await;
        }
    }
    let speed = rate_hz.max(0.001) / (1_000.0 / f64::from(PACKET_MS));
    let period = Duration::from_secs_f64(1.0 / rate_hz.max(0.001));
    let mut stint = 0;
    let mut model = new_stint(stint);
    let mut next = Instant::now();
    let mut packets = 0u64;
    while !cancel.is_cancelled() && limit.is_none_or(|limit| packets < limit) {
        next += period;
        let mut collected = Collected::default();
        let start_us = u64::from(model.now_ms()) * 1_000;
        model.run_until(model.now_ms() + PACKET_MS, &mut collected);
        let now = now_us();
        for (at_us, bus, frame) in collected.0 {
            let offset = (at_us.saturating_sub(start_us) as f64 / speed) as u64;
            let logged = LoggedFrame::new(
                now + offset,
                u8::try_from(bus).unwrap_or(u8::MAX),
                frame.id(),
                frame.data(),
            );
            if let Some(logged) = logged {
                if !batcher.push(Input::Frame(logged)).await {
                    return packets;
                }
            }
        }
        if !batcher.flush().await {
            return packets;
        }
        packets += 1;
        if model.car.pack.soc < NEW_STINT_SOC {
            stint += 1;
            model = new_stint(stint);
        }
        tokio::select! {
            () = tokio::time::sleep_until(next) => {}
            () = cancel.cancelled() => break,
        }
    }
    packets
}
