//! Simulated boards for the bench day's transcripts: the bring-up benches of `aer_ccm::bench`
//! and `aer_pcc::bench`, over hardware a transcript sets (the sensors' volts, what the DTI,
//! the PCC and the BMS send, the V/F converters' pulse trains), driven by the console's bench
//! loop at the images' own periods, with the images' log. What a transcript prints is what the
//! image's code prints for that bench.

use aer::can::{
    DtiAcLimits, DtiControl, DtiCurrents, DtiDcLimits, DtiDriveEnable, DtiFaultCode, DtiFlags,
    DtiFocCurrents, DtiSetDriveEnable, DtiSpeed, DtiTemperatures, OrionCellVoltages, OrionLimits,
    OrionPackStatus, PccStatus, PrechargeState,
};
use aer_boards::ccm::{PIN_COUNT, Revision};
use aer_ccm::bench::{AnalogPins, Bus, CcmBench, CcmHardware, Output};
use aer_ccm::calibration::store::RamFlash;
use aer_console::bench::BenchLoop;
use aer_console::{Level, LogBuffer, RebootRequest};
use aer_flexcan::{BusStatus, CanFrame, FaultState, SelfTestError};
use aer_pcc::bench::{PccBench, PccHardware, VfInputs};
use aer_pcc::measurement::FrequencyMeter;
use aer_pcc::{TASK_PERIOD_MS, VfConfig};
use core::fmt::{self, Write};
use embedded_can::{ExtendedId, Frame, Id, StandardId};
use heapless::Deque;

/// A controller on a bus with other nodes: error-active, nothing counted.
pub const ACTIVE: BusStatus = BusStatus {
    state: FaultState::ErrorActive,
    tx_errors: 0,
    rx_errors: 0,
    rx_fifo_overflows: 0,
    bus_off_events: 0,
    tx_dropped: 0,
};

/// A board alone on its bus after `can`: its heartbeats go unacknowledged.
pub const ALONE: BusStatus = BusStatus {
    state: FaultState::ErrorPassive,
    tx_errors: 128,
    ..ACTIVE
};

/// Which lines of the log a transcript keeps.
#[derive(Debug, Clone, Copy)]
pub enum Keep {
    /// None: the host reads them, the transcript does not show them.
    Nothing,
    /// Every line.
    All,
    /// Every line but the periodic reports, which run from `--- t=` to the line starting
    /// with `last`.
    NoReports {
        /// The first words of a report's last line.
        last: &'static str,
    },
    /// The lines starting with one of these.
    Starting(&'static [&'static str]),
}

/// The console as the host reads it: lines are taken out of the image's log as they come and
/// written to the transcript when a transcript keeps them.
pub struct Reader {
    line: [u8; 1024],
    len: usize,
    in_report: bool,
}

impl Reader {
    const fn new() -> Self {
        Self {
            line: [0; 1024],
            len: 0,
            in_report: false,
        }
    }

    /// Takes every queued byte out of `log`; writes the lines `keep` keeps to `out`.
    fn drain<const N: usize>(
        &mut self,
        log: &mut LogBuffer<N>,
        out: &mut dyn Write,
        keep: Keep,
    ) -> fmt::Result {
        let mut chunk = [0u8; 64];
        loop {
            let count = log.peek(&mut chunk);
            if count == 0 {
                return Ok(());
            }
            for &byte in chunk.get(..count).unwrap_or(&[]) {
                match byte {
                    b'\n' => {
                        let text = core::str::from_utf8(self.line.get(..self.len).unwrap_or(&[]))
                            .unwrap_or("(not text)");
                        if keeps(&mut self.in_report, keep, text) {
                            writeln!(out, "{text}")?;
                        }
                        self.len = 0;
                    }
                    b'\r' => {}
                    byte => {
                        if let Some(slot) = self.line.get_mut(self.len) {
                            *slot = byte;
                            self.len += 1;
                        }
                    }
                }
            }
            log.consume(count);
        }
    }
}

/// Whether `keep` keeps `line`; `in_report` follows the periodic reports.
fn keeps(in_report: &mut bool, keep: Keep, line: &str) -> bool {
    match keep {
        Keep::Nothing => false,
        Keep::All => true,
        Keep::NoReports { last } => {
            if line.starts_with("--- t=") {
                *in_report = true;
            }
            let kept = !*in_report;
            if *in_report && line.starts_with(last) {
                *in_report = false;
            }
            kept
        }
        Keep::Starting(prefixes) => prefixes.iter().any(|prefix| line.starts_with(prefix)),
    }
}

