//! The precharge circuit and the PCC that drives it: the real `aer_pcc` state machine, BMS link
//! and V/F measurement chain, fed with the pulse trains the circuit's voltages make, and the
//! precharge resistor's thermistors through the PCC's own conversion.

use aer_flexcan::CanFrame;
use aer_pcc::bms::BmsLink;
use aer_pcc::constants::{CONVERTERS, THERMISTORS};
use aer_pcc::measurement::VoltageChannel;
use aer_pcc::{Inputs, Precharge, PrechargeConfig, Relays, State, TASK_PERIOD_MS};

/// The precharge circuit as the team's board wires it: a closed shutdown circuit closes AIR-
/// and the precharge relay itself, so the tractive system's capacitance charges through the
/// precharge resistor; the PCC's one output closes AIR+, which bypasses the resistor, and
/// AIR+ is powered through the shutdown circuit too. An open shutdown circuit drops every
/// relay, and the capacitance discharges through the discharge resistor.
///
/// The hardware's own failures: AIR+ welded (closed whatever its coil does), the discharge
/// circuit open (the capacitance then discharges only through the inverter's own bleeder),
/// and a load on the tractive system that holds a precharge below its target (a short, a
/// leak) and heats the resistor.
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
    /// AIR+'s contacts are welded shut.
    pub air_plus_welded: bool,
    /// AIR+ never closes (its coil unpowered, its driver dead).
    pub air_plus_stuck_open: bool,
    /// The discharge circuit is open: the capacitance discharges through the inverter's own
    /// bleeder only ([`BLEEDER_TAU_MS`]).
    pub discharge_failed: bool,
    /// A load across the tractive system (Ohm), if any.
    pub load_ohm: Option<f32>,
    /// The precharge resistor and its temperature.
    pub resistor: PrechargeResistor,
}

/// The tractive system's time constant with no discharge circuit: the inverter's own bleeder
/// resistor across the DC link (ms; assumed: inverters bleed their DC link in tens of
/// seconds, far slower than the rules' 5 s).
pub const BLEEDER_TAU_MS: f32 = 20_000.0;

/// The precharge resistor as a heat store: the team's part is not documented, so these are a
/// plausible wire-wound resistor in an aluminium housing (assumed). What they decide is how
/// long a stalled precharge takes to reach the thermistors' limit, which the tests only need
/// to be finite.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PrechargeResistor {
    /// Resistance (Ohm): with the modelled 2 mF DC link, 1.9 kOhm gives the 3.8 s time
    /// constant.
    pub ohm: f32,
    /// Heat capacity (J/K).
    pub heat_capacity_j_per_k: f32,
    /// Heat loss to the air (W/K).
    pub loss_w_per_k: f32,
    /// Air temperature (degC).
    pub ambient_c: f32,
    /// Its temperature now (degC).
    pub celsius: f32,
}

impl PrechargeResistor {
    /// The modelled resistor, at `ambient_c`.
    pub const fn new(ambient_c: f32) -> Self {
        Self {
            ohm: 1_900.0,
            heat_capacity_j_per_k: 20.0,
            loss_w_per_k: 0.15,
            ambient_c,
            celsius: ambient_c,
        }
    }
}

impl PrechargePlant {
    /// A circuit at rest with the pack at `accumulator_v`, the shutdown circuit closed.
    pub const fn new(accumulator_v: f32, precharge_tau_ms: f32, discharge_tau_ms: f32) -> Self {
        Self {
            accumulator_v,
            tractive_v: 0.0,
            precharge_tau_ms,
            discharge_tau_ms,
            shutdown_closed: true,
            air_plus_welded: false,
            air_plus_stuck_open: false,
            discharge_failed: false,
            load_ohm: None,
            resistor: PrechargeResistor::new(25.0),
        }
    }

    /// True when AIR+ is closed: the PCC commands it and the shutdown circuit powers it, or
    /// its contacts are welded.
    pub fn air_plus_closed(&self, relays: Relays) -> bool {
        (self.shutdown_closed && relays.air_plus && !self.air_plus_stuck_open)
            || self.air_plus_welded
    }

    /// True when the pack is connected to the tractive system without the resistor: AIR+
    /// closed, and AIR- closed by the shutdown circuit.
    pub fn connected(&self, relays: Relays) -> bool {
        self.shutdown_closed && self.air_plus_closed(relays)
    }

