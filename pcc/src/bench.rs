//! The PCC bring-up image's bench, without hardware types: what it reads and decides at every
//! step of the bring-up loop (`aer_console::bench`), what it answers to each command and what
//! its report prints. The image gives it the board through [`PccHardware`]; the bench day's
//! transcripts (docs/bench-day.md) give it a simulated one, so the page quotes what the image
//! does.
//!
//! It reads both V/F converters (and the voltages they mean), both thermistor inputs and the
//! CAN controller, and drives the LED and pin 11 (AIR+), the latter only behind the HV gate
//! ([`crate::bringup`]): high only within 30 s of a typed confirmation and only while both
//! converters are alive and read below 60 V, checked at every step.

use crate::bringup::{AirPlusAnswer, AirPlusBench, converter_reading};
use crate::console::{BringupReport, ThermistorReading, VfReading};
use crate::constants::CONVERTERS;
use aer_boards::pcc::Revision;
use aer_console::bench::{BenchBoard, Reply};
use aer_console::bringup::{
    AnalogReading, BusLine, DigitalReading, Heard, ReportHeader, SelfTestLine, edge_rate_hz,
};
use aer_console::hv_gate::HvReading;
use aer_console::{Command, LogBuffer};
use aer_flexcan::{BusStatus, CanFrame, SelfTestError};
use embedded_can::{Frame, Id, StandardId};

/// The heartbeat this board sends after `can` (not an identifier of the car's schema).
pub const HEARTBEAT_ID: u16 = 0x7F2;

/// The board as the bench drives it: the image's pins and controller, or a simulation.
pub trait PccHardware {
    /// Drives pin 11 (AIR+): high closes it.
    fn set_air_plus(&mut self, high: bool);
    /// Drives the on-board LED.
    fn set_led(&mut self, high: bool);
    /// Whether the LED is on.
    fn led(&self) -> bool;
    /// Both thermistor inputs' 12-bit counts.
    fn thermistors(&mut self) -> [u16; 2];
    /// Both V/F inputs' rising edges since start-up.
    fn edges(&self) -> [u32; 2];
    /// The next frame CAN2 received, if its controller started.
    fn receive(&mut self) -> Option<CanFrame>;
    /// Queues `frame` on CAN2; false when it did not start or every mailbox is busy.
    fn transmit(&mut self, frame: &CanFrame) -> bool;
    /// CAN2's loopback self-test with `frame`; `None` when it did not start.
    fn self_test(&mut self, frame: &CanFrame) -> Option<Result<(), SelfTestError>>;
    /// CAN2's state; `None` when it did not start.
    fn bus_status(&self) -> Option<BusStatus>;
    /// Services the hardware watchdog.
    fn feed_watchdog(&mut self);
}

/// What the image reads at each step outside the bench: both V/F inputs' levels and their
/// frequencies now (`None`: silent), from the edge interrupt's time stamps.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VfInputs {
    /// The inputs' levels.
    pub levels: [bool; 2],
    /// Accumulator, tractive system (Hz).
    pub hz: [Option<f32>; 2],
}

/// The bench over a board.
pub struct PccBench<H> {
    hw: H,
    board: Revision,
    /// Pin 11's gate.
    gate: AirPlusBench,
    /// Both converters as this step read them.
    readings: [HvReading; 2],
    heard: Heard,
    edges_before: [u32; 2],
    heartbeats: bool,
    heartbeat: u8,
}

impl<H: PccHardware> PccBench<H> {
    /// The bench over `hw`, wired as `board` says; pin 11 low.
    pub fn new(mut hw: H, board: Revision) -> Self {
        hw.set_air_plus(false);
        Self {
            hw,
            board,
            gate: AirPlusBench::new(),
            readings: [HvReading::Silent; 2],
            heard: Heard::default(),
            edges_before: [0; 2],
            heartbeats: false,
            heartbeat: 0,
        }
    }

    /// The board, for a simulation to look at.
    pub fn hardware(&mut self) -> &mut H {
        &mut self.hw
    }

    /// Drives pin 11 as the gate decided.
    fn apply(&mut self) {
        self.hw.set_air_plus(self.gate.air_plus());
    }

    fn can_test<const N: usize>(&mut self, log: &mut LogBuffer<N>) -> &'static str {
        let frame =
            StandardId::new(HEARTBEAT_ID).and_then(|id| CanFrame::new(id, &[0xA5, 0x5A, 2]));
        let result = frame.and_then(|frame| self.hw.self_test(&frame));
        log.line(format_args!(
            "{}",
            SelfTestLine {
                name: "CAN2",
                result
            }
        ));
        self.heartbeats = true;
        "heartbeats 0x7F2 every second from now"
    }
}

impl<H: PccHardware> BenchBoard for PccBench<H> {
    /// The V/F inputs, read under their interrupt's lock.
    type Shared = VfInputs;
    const NAME: &'static str = "PCC";
    const SAFE: &'static str = "pin 11 (AIR+) low";
    const PANIC: &'static str =
        "drives pin 11 (AIR+) low at once; the watchdog restarts the board within 0.5 s";