/// A transcript nobody reads.
pub struct Discard;

impl Write for Discard {
    fn write_str(&mut self, _: &str) -> fmt::Result {
        Ok(())
    }
}

/// A pulse train on a V/F input: none, a steady frequency, or a linear sweep.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Pulses {
    /// No pulses: the converter unplugged, unpowered or broken (or the generator off).
    None,
    /// A steady frequency (Hz).
    Hz(f32),
    /// A linear sweep from `from_hz` at `start_ms` to `to_hz` `duration_ms` later, holding the
    /// end (a single sweep, as the bench's signal generator runs it).
    Sweep {
        /// Start frequency (Hz).
        from_hz: f32,
        /// End frequency (Hz).
        to_hz: f32,
        /// When it starts (ms).
        start_ms: u32,
        /// How long it takes (ms).
        duration_ms: u32,
    },
}

impl Pulses {
    /// The pulses that `volts` at a converter's input gives.
    pub fn volts(volts: f32) -> Self {
        Self::Hz(VfConfig::PCC_BOARD.hz_for_volts(volts))
    }

    fn hz_at(&self, now_us: u64) -> f32 {
        match *self {
            Self::None => 0.0,
            Self::Hz(hz) => hz,
            Self::Sweep {
                from_hz,
                to_hz,
                start_ms,
                duration_ms,
            } => {
                let start_us = u64::from(start_ms) * 1_000;
                if now_us < start_us {
                    return from_hz;
                }
                let elapsed = (now_us - start_us) as f32 / (duration_ms as f32 * 1_000.0);
                from_hz + (to_hz - from_hz) * elapsed.min(1.0)
            }
        }
    }
}

/// A pulse train's edges, by accumulated phase in 1 ms slices.
#[derive(Debug, Clone, Copy)]
pub struct PulseTrain {
    /// What the input carries now.
    pub pulses: Pulses,
    phase: f32,
}

impl PulseTrain {
    /// No pulses.
    pub const fn new() -> Self {
        Self {
            pulses: Pulses::None,
            phase: 0.0,
        }
    }

    /// Calls `edge` with the time (us) of every rising edge in the millisecond starting at
    /// `slice_us`.
    pub fn slice(&mut self, slice_us: u64, mut edge: impl FnMut(u64)) {
        let hz = self.pulses.hz_at(slice_us);
        if hz <= 0.0 {
            return;
        }
        let cycles = hz / 1_000.0;
        let mut next = 1.0 - self.phase;
        while next <= cycles {
            edge(slice_us + (next / cycles * 1_000.0) as u64);
            next += 1.0;
        }
        self.phase = cycles - (next - 1.0);
    }
}

// --- The CCM ---------------------------------------------------------------------------------

/// A DTI on the simulated inverter bus.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimDti {
    /// The DC link it reports (V).
    pub dc_link_v: i16,
    /// The motor's electrical rpm.
    pub erpm: i32,
    /// Its fault code.
    pub fault: DtiFaultCode,
    /// It drops its drive enable this long after the last enable command (ms); `None`: never.
    pub timeout_ms: Option<u32>,
}

impl SimDti {
    /// At rest on the bench: no DC link voltage, no fault, the motor still, its command
    /// timeout set to 100 ms in the DTI tool (step 7).
    pub const AT_REST: Self = Self {
        dc_link_v: 0,
        erpm: 0,
        fault: DtiFaultCode::None,
        timeout_ms: Some(100),
    };
}

/// The CCM board, simulated.
pub struct SimCcm {
    now_ms: u32,
    analog: AnalogPins,
    divider: f32,
    volts: [f32; PIN_COUNT],
    /// The buttons' levels.
    pub buttons: [bool; 2],
    brake_light: bool,
    led: bool,
    /// Each controller's state (`None`: did not start).
    pub buses: [Option<BusStatus>; 2],
    rx: [Deque<CanFrame, 64>; 2],
    flash: RamFlash,
    /// The DTI on the inverter bus, if any.
    pub dti: Option<SimDti>,
    /// The PCC's state on the vehicle bus, if it runs its race image.
    pub pcc: Option<PrechargeState>,
    /// The BMS on the vehicle bus.
    pub bms: bool,
    last_enable_ms: Option<u32>,
}