    /// Advances the circuit by `dt_ms` with `relays` applied. Backward Euler: stable for any
    /// step, and plain arithmetic, so host and Cortex-M7 compute the same bits.
    pub fn advance(&mut self, relays: Relays, dt_ms: f32) {
        let through_resistor = self.shutdown_closed && !self.connected(relays);
        let (target, tau) = if self.connected(relays) {
            (self.accumulator_v, 0.0)
        } else if self.shutdown_closed {
            match self.load_ohm {
                // The load and the resistor divide the pack; the capacitance sees both in
                // parallel.
                Some(load) if load > 0.0 => {
                    let ohm = self.resistor.ohm;
                    (
                        self.accumulator_v * load / (ohm + load),
                        self.precharge_tau_ms * load / (ohm + load),
                    )
                }
                _ => (self.accumulator_v, self.precharge_tau_ms),
            }
        } else if self.discharge_failed {
            (0.0, BLEEDER_TAU_MS)
        } else {
            (0.0, self.discharge_tau_ms)
        };
        let factor = dt_ms / (tau + dt_ms);
        self.tractive_v += (target - self.tractive_v) * factor;
        let resistor = &mut self.resistor;
        let power_w = if through_resistor {
            let drop = self.accumulator_v - self.tractive_v;
            drop * drop / resistor.ohm
        } else {
            0.0
        };
        let loss_w = resistor.loss_w_per_k * (resistor.celsius - resistor.ambient_c);
        resistor.celsius += (power_w - loss_w) * dt_ms / 1_000.0 / resistor.heat_capacity_j_per_k;
    }
}

/// An LM331's output for a voltage: rising edges at the frequency the converter's scaling
/// gives, carried across calls so a slow train keeps its period.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PulseGenerator {
    /// Fraction of a period elapsed since the last edge.
    phase: f32,
}

impl PulseGenerator {
    /// The edges of the `span_us` starting at `start_us` for a signal at `hz` (none at 0 Hz),
    /// each to `edge(time_us)`.
    pub fn run(&mut self, start_us: u32, span_us: u32, hz: f32, mut edge: impl FnMut(u32)) {
        if hz <= 0.0 || !hz.is_finite() {
            return;
        }
        let periods = self.phase + hz * span_us as f32 / 1e6;
        let edges = periods as u32;
        for k in 1..=edges {
            let offset_us = (k as f32 - self.phase) / hz * 1e6;
            edge(start_us.wrapping_add(offset_us as u32));
        }
        self.phase = periods - edges as f32;
    }
}

/// What breaks in the PCC's own sensing this millisecond.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SensingFaults {
    /// A converter's output wire is broken: no pulses (accumulator, tractive system).
    pub converter_silent: [bool; 2],
    /// A thermistor is open (its pin at the rail).
    pub thermistor_open: [bool; 2],
}

/// The PCC node: state machine, BMS link, measurement chain and the circuit it switches.
#[derive(Debug, Clone)]
pub struct PccNode {
    /// The PCC's logic, as on the Teensy.
    pub logic: Precharge,
    bms: BmsLink,
    /// The circuit.
    pub plant: PrechargePlant,
    /// The relays as the PCC commands them.
    relays: Relays,
    /// AIR+'s contacts, which follow the command after the contactor's operate or release
    /// time.
    contacts: Contacts,
    channels: [VoltageChannel; 2],
    pulses: [PulseGenerator; 2],
    /// The sensing faults in effect.
    pub sensing: SensingFaults,
    /// Every time the pack was connected without the resistor: how many times, and the
    /// lowest the tractive system stood then (% of the pack).
    pub closures: Closures,
}

/// AIR+ closes [`AIR_OPERATE_MS`] after its coil is powered and opens [`AIR_RELEASE_MS`]
/// after it is released (assumed: the contactors FSAE cars carry close in 15-30 ms and open in
/// under 10 ms): what the PCC sees of ONLINE is its contacts, not its command.
pub const AIR_OPERATE_MS: u32 = 25;
/// See [`AIR_OPERATE_MS`].
pub const AIR_RELEASE_MS: u32 = 8;

/// AIR+'s contacts and since when its command last changed.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
struct Contacts {
    closed: bool,
    commanded: bool,
    since_ms: u32,
}

impl Contacts {
    /// The contacts at `now_ms` with the coil `commanded`.
    fn follow(&mut self, commanded: bool, now_ms: u32) -> Relays {
        if commanded != self.commanded {
            self.commanded = commanded;
            self.since_ms = now_ms;
        }
        let delay = if commanded {
            AIR_OPERATE_MS
        } else {
            AIR_RELEASE_MS
        };
        if self.closed != commanded && now_ms.wrapping_sub(self.since_ms) >= delay {
            self.closed = commanded;
        }
        Relays {
            air_plus: self.closed,
        }
    }
}

