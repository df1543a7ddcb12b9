//! The CCM bring-up image's bench, without hardware types: what it reads and decides at every
//! step of the bring-up loop (`aer_console::bench`), what it answers to each command and what
//! its report prints. The image gives it the board through [`CcmHardware`]; the bench day's
//! transcripts (docs/bench-day.md) give it a simulated one, so the page quotes what the image
//! does.
//!
//! Every input it reads comes from the board table (`aer_boards::ccm::Revision`): the analog
//! inputs in the table's order (the pedals on that option, BSE1, BSE2, the shocks, the
//! thermistor), the buttons, the wheel-speed inputs, the outputs by their signal names. It
//! reads both CAN controllers (the DTI on the inverter bus, the PCC's state on the vehicle
//! bus), records the pedal, brake and shock calibration and saves it, and runs the DTI's
//! command-timeout test behind its guard ([`DtiGuard`](crate::console::dti::DtiGuard)), which
//! it checks at every step.

use crate::analog::sensor_volts;
use crate::apps::PedalVolts;
use crate::calibration::measured::{MEASURED, SOURCE};
use crate::calibration::store::CalibrationFlash;
use crate::calibration::{BenchPoint, BenchRecorder, BenchSample, EPK, ShockEnd};
use crate::chassis::shock_volts;
use crate::console::bringup::{self, Report};
use crate::console::dti::{DtiBench, EnableTest, Path, Step};
use crate::constants::TRACTIVE_OFF_V;
use crate::inverter::OutFrames;
use aer::runtime::EncodeError;
use aer_boards::ccm::{PIN_COUNT, Pedals, Revision};
use aer_boards::{Mode, Pin};
use aer_console::bench::{BenchBoard, Reply};
use aer_console::bringup::{
    AnalogReading, BusLine, DigitalReading, Heard, ReportHeader, SelfTestLine, edge_rate_hz,
};
use aer_console::{Command, Level, LogBuffer, PedalPosition, ShockPoint};
use aer_flexcan::{BusStatus, CanFrame, SelfTestError};
use embedded_can::{ExtendedId, Frame, Id, StandardId};

/// The CCM's two CAN controllers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Bus {
    /// CAN3: BMS, charger, PCC, IMD, the Pi.
    Vehicle,
    /// CAN2: the inverter.
    Inverter,
}

/// The outputs `out` drives.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Output {
    /// Brake light (digital).
    BrakeLight,
    /// The on-board LED (digital).
    Led,
    /// Coolant pump 1 (PWM).
    Pump1,
    /// Coolant pump 2 (PWM).
    Pump2,
    /// Radiator fan (PWM).
    Fan,
    /// Ready-to-drive buzzer (PWM tone).
    Buzzer,
}

/// The board as the bench drives it: the image's pins and controllers, or a simulation.
pub trait CcmHardware {
    /// The saved copies' flash.
    type Flash: CalibrationFlash;
    /// The on-chip ADC input `index`, in the board table's order of analog pins: 12-bit
    /// counts.
    fn analog(&mut self, index: usize) -> u16;
    /// On the ADS1115 option, both pedal sensors' last conversions (V at the sensors) and the
    /// converter's failed transactions so far; `None` on a board whose pedals are on-chip
    /// analog inputs.
    fn ads1115(&mut self) -> Option<(PedalVolts, u32)>;
    /// The ready-to-move and launch buttons' levels.
    fn buttons(&self) -> [bool; 2];
    /// Both wheel-speed inputs' rising edges since start-up.
    fn wheel_edges(&self) -> [u32; 2];
    /// Drives an output.
    fn set_output(&mut self, output: Output, level: Level);
    /// Whether the brake light is on.
    fn brake_light(&self) -> bool;
    /// Toggles the LED.
    fn toggle_led(&mut self);
    /// The next frame `bus` received, if its controller started.
    fn receive(&mut self, bus: Bus) -> Option<CanFrame>;
    /// Queues `frame` on `bus`, replacing a pending frame with its identifier when `latest`;
    /// false when the controller did not start or every mailbox is busy.
    fn transmit(&mut self, bus: Bus, frame: &CanFrame, latest: bool) -> bool;
    /// The loopback self-test of `bus` with `frame`; `None` when it did not start.
    fn self_test(&mut self, bus: Bus, frame: &CanFrame) -> Option<Result<(), SelfTestError>>;
    /// The controller's state; `None` when it did not start.
    fn bus_status(&self, bus: Bus) -> Option<BusStatus>;
    /// `i2c scan` on the ADS1115 option: every address that answers, and the converter's
    /// config register, into `log`; `None` on a board without I2C.
    fn i2c_scan(&mut self, log: &mut dyn FnMut(core::fmt::Arguments<'_>)) -> Option<()>;
    /// Services the hardware watchdog.
    fn feed_watchdog(&mut self);
    /// The saved copies' flash.
    fn flash(&mut self) -> &mut Self::Flash;
}

/// Heartbeats this board sends on `can` (not identifiers of the car's schema).
pub const HEARTBEAT_IDS: [(Bus, u16); 2] = [(Bus::Vehicle, 0x7F3), (Bus::Inverter, 0x7F2)];

/// The analog pins of a board, in its table's order.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AnalogPins {
    pins: [Option<Pin>; PIN_COUNT],
}

impl AnalogPins {
    /// The on-chip ADC inputs `board` lists, in its order.
    pub fn of(board: &Revision) -> Self {
        let mut pins = [None; PIN_COUNT];
        let analog = board
            .pins()
            .into_iter()
            .filter(|pin| matches!(pin.mode, Mode::Analog(_)));
        for (slot, pin) in pins.iter_mut().zip(analog) {
            *slot = Some(pin);
        }
        Self { pins }
    }