impl SimCcm {
    /// The board of `board`, alone on its buses, every sensor at rest (pedal and brakes
    /// released, shocks extended, the thermistor at room temperature).
    pub fn at_rest(board: &Revision) -> Self {
        let mut sim = Self {
            now_ms: 0,
            analog: AnalogPins::of(board),
            divider: board.adc_divider,
            volts: [0.0; PIN_COUNT],
            buttons: [false; 2],
            brake_light: false,
            led: false,
            buses: [Some(ALONE); 2],
            rx: [Deque::new(), Deque::new()],
            flash: RamFlash::default(),
            dti: None,
            pcc: None,
            bms: false,
            last_enable_ms: None,
        };
        for (signal, volts) in [
            ("apps1", 0.52),
            ("apps2", 0.77),
            ("bse1", 0.51),
            ("bse2", 0.51),
            ("shock1", 4.98),
            ("shock2", 4.98),
            ("shock3", 4.98),
            ("shock4", 4.98),
            ("thermistor1", 2.45),
        ] {
            sim.set(signal, volts);
        }
        sim
    }

    /// Puts `volts` on the sensor of the analog input named `signal` (none: nothing).
    pub fn set(&mut self, signal: &str, volts: f32) {
        let index = self.analog.iter().position(|pin| pin.signal == signal);
        if let Some(slot) = index.and_then(|index| self.volts.get_mut(index)) {
            *slot = volts;
        }
    }

    /// The frames the other nodes send in the millisecond `now_ms`.
    fn tick(&mut self, now_ms: u32) {
        self.now_ms = now_ms;
        if now_ms % 10 != 3 {
            return;
        }
        let tenth = now_ms % 100 == 3;
        if let Some(state) = self.pcc {
            let online = matches!(state, PrechargeState::Online | PrechargeState::Charging);
            let status = PccStatus {
                pcc_state: state,
                pcc_error_too_fast: false,
                pcc_error_air_plus_open: false,
                pcc_error_converters_disagree: false,
                pcc_error_bypassed: false,
                pcc_error_resistor_hot: false,
                pcc_accumulator_no_pulses: false,
                pcc_tractive_no_pulses: false,
                pcc_error_accumulator_silent: false,
                pcc_error_tractive_silent: false,
                pcc_error_no_discharge: false,
                pcc_error_too_slow: false,
                pcc_error_bms_timeout: false,
                pcc_error_shutdown: false,
                pcc_error_undefined_state: false,
                pcc_accumulator_voltage: 392.0,
                // AIR+ closed joins the two: what a working PCC reports ONLINE.
                pcc_tractive_voltage: if online { 392.0 } else { 0.0 },
                pcc_precharge_progress: if online { 100.0 } else { 0.0 },
            };
            self.push_encoded(Bus::Vehicle, PccStatus::ID, false, |data| {
                status.encode(data)
            });
        }
        if self.bms {
            self.push_raw(Bus::Vehicle, OrionPackStatus::ID, false);
            if tenth {
                self.push_raw(Bus::Vehicle, OrionLimits::ID, false);
                self.push_raw(Bus::Vehicle, OrionCellVoltages::ID, false);
            }
        }
        let Some(dti) = self.dti else {
            return;
        };
        let enabled = self.last_enable_ms.is_some_and(|at| {
            dti.timeout_ms
                .is_none_or(|limit| now_ms.wrapping_sub(at) <= limit)
        });
        if tenth {
            self.push_raw(Bus::Inverter, DtiControl::ID, true);
        }
        let speed = DtiSpeed {
            dti_erpm: dti.erpm,
            dti_duty_cycle: 0.0,
            dti_input_voltage: dti.dc_link_v,
        };
        self.push_encoded(Bus::Inverter, DtiSpeed::ID, true, |data| speed.encode(data));
        self.push_raw(Bus::Inverter, DtiCurrents::ID, true);
        if tenth {
            let temperatures = DtiTemperatures {
                dti_controller_temp: 24.5,
                dti_motor_temp: 23.0,
                dti_fault_code: dti.fault,
            };
            self.push_encoded(Bus::Inverter, DtiTemperatures::ID, true, |data| {
                temperatures.encode(data)
            });
            self.push_raw(Bus::Inverter, DtiFocCurrents::ID, true);
        }
        let mut flags = [0u8; 8];
        // CAN map 2.5 in the last byte, every other field 0.
        if let Some(map) = flags.get_mut(7) {
            *map = 25;
        }
        if let Ok(decoded) = DtiFlags::decode(&flags) {
            let status = DtiFlags {
                dti_drive_enabled: if enabled {
                    DtiDriveEnable::Enabled
                } else {
                    DtiDriveEnable::Disabled
                },
                ..decoded
            };
            self.push_encoded(Bus::Inverter, DtiFlags::ID, true, |data| {
                status.encode(data)
            });
        }
        if tenth {
            self.push_raw(Bus::Inverter, DtiAcLimits::ID, true);
            self.push_raw(Bus::Inverter, DtiDcLimits::ID, true);
        }
    }

