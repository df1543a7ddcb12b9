//! The precharge circuit and the PCC that drives it: the real `aer_pcc` state machine and
//! BMS link, fed from a model of the tractive system's capacitance.

use aer_flexcan::CanFrame;
use aer_pcc::bms::BmsLink;
use aer_pcc::{Inputs, Precharge, PrechargeConfig, Relays, State};

/// The precharge circuit as the team's board wires it: a closed shutdown circuit closes AIR-
/// and the precharge relay itself, so the tractive system's capacitance charges through the
/// precharge resistor; the PCC's one output closes AIR+, which bypasses the resistor, and
/// AIR+ is powered through the shutdown circuit too. An open shutdown circuit drops every
/// relay, and the capacitance discharges through the discharge resistor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PrechargePlant {
    /// Pack voltage (V).
    pub accumulator_v: f32,
    /// Tractive-system (DC link) voltage (V).
    pub tractive_v: f32,
    /// R x C through the precharge resistor (ms).
    pub precharge_tau_ms: f32,
    /// R x C through the discharge resistor (ms).
    pub discharge_tau_ms: f32,
    /// The shutdown circuit is closed (the car's hardware, not the PCC).
    pub shutdown_closed: bool,
}

impl PrechargePlant {
    /// True when AIR+ is closed: the PCC commands it and the shutdown circuit powers it.
    pub fn air_plus_closed(&self, relays: Relays) -> bool {
        self.shutdown_closed && relays.air_plus
    }

    /// Advances the circuit by `dt_ms` with `relays` applied. Backward Euler: stable for any
    /// step, and plain arithmetic, so host and Cortex-M7 compute the same bits.
    pub fn advance(&mut self, relays: Relays, dt_ms: f32) {
        let (target, tau) = if self.air_plus_closed(relays) {
            (self.accumulator_v, 0.0)
        } else if self.shutdown_closed {
            (self.accumulator_v, self.precharge_tau_ms)
        } else {
            (0.0, self.discharge_tau_ms)
        };
        let factor = dt_ms / (tau + dt_ms);
        self.tractive_v += (target - self.tractive_v) * factor;
    }
}

/// The PCC node: state machine, BMS link and the circuit it switches.
#[derive(Debug, Clone)]
pub struct PccNode {
    /// The PCC's logic, as on the Teensy.
    pub logic: Precharge,
    bms: BmsLink,
    /// The circuit.
    pub plant: PrechargePlant,
    relays: Relays,
}

impl PccNode {
    /// A PCC at reset with the car's configuration and a 3.8 s precharge time constant (90 %
    /// after 8.75 s).
    pub fn new(now_ms: u32, accumulator_v: f32) -> Self {
        Self {
            logic: Precharge::new(PrechargeConfig::CAR, now_ms),
            bms: BmsLink::default(),
            plant: PrechargePlant {
                accumulator_v,
                tractive_v: 0.0,
                precharge_tau_ms: 3_800.0,
                discharge_tau_ms: 500.0,
                shutdown_closed: true,
            },
            relays: Relays::ALL_OPEN,
        }
    }

    /// A frame on the PCC's bus (it listens to the BMS).
    pub fn on_frame(&mut self, now_ms: u32, frame: &CanFrame) {
        self.bms.on_frame(now_ms, frame);
    }

    /// One 10 ms control period with the pack at `accumulator_v` and the shutdown circuit
    /// open or closed; returns the status frame to send.
    pub fn step(
        &mut self,
        now_ms: u32,
        accumulator_v: f32,
        shutdown_open: bool,
    ) -> Option<CanFrame> {
        self.plant.accumulator_v = accumulator_v;
        self.plant.shutdown_closed = !shutdown_open;
        let inputs = Inputs {
            now_ms,
            accumulator_v,
            tractive_v: self.plant.tractive_v,
            bms_last_seen_ms: self.bms.last_seen_ms(),
            charger_safety: self.bms.charger_safety(),
        };
        self.relays = self.logic.step(&inputs);
        self.logic.status_frame::<CanFrame>()
    }

    /// Advances the circuit by `dt_ms` with the relays as last commanded.
    pub fn advance(&mut self, dt_ms: f32) {
        self.plant.advance(self.relays, dt_ms);
    }

    /// The relays as commanded.
    pub fn relays(&self) -> Relays {
        self.relays
    }

    /// The accumulator is connected to the tractive system through AIR+ (full power).
    pub fn connected(&self) -> bool {
        self.plant.air_plus_closed(self.relays)
    }

    /// The PCC's state.
    pub fn state(&self) -> State {
        self.logic.state()
    }
}