    /// The pins, in order.
    pub fn iter(&self) -> impl Iterator<Item = Pin> + '_ {
        self.pins.iter().map_while(|pin| *pin)
    }

    /// How many there are.
    pub fn len(&self) -> usize {
        self.iter().count()
    }

    /// True for a board without analog inputs.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Where `pin` sits among them.
    pub fn index_of(&self, pin: Pin) -> Option<usize> {
        self.iter().position(|listed| listed.number == pin.number)
    }
}

/// The bench over a board.
pub struct CcmBench<H> {
    hw: H,
    board: Revision,
    analog: AnalogPins,
    /// BSE1, BSE2 and the shocks among the analog inputs.
    brakes: [Option<usize>; 2],
    shocks: [Option<usize>; 4],
    calibration: BenchRecorder,
    heard: [Heard; 2],
    dti: DtiBench,
    heartbeats: bool,
    heartbeat: u8,
    wheels_before: [u32; 2],
    buttons_before: [bool; 2],
    button_edges: [u32; 2],
}

impl<H: CcmHardware> CcmBench<H> {
    /// The bench over `hw`, wired as `board` says; every output off.
    pub fn new(mut hw: H, board: Revision) -> Self {
        let analog = AnalogPins::of(&board);
        for output in [
            Output::BrakeLight,
            Output::Pump1,
            Output::Pump2,
            Output::Fan,
            Output::Buzzer,
        ] {
            hw.set_output(output, Level::Off);
        }
        Self {
            hw,
            board,
            analog,
            brakes: board.brakes.map(|pin| analog.index_of(pin)),
            shocks: board.shocks.map(|pin| analog.index_of(pin)),
            calibration: BenchRecorder::default(),
            heard: [Heard::default(); 2],
            dti: DtiBench::default(),
            heartbeats: false,
            heartbeat: 0,
            wheels_before: [0; 2],
            buttons_before: [false; 2],
            button_edges: [0; 2],
        }
    }

    /// The board, for a simulation to drive.
    pub fn hardware(&mut self) -> &mut H {
        &mut self.hw
    }

    /// The DTI as the bench knows it.
    pub fn dti(&self) -> &DtiBench {
        &self.dti
    }

    /// Both pedal sensors (V at the sensors), as the race image reads them.
    fn pedal_volts(&mut self) -> PedalVolts {
        match self.board.pedals {
            Pedals::OnChipAdc { apps } => {
                let [apps1, apps2] = apps.map(|pin| self.analog.index_of(pin));
                [Some(self.volts(apps1)), Some(self.volts(apps2))]
            }
            Pedals::Ads1115 { .. } => self.hw.ads1115().map_or([None; 2], |(volts, _)| volts),
        }
    }