    fn push_encoded<E>(
        &mut self,
        bus: Bus,
        id: u32,
        extended: bool,
        encode: impl FnOnce(&mut [u8; 8]) -> Result<usize, E>,
    ) {
        let mut data = [0u8; 8];
        if let Ok(len) = encode(&mut data) {
            self.push(bus, id, extended, data.get(..len.min(8)).unwrap_or(&[]));
        }
    }

    fn push_raw(&mut self, bus: Bus, id: u32, extended: bool) {
        self.push(bus, id, extended, &[0; 8]);
    }

    fn push(&mut self, bus: Bus, id: u32, extended: bool, data: &[u8]) {
        let id = if extended {
            ExtendedId::new(id).map(Id::Extended)
        } else {
            u16::try_from(id)
                .ok()
                .and_then(StandardId::new)
                .map(Id::Standard)
        };
        let queue = match bus {
            Bus::Vehicle => &mut self.rx[0],
            Bus::Inverter => &mut self.rx[1],
        };
        if let Some(frame) = id.and_then(|id| CanFrame::new(id, data)) {
            let _full = queue.push_back(frame);
        }
    }
}

impl CcmHardware for SimCcm {
    type Flash = RamFlash;

    fn analog(&mut self, index: usize) -> u16 {
        let volts = self.volts.get(index).copied().unwrap_or(0.0);
        counts_for(volts, self.divider)
    }

    fn ads1115(&mut self) -> Option<(aer_ccm::apps::PedalVolts, u32)> {
        None
    }

    fn buttons(&self) -> [bool; 2] {
        self.buttons
    }

    fn wheel_edges(&self) -> [u32; 2] {
        [0; 2]
    }

    fn set_output(&mut self, output: Output, level: Level) {
        match output {
            Output::BrakeLight => self.brake_light = level.high(),
            Output::Led => self.led = level.high(),
            Output::Pump1 | Output::Pump2 | Output::Fan | Output::Buzzer => {}
        }
    }

    fn brake_light(&self) -> bool {
        self.brake_light
    }

    fn toggle_led(&mut self) {
        self.led = !self.led;
    }

    fn receive(&mut self, bus: Bus) -> Option<CanFrame> {
        match bus {
            Bus::Vehicle => self.rx[0].pop_front(),
            Bus::Inverter => self.rx[1].pop_front(),
        }
    }

    fn transmit(&mut self, bus: Bus, frame: &CanFrame, _: bool) -> bool {
        let started = match bus {
            Bus::Vehicle => self.buses[0].is_some(),
            Bus::Inverter => self.buses[1].is_some(),
        };
        if bus == Bus::Inverter {
            if let Id::Extended(id) = frame.id() {
                if id.as_raw() == DtiSetDriveEnable::ID {
                    let enable = DtiSetDriveEnable::decode(frame.data()).is_ok_and(|command| {
                        command.dti_drive_enable_cmd == DtiDriveEnable::Enabled
                    });
                    self.last_enable_ms = enable.then_some(self.now_ms);
                }
            }
        }
        started
    }

    fn self_test(&mut self, bus: Bus, _: &CanFrame) -> Option<Result<(), SelfTestError>> {
        let started = match bus {
            Bus::Vehicle => self.buses[0].is_some(),
            Bus::Inverter => self.buses[1].is_some(),
        };
        started.then_some(Ok(()))
    }

    fn bus_status(&self, bus: Bus) -> Option<BusStatus> {
        match bus {
            Bus::Vehicle => self.buses[0],
            Bus::Inverter => self.buses[1],
        }
    }