/// The pack connected to the tractive system without the resistor (AIR+ and AIR- closed):
/// what it found there.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Closures {
    /// How many times.
    pub count: u32,
    /// The lowest tractive-system voltage at such a moment, as % of the pack (`None` before
    /// the first): below the precharge target it is a precharge bypassed.
    pub lowest_percent: Option<f32>,
    was_connected: bool,
}

impl PccNode {
    /// A PCC at reset with the car's configuration and a 3.8 s precharge time constant (90 %
    /// after 8.75 s).
    pub fn new(now_ms: u32, accumulator_v: f32) -> Self {
        Self {
            logic: Precharge::new(PrechargeConfig::CAR, now_ms),
            bms: BmsLink::default(),
            plant: PrechargePlant::new(accumulator_v, 3_800.0, 500.0),
            relays: Relays::ALL_OPEN,
            contacts: Contacts::default(),
            channels: CONVERTERS.map(|vf| VoltageChannel::new(vf, TASK_PERIOD_MS)),
            pulses: [PulseGenerator::default(); 2],
            sensing: SensingFaults::default(),
            closures: Closures::default(),
        }
    }

    /// A frame on the PCC's bus (it listens to the BMS).
    pub fn on_frame(&mut self, now_ms: u32, frame: &CanFrame) {
        self.bms.on_frame(now_ms, frame);
    }

    /// One 10 ms control period with the pack at `accumulator_v` (the shutdown circuit is the
    /// car's hardware, set each millisecond in [`PrechargePlant::shutdown_closed`]); returns
    /// the frames to send (the status, and the resistor's temperatures every 100 ms).
    pub fn step(&mut self, now_ms: u32, accumulator_v: f32) -> [Option<CanFrame>; 2] {
        self.plant.accumulator_v = accumulator_v;
        let now_us = now_ms.wrapping_mul(1_000);
        let [accumulator, tractive] = self
            .channels
            .each_mut()
            .map(|channel| channel.sample(now_us));
        let celsius = self.plant.resistor.celsius;
        let resistor_c = self.sensing.thermistor_open.map(|open| {
            let counts = if open {
                THERMISTORS.full_scale
            } else {
                THERMISTORS.counts_for(celsius)
            };
            THERMISTORS.temperature_c(counts)
        });
        let inputs = Inputs {
            now_ms,
            accumulator_v: accumulator.volts,
            tractive_v: tractive.volts,
            raw_v: [accumulator.raw_volts, tractive.raw_volts],
            pulses: [accumulator.pulses, tractive.pulses],
            bms_last_seen_ms: self.bms.last_seen_ms(),
            charger_safety: self.bms.charger_safety(),
            resistor_c,
        };
        self.relays = self.logic.step(&inputs);
        let thermal_due = now_ms % aer::can::PccThermal::CYCLE_TIME_MS < TASK_PERIOD_MS;
        [
            self.logic.status_frame::<CanFrame>(),
            thermal_due
                .then(|| self.logic.thermal_frame::<CanFrame>())
                .flatten(),
        ]
    }

    /// Advances the circuit by one millisecond ending at `now_ms` with the relays as last
    /// commanded, and the converters' pulses of that millisecond into the measurement chain.
    pub fn advance(&mut self, now_ms: u32) {
        let contacts = self.contacts.follow(self.relays.air_plus, now_ms);
        let connected = self.plant.connected(contacts);
        if connected && !self.closures.was_connected && self.plant.accumulator_v > 0.0 {
            let percent = 100.0 * self.plant.tractive_v / self.plant.accumulator_v;
            self.closures.count += 1;
            self.closures.lowest_percent = Some(
                self.closures
                    .lowest_percent
                    .map_or(percent, |lowest| lowest.min(percent)),
            );
        }
        self.closures.was_connected = connected;
        self.plant.advance(contacts, 1.0);
        let start_us = now_ms.wrapping_sub(1).wrapping_mul(1_000);
        let volts = [self.plant.accumulator_v, self.plant.tractive_v];
        for (((generator, channel), vf), (volts, silent)) in self
            .pulses
            .iter_mut()
            .zip(self.channels.iter_mut())
            .zip(CONVERTERS)
            .zip(volts.into_iter().zip(self.sensing.converter_silent))
        {
            let hz = if silent { 0.0 } else { vf.hz_for_volts(volts) };
            generator.run(start_us, 1_000, hz, |at_us| channel.on_edge(at_us));
        }
    }

    /// The relays as commanded.
    pub fn relays(&self) -> Relays {
        self.relays
    }

    /// The accumulator is connected to the tractive system through AIR+ (full power).
    pub fn connected(&self) -> bool {
        self.plant.connected(Relays {
            air_plus: self.contacts.closed,
        })
    }

    /// The PCC's state.
    pub fn state(&self) -> State {
        self.logic.state()
    }
}