    /// Volts at the sensor of the analog input at `index`.
    fn volts(&mut self, index: Option<usize>) -> f32 {
        index.map_or(f32::NAN, |index| {
            sensor_volts(self.hw.analog(index), self.board.adc_divider)
        })
    }

    /// Whether the tractive system counts as live for saving and erasing the flash: while
    /// `dti enable` runs, or the DTI reports 60 V or more on its DC link.
    fn tractive_live(&self) -> bool {
        self.dti.test.active()
            || self
                .dti
                .evidence
                .dc_link
                .is_some_and(|(volts, _)| volts.is_nan() || volts >= TRACTIVE_OFF_V)
    }

    /// Queues the `dti enable` test's frames on the inverter bus (each replaces a pending
    /// frame with its id). A frame that did not encode is not sent: the DTI sees silence.
    fn send_dti(&mut self, frames: Result<OutFrames, EncodeError>) {
        let Ok(frames) = frames else {
            return;
        };
        for frame in frames.iter() {
            let can_frame = ExtendedId::new(frame.id)
                .map(Id::Extended)
                .and_then(|id| CanFrame::new(id, frame.data()));
            if let Some(can_frame) = can_frame {
                let _queued = self.hw.transmit(Bus::Inverter, &can_frame, true);
            }
        }
    }

    fn output(&mut self, signal: &str, level: Level) -> &'static str {
        let board = &self.board;
        let [pump1, pump2] = board.pumps;
        let output = [
            (board.brake_light, Output::BrakeLight),
            (board.led, Output::Led),
            (pump1, Output::Pump1),
            (pump2, Output::Pump2),
            (board.fan, Output::Fan),
            (board.buzzer, Output::Buzzer),
        ]
        .into_iter()
        .find(|(pin, _)| pin.signal == signal);
        match output {
            Some((_, output)) => {
                self.hw.set_output(output, level);
                "done"
            }
            None => "no such output: brake-light, led, pump1, pump2, fan, rtd-buzzer",
        }
    }

    fn can_test<const N: usize>(&mut self, log: &mut LogBuffer<N>) -> &'static str {
        for (bus, id) in HEARTBEAT_IDS {
            let payload = [0xA5, 0x5A, if bus == Bus::Vehicle { 3 } else { 2 }];
            let frame = StandardId::new(id).and_then(|id| CanFrame::new(id, &payload));
            let result = frame.and_then(|frame| self.hw.self_test(bus, &frame));
            log.line(format_args!(
                "{}",
                SelfTestLine {
                    name: bus_name(bus),
                    result
                }
            ));
        }
        self.heartbeats = true;
        "heartbeats 0x7F3 on CAN3 and 0x7F2 on CAN2 every second from now"
    }

    fn send_heartbeats(&mut self) {
        self.heartbeat = self.heartbeat.wrapping_add(1);
        for (bus, id) in HEARTBEAT_IDS {
            if let Some(frame) =
                StandardId::new(id).and_then(|id| CanFrame::new(id, &[self.heartbeat]))
            {
                let _queued = self.hw.transmit(bus, &frame, false);
            }
        }
    }

    fn read_buses(&mut self, now_ms: u32) {
        let [heard_vehicle, heard_inverter] = &mut self.heard;
        // The vehicle bus also feeds the DTI guard (the PCC's state); the inverter bus the DTI
        // checks (node id, CAN map, drive, fault, DC link, motor speed, command timeout).
        for (bus, heard) in [
            (Bus::Vehicle, heard_vehicle),
            (Bus::Inverter, heard_inverter),
        ] {
            for _ in 0..8 {
                let Some(frame) = self.hw.receive(bus) else {
                    break;
                };
                let (id, extended) = match frame.id() {
                    Id::Standard(id) => (u32::from(id.as_raw()), false),
                    Id::Extended(id) => (id.as_raw(), true),
                };
                match bus {
                    Bus::Vehicle => self.dti.vehicle_frame(now_ms, id, extended, frame.data()),
                    Bus::Inverter => self.dti.frame(now_ms, id, extended, frame.data()),
                }
                heard.frame(id);
            }
        }
    }
}

fn bus_name(bus: Bus) -> &'static str {
    match bus {
        Bus::Vehicle => "CAN3 (vehicle)",
        Bus::Inverter => "CAN2 (inverter)",
    }
}