    fn i2c_scan(&mut self, _: &mut dyn FnMut(fmt::Arguments<'_>)) -> Option<()> {
        None
    }

    fn feed_watchdog(&mut self) {}

    fn flash(&mut self) -> &mut RamFlash {
        &mut self.flash
    }
}

/// The 12-bit ADC counts for `volts` at a sensor behind `divider`.
pub fn counts_for(volts: f32, divider: f32) -> u16 {
    (volts / divider / 3.3 * 4_095.0 + 0.5).clamp(0.0, 4_095.0) as u16
}

/// The CCM bring-up image on the simulated board, every millisecond as its bench task runs.
pub struct CcmSession {
    bench_loop: BenchLoop,
    bench: CcmBench<SimCcm>,
    log: LogBuffer<{ aer_ccm::console::bringup::LOG_BYTES }>,
    reader: Reader,
    reboot: RebootRequest,
    now_ms: u32,
}

impl CcmSession {
    /// The image started on `sim`, wired as `board` says.
    pub fn new(sim: SimCcm, board: Revision) -> Self {
        Self {
            bench_loop: BenchLoop::new(),
            bench: CcmBench::new(sim, board),
            log: LogBuffer::new(),
            reader: Reader::new(),
            reboot: RebootRequest::new(),
            now_ms: 0,
        }
    }

    /// The simulated board.
    pub fn sim(&mut self) -> &mut SimCcm {
        self.bench.hardware()
    }

    /// Runs the bench up to `until_ms` (one step per millisecond), the host reading the log;
    /// the lines `keep` keeps go to `out`.
    pub fn run(&mut self, until_ms: u32, out: &mut dyn Write, keep: Keep) -> fmt::Result {
        while self.now_ms < until_ms {
            self.step(None)?;
            self.reader.drain(&mut self.log, out, keep)?;
        }
        Ok(())
    }

    /// Runs the bench up to `until_ms`, nobody reading the transcript.
    pub fn skip(&mut self, until_ms: u32) -> fmt::Result {
        self.run(until_ms, &mut Discard, Keep::Nothing)
    }

    /// Types `line` at the current millisecond (the step takes it); the lines `keep` keeps of
    /// what it prints go to `out`.
    pub fn type_line(&mut self, line: &str, out: &mut dyn Write, keep: Keep) -> fmt::Result {
        self.step(Some(line))?;
        self.reader.drain(&mut self.log, out, keep)
    }

    fn step(&mut self, line: Option<&str>) -> fmt::Result {
        let now = self.now_ms;
        self.bench.hardware().tick(now);
        let typed = line.map(|text| {
            let mut typed = aer_console::bench::Line::new();
            let _fits = typed.push_str(text);
            typed
        });
        let _after = self.bench_loop.step(
            &mut self.bench,
            now,
            typed,
            &self.reboot,
            &[true, true],
            &mut self.log,
        );
        self.now_ms += 1;
        if self.log.dropped() > 0 {
            return Err(fmt::Error);
        }
        Ok(())
    }

    /// Now (ms).
    pub fn now_ms(&self) -> u32 {
        self.now_ms
    }
}

// --- The PCC ---------------------------------------------------------------------------------

/// The PCC board, simulated.
pub struct SimPcc {
    /// The accumulator's and the tractive system's converter outputs.
    pub inputs: [PulseTrain; 2],
    meters: [FrequencyMeter; 2],
    edges: [u32; 2],
    air_plus: bool,
    led: bool,
    /// The controller's state (`None`: did not start).
    pub bus: Option<BusStatus>,
    rx: Deque<CanFrame, 32>,
    /// The BMS's limits frame from a CAN adapter, every 100 ms.
    pub bms: bool,
}

impl SimPcc {
    /// On its bus, both converters silent.
    pub fn new() -> Self {
        Self {
            inputs: [PulseTrain::new(); 2],
            meters: [FrequencyMeter::default(); 2],
            edges: [0; 2],
            air_plus: false,
            led: false,
            bus: Some(ACTIVE),
            rx: Deque::new(),
            bms: false,
        }
    }

    /// The millisecond from `now_ms`: the converters' edges (the edge interrupt's stamps and
    /// counts) and the BMS's frame.
    fn tick(&mut self, now_ms: u32) {
        let slice_us = u64::from(now_ms) * 1_000;
        for ((train, meter), edges) in self
            .inputs
            .iter_mut()
            .zip(self.meters.iter_mut())
            .zip(self.edges.iter_mut())
        {
            train.slice(slice_us, |at_us| {
                meter.on_edge(at_us as u32);
                *edges = edges.wrapping_add(1);
            });
        }
        if self.bms && now_ms % 100 == 7 {
            if let Some(frame) = u16::try_from(OrionLimits::ID)
                .ok()
                .and_then(StandardId::new)
                .and_then(|id| CanFrame::new(id, &[0; 8]))
            {
                let _full = self.rx.push_back(frame);
            }
        }
    }