    fn feed_watchdog(&mut self) {
        self.hw.feed_watchdog();
    }

    fn all_off(&mut self) {
        self.gate.all_off();
        self.hw.set_air_plus(false);
    }

    fn step<const N: usize>(&mut self, now_ms: u32, inputs: &VfInputs, log: &mut LogBuffer<N>) {
        while let Some(frame) = self.hw.receive() {
            self.heard.frame(raw_id(&frame));
        }
        let [accumulator, tractive] = inputs.hz;
        self.readings = [
            converter_reading(accumulator, &CONVERTERS[0], now_ms),
            converter_reading(tractive, &CONVERTERS[1], now_ms),
        ];
        if let Some(refusal) = self.gate.step(now_ms, self.readings) {
            log.line(format_args!("t={now_ms} ms pin 11 (AIR+) low: {refusal}"));
        }
        self.apply();
    }

    fn command<const N: usize>(
        &mut self,
        command: Command<'_>,
        now_ms: u32,
        log: &mut LogBuffer<N>,
    ) -> Reply {
        Reply::Say(match command {
            Command::ConfirmHvDisconnected => match self.gate.confirm(now_ms, self.readings) {
                Ok(()) => {
                    "HV outputs armed for 30 s (both converters alive and below 60 V; checked every 10 ms)"
                }
                Err(refusal) => {
                    log.line(format_args!("refused: {refusal}"));
                    "not confirmed"
                }
            },
            Command::Output {
                signal: "air-plus-close",
                level,
            } => {
                let answer = self.gate.set(level.high(), now_ms, self.readings);
                self.apply();
                match answer {
                    AirPlusAnswer::Refused(_) => {
                        log.line(format_args!("{answer}"));
                        "refused (the line above says why)"
                    }
                    AirPlusAnswer::High => {
                        "pin 11 (AIR+) HIGH for at most 30 s from the confirmation"
                    }
                    AirPlusAnswer::Low => "pin 11 (AIR+) low",
                }
            }
            Command::Output {
                signal: "led",
                level,
            } => {
                self.hw.set_led(level.high());
                "led set"
            }
            Command::Output { .. } => "no such output on the PCC: air-plus-close, led",
            Command::AllOff => {
                self.all_off();
                "every output low, confirmation revoked"
            }
            Command::CanTest => self.can_test(log),
            Command::Calibrate(_)
            | Command::CalibrateShock { .. }
            | Command::CalSave
            | Command::CalLoad
            | Command::CalErase
            | Command::I2cScan
            | Command::ConfirmWheelsOffGround
            | Command::DtiEnable => "not on the PCC",
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
        inputs: &VfInputs,
        log: &mut LogBuffer<N>,
    ) {
        let edges = self.hw.edges();
        let [counts1, counts2] = self.hw.thermistors();
        if self.heartbeats {
            self.heartbeat = self.heartbeat.wrapping_add(1);
            if let Some(frame) =
                StandardId::new(HEARTBEAT_ID).and_then(|id| CanFrame::new(id, &[self.heartbeat]))
            {
                let _queued = self.hw.transmit(&frame);
            }
        }
        let [accumulator_pin, tractive_pin] = self.board.voltage_freq;
        let reading = |pin, vf| VfReading {
            input: DigitalReading {
                pin,
                high: false,
                edges: 0,
                hz: 0.0,
            },
            vf,
        };
        let mut vf = [
            reading(accumulator_pin, CONVERTERS[0]),
            reading(tractive_pin, CONVERTERS[1]),
        ];
        for (((reading, high), before), after) in vf
            .iter_mut()
            .zip(inputs.levels)
            .zip(self.edges_before)
            .zip(edges)
        {
            reading.input.high = high;
            reading.input.edges = after;
            reading.input.hz = edge_rate_hz(before, after, elapsed_ms);
        }
        let [pin1, pin2] = self.board.thermistors;
        BringupReport {
            header,
            vf,
            thermistors: [
                ThermistorReading(AnalogReading {
                    pin: pin1,
                    counts: counts1,
                    divider: 1.0,
                }),
                ThermistorReading(AnalogReading {
                    pin: pin2,
                    counts: counts2,
                    divider: 1.0,
                }),
            ],
            bus: BusLine {
                name: "CAN2",
                status: self.hw.bus_status(),
                heard: &self.heard,
            },
            gate: self.gate.line(header.now_ms, self.readings),
        }
        .write(log);
        self.edges_before = edges;
        self.heard = Heard::default();
    }

    fn toggle_led(&mut self) {
        let on = self.hw.led();
        self.hw.set_led(!on);
    }
}

fn raw_id(frame: &CanFrame) -> u32 {
    match frame.id() {
        Id::Standard(id) => u32::from(id.as_raw()),
        Id::Extended(id) => id.as_raw(),
    }
}