impl<H: CcmHardware> BenchBoard for CcmBench<H> {
    /// The wheel-speed inputs' levels, read under their interrupt's lock.
    type Shared = [bool; 2];
    const NAME: &'static str = "CCM";
    const SAFE: &'static str = "every output off";
    const PANIC: &'static str = "sends the inverter drive disabled and 0 A on CAN2 (watch candump can0 on the inverter bus) and restarts the board at once";

    fn feed_watchdog(&mut self) {
        self.hw.feed_watchdog();
    }

    fn all_off(&mut self) {
        // A DTI that kept its drive enabled (no command timeout) is told to drop it.
        self.dti.test.stop();
        if self.dti.evidence.dc_link.is_some() {
            self.send_dti(EnableTest::disable_frames());
        }
        self.dti.guard.revoke();
        for output in [
            Output::BrakeLight,
            Output::Pump1,
            Output::Pump2,
            Output::Fan,
            Output::Buzzer,
        ] {
            self.hw.set_output(output, Level::Off);
        }
    }

    fn step<const N: usize>(&mut self, now_ms: u32, _: &[bool; 2], log: &mut LogBuffer<N>) {
        if self.calibration.recording() {
            let sample = BenchSample {
                pedals: self.pedal_volts(),
                brakes: self.brakes.map(|index| self.volts(index)),
                shocks: self.shocks.map(|index| {
                    index.map_or(f32::NAN, |index| shock_volts(self.hw.analog(index)))
                }),
            };
            if let Some(point) = self.calibration.sample(&sample) {
                bringup::calibration(log, &self.calibration, point);
            }
        }
        for ((high, before), edges) in self
            .hw
            .buttons()
            .into_iter()
            .zip(self.buttons_before.iter_mut())
            .zip(self.button_edges.iter_mut())
        {
            if high && !*before {
                *edges = edges.wrapping_add(1);
            }
            *before = high;
        }
        self.read_buses(now_ms);
        if let Some((timeout, frames)) = self.dti.poll(now_ms) {
            self.send_dti(frames);
            log.line(format_args!("t={now_ms} ms {timeout}; drive disable sent"));
        }
        match self.dti.due(now_ms) {
            Some(Step::Send(frames)) => self.send_dti(frames),
            Some(Step::Stopped(why, frames)) => {
                self.send_dti(frames);
                log.line(format_args!(
                    "t={now_ms} ms dti enable STOPPED, drive disable sent: {why}"
                ));
            }
            None => {}
        }
    }