    /// What the bench task reads at a step at `now_ms`, as the image's reads it.
    fn inputs(&mut self, now_ms: u32) -> VfInputs {
        let now_us = now_ms.wrapping_mul(1_000);
        let timeout_us = VfConfig::PCC_BOARD.edge_timeout_us;
        VfInputs {
            levels: [false; 2],
            hz: self
                .meters
                .each_mut()
                .map(|meter| meter.reading(now_us, timeout_us)),
        }
    }
}

impl Default for SimPcc {
    fn default() -> Self {
        Self::new()
    }
}

impl PccHardware for SimPcc {
    fn set_air_plus(&mut self, high: bool) {
        self.air_plus = high;
    }

    fn set_led(&mut self, high: bool) {
        self.led = high;
    }

    fn led(&self) -> bool {
        self.led
    }

    fn thermistors(&mut self) -> [u16; 2] {
        // The resistor at room temperature, through the board's divider.
        let thermistors = aer_pcc::constants::THERMISTORS;
        [thermistors.counts_for(22.0), thermistors.counts_for(22.5)]
    }

    fn edges(&self) -> [u32; 2] {
        self.edges
    }

    fn receive(&mut self) -> Option<CanFrame> {
        self.rx.pop_front()
    }

    fn transmit(&mut self, _: &CanFrame) -> bool {
        self.bus.is_some()
    }

    fn self_test(&mut self, _: &CanFrame) -> Option<Result<(), SelfTestError>> {
        self.bus.map(|_| Ok(()))
    }

    fn bus_status(&self) -> Option<BusStatus> {
        self.bus
    }

    fn feed_watchdog(&mut self) {}
}

/// The PCC bring-up image on the simulated board, every 10 ms as its bench task runs.
pub struct PccSession {
    bench_loop: BenchLoop,
    bench: PccBench<SimPcc>,
    log: LogBuffer<{ aer_pcc::console::BRINGUP_LOG_BYTES }>,
    reader: Reader,
    reboot: RebootRequest,
    now_ms: u32,
}

impl PccSession {
    /// The image started on `sim`.
    pub fn new(sim: SimPcc) -> Self {
        Self {
            bench_loop: BenchLoop::new(),
            bench: PccBench::new(sim, aer_boards::pcc::COMP_CAR),
            log: LogBuffer::new(),
            reader: Reader::new(),
            reboot: RebootRequest::new(),
            now_ms: 0,
        }
    }

    /// The simulated board.
    pub fn sim(&mut self) -> &mut SimPcc {
        self.bench.hardware()
    }

    /// Runs the bench up to `until_ms` (a step every 10 ms), the host reading the log; the
    /// lines `keep` keeps go to `out`.
    pub fn run(&mut self, until_ms: u32, out: &mut dyn Write, keep: Keep) -> fmt::Result {
        while self.now_ms < until_ms {
            self.step(None)?;
            self.reader.drain(&mut self.log, out, keep)?;
        }
        Ok(())
    }

    /// Runs the bench up to `until_ms`, nobody reading the transcript.
    pub fn skip(&mut self, until_ms: u32) -> fmt::Result {
        self.run(until_ms, &mut Discard, Keep::Nothing)
    }

    /// Types `line` for the next step; the lines `keep` keeps of what it prints go to `out`.
    pub fn type_line(&mut self, line: &str, out: &mut dyn Write, keep: Keep) -> fmt::Result {
        self.step(Some(line))?;
        self.reader.drain(&mut self.log, out, keep)
    }

    fn step(&mut self, line: Option<&str>) -> fmt::Result {
        let now = self.now_ms;
        for ms in now..now + TASK_PERIOD_MS {
            self.bench.hardware().tick(ms);
        }
        let step_ms = now + TASK_PERIOD_MS;
        let inputs = self.bench.hardware().inputs(step_ms);
        let typed = line.map(|text| {
            let mut typed = aer_console::bench::Line::new();
            let _fits = typed.push_str(text);
            typed
        });
        let _after = self.bench_loop.step(
            &mut self.bench,
            step_ms,
            typed,
            &self.reboot,
            &inputs,
            &mut self.log,
        );
        self.now_ms = step_ms;
        if self.log.dropped() > 0 {
            return Err(fmt::Error);
        }
        Ok(())
    }
}