    fn command<const N: usize>(
        &mut self,
        command: Command<'_>,
        now_ms: u32,
        log: &mut LogBuffer<N>,
    ) -> Reply {
        Reply::Say(match command {
            Command::Output { signal, level } => self.output(signal, level),
            Command::AllOff => {
                self.all_off();
                "every output off, confirmations revoked"
            }
            Command::ConfirmHvDisconnected => {
                match self
                    .dti
                    .guard
                    .confirm_hv_disconnected(now_ms, &self.dti.evidence)
                {
                    Ok(()) => {
                        "HV confirmed (the DTI reads its DC link below 60 V): `dti enable` armed for 30 s"
                    }
                    Err(refusal) => {
                        log.line(format_args!("refused: {refusal}"));
                        "not confirmed"
                    }
                }
            }
            Command::ConfirmWheelsOffGround => {
                self.dti.guard.confirm_wheels_off_ground(now_ms);
                "wheels off the ground confirmed for 30 s: at high voltage `dti enable` also needs the PCC ONLINE, the DTI without fault and the motor still"
            }
            Command::DtiEnable => match self.dti.enable(now_ms) {
                Ok(Path::LowVoltage) => {
                    "drive enable at 0 A for 1 s (below 60 V), then silence: the report's `DTI command timeout` line gives the result"
                }
                Ok(Path::HighVoltage) => {
                    "drive enable at 0 A for 1 s AT HIGH VOLTAGE (PCC ONLINE, wheels off the ground), then silence: the report's `DTI command timeout` line gives the result"
                }
                Err(refusal) => {
                    log.line(format_args!("refused: {refusal}"));
                    "not started"
                }
            },
            Command::CanTest => self.can_test(log),
            Command::Calibrate(position) => {
                self.calibration.start(match position {
                    PedalPosition::Rest => BenchPoint::Rest,
                    PedalPosition::Full => BenchPoint::Full,
                });
                "recording for 1 s: hold the pedal still"
            }
            Command::CalibrateShock { corner, point } => {
                let mut sensors = [false; 4];
                for &index in corner.indices() {
                    if let Some(sensor) = sensors.get_mut(index) {
                        *sensor = true;
                    }
                }
                let end = match point {
                    ShockPoint::Extended => ShockEnd::Extended,
                    ShockPoint::Compressed => ShockEnd::Compressed,
                };
                self.calibration.start(BenchPoint::Shock { sensors, end });
                "recording for 1 s: hold the damper still"
            }
            Command::CalSave => {
                let live = self.tractive_live();
                bringup::cal_save(log, self.hw.flash(), &self.calibration, MEASURED, EPK, live);
                "the line above says what was saved"
            }
            Command::CalLoad => {
                bringup::cal_load(log, self.hw.flash(), MEASURED, SOURCE, EPK);
                "the line above is what the race image's start-up loads now"
            }
            Command::CalErase => {
                let live = self.tractive_live();
                bringup::cal_erase(log, self.hw.flash(), EPK, live);
                "the line above says what was erased"
            }
            Command::I2cScan => {
                let mut lines = |args: core::fmt::Arguments<'_>| {
                    log.line(args);
                };
                match self.hw.i2c_scan(&mut lines) {
                    Some(()) => "scan done",
                    None => {
                        "this board reads the pedals on the on-chip ADC: no I2C (the ADS1115 images have it)"
                    }
                }
            }
            // The loop answers these itself.
            Command::Help
            | Command::Report
            | Command::WatchdogTest
            | Command::Bootloader
            | Command::Restart
            | Command::Status
            | Command::PanicTest => "taken by the bench loop",
        })
    }

    fn report<const N: usize>(
        &mut self,
        header: ReportHeader,
        elapsed_ms: u32,
        wheel_levels: &[bool; 2],
        log: &mut LogBuffer<N>,
    ) {
        if self.heartbeats {
            self.send_heartbeats();
        }
        let wheels_now = self.hw.wheel_edges();
        let divider = self.board.adc_divider;
        let mut analog = [AnalogReading {
            pin: self.board.led,
            counts: 0,
            divider,
        }; PIN_COUNT];
        let count = self.analog.len();
        for (index, (slot, pin)) in analog.iter_mut().zip(self.analog.iter()).enumerate() {
            *slot = AnalogReading {
                pin,
                counts: self.hw.analog(index),
                divider,
            };
        }
        let ads1115 = self.hw.ads1115();
        let [wheel1, wheel2] = self.board.wheel_speed;
        let [before1, before2] = self.wheels_before;
        let [after1, after2] = wheels_now;
        let [level1, level2] = *wheel_levels;
        let [ready, launch] = self.hw.buttons();
        let [ready_edges, launch_edges] = self.button_edges;
        let digital = [
            (
                wheel1,
                level1,
                after1,
                edge_rate_hz(before1, after1, elapsed_ms),
            ),
            (
                wheel2,
                level2,
                after2,
                edge_rate_hz(before2, after2, elapsed_ms),
            ),
            (self.board.ready_to_move, ready, ready_edges, 0.0),
            (self.board.launch, launch, launch_edges, 0.0),
        ]
        .map(|(pin, high, edges, hz)| DigitalReading {
            pin,
            high,
            edges,
            hz,
        });
        let [heard_vehicle, heard_inverter] = &self.heard;
        Report {
            header,
            analog: analog.get(..count).unwrap_or(&[]),
            ads1115,
            digital: &digital,
            buses: [
                BusLine {
                    name: bus_name(Bus::Vehicle),
                    status: self.hw.bus_status(Bus::Vehicle),
                    heard: heard_vehicle,
                },
                BusLine {
                    name: bus_name(Bus::Inverter),
                    status: self.hw.bus_status(Bus::Inverter),
                    heard: heard_inverter,
                },
            ],
            dti: &self.dti,
            brake_light: self.hw.brake_light(),
        }
        .write(log);
        self.wheels_before = wheels_now;
        self.heard = [Heard::default(); 2];
        self.dti.report_done();
    }

    fn toggle_led(&mut self) {
        self.hw.toggle_led();
    }
}
