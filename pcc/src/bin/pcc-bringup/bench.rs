//! The PCC's bench checks, as the bring-up loop (`aer_console::bench`) drives them: both V/F
//! converters (and the voltages they mean), both thermistor inputs, the CAN controller, the
//! LED, and pin 11 (AIR+) behind the HV gate: high only within 30 s of a typed confirmation
//! and only while both converters read below 60 V.

use crate::EDGES;
use aer_console::bench::{BenchBoard, Reply};
use aer_console::bringup::{
    AnalogReading, BusLine, DigitalReading, Heard, HvGate, HvReadings, ReportHeader, SelfTestLine,
    edge_rate_hz,
};
use aer_console::usb::UsbConsole;
use aer_console::{Command, LogBuffer};
use aer_flexcan::{CanFrame, Flexcan};
use aer_pcc::console::{BringupReport, VfReading};
use aer_pcc::hw::{self, SetupFailed, board};
use aer_pcc::{PrechargeConfig, VfConfig};
use core::sync::atomic::Ordering;
use embedded_can::{Frame, Id, StandardId};
use teensy4_bsp::hal::{adc, gpio};
use teensy4_bsp::ral;

/// The heartbeat this board sends after `can` (not an identifier of the car's schema).
const HEARTBEAT_ID: u16 = 0x7F2;

/// Everything the bench drives and reads, and what its tests remember.
pub struct PccBench {
    air_plus: gpio::Output,
    led: gpio::Output,
    adc: adc::Adc,
    thermistors: [adc::AnalogInput; 2],
    can: Option<Flexcan<{ board::CAN_INSTANCE }>>,
    wdog: ral::wdog::WDOG1,
    gate: HvGate,
    /// Both converters' voltages from the last report period's edge rates.
    volts: [Option<f32>; 2],
    heard: Heard,
    edges_before: [u32; 2],
    heartbeats: bool,
    heartbeat: u8,
}

impl PccBench {
    /// The bench over the set-up board; hands back what the image shares with interrupts
    /// (the V/F inputs, the console). A controller that did not start is reported and left
    /// out.
    pub fn new<const N: usize>(
        board: hw::Pcc,
        log: &mut LogBuffer<N>,
    ) -> Result<(Self, [gpio::Input; 2], Option<UsbConsole>), SetupFailed> {
        let adc = board.adc;
        let (thermistor1, thermistor2) = board.thermistors;
        let thermistors = [
            adc.input::<_, 1>(thermistor1).map_err(|_| SetupFailed)?,
            adc.input::<_, 1>(thermistor2).map_err(|_| SetupFailed)?,
        ];
        let can = board
            .can
            .map_err(|error| log.line(format_args!("CAN2 did not start: {error}")))
            .ok();
        let bench = Self {
            air_plus: board.air_plus,
            led: board.led,
            adc,
            thermistors,
            can,
            wdog: board.wdog,
            gate: HvGate::new(PrechargeConfig::CAR.discharged_v),
            volts: [None; 2],
            heard: Heard::default(),
            edges_before: [0; 2],
            heartbeats: false,
            heartbeat: 0,
        };
        Ok((bench, board.vf, board.console))
    }

    /// The converters' voltages, the HV gate's evidence.
    fn readings(&self) -> [(&'static str, Option<f32>); 2] {
        let [accumulator_v, tractive_v] = self.volts;
        [
            ("accumulator (pin 14)", accumulator_v),
            ("tractive system (pin 15)", tractive_v),
        ]
    }

    fn air_plus<const N: usize>(
        &mut self,
        high: bool,
        now_ms: u32,
        log: &mut LogBuffer<N>,
    ) -> &'static str {
        if !high {
            self.air_plus.clear();
            return "pin 11 (AIR+) low";
        }
        let readings = self.readings();
        match self.gate.allows(now_ms, HvReadings { volts: &readings }) {
            Ok(()) => {
                self.air_plus.set();
                "pin 11 (AIR+) HIGH for at most 30 s from the confirmation"
            }
            Err(refusal) => {
                log.line(format_args!("refused: {refusal}"));
                "pin 11 (AIR+) stays low"
            }
        }
    }
}

impl BenchBoard for PccBench {
    /// The V/F inputs' levels, read under their interrupt's lock.
    type Shared = [bool; 2];
    const NAME: &'static str = "PCC";
    const SAFE: &'static str = "pin 11 (AIR+) low";

    fn feed_watchdog(&mut self) {
        hw::feed_watchdog(&self.wdog);
    }

    fn all_off(&mut self) {
        self.air_plus.clear();
    }

    fn step<const N: usize>(&mut self, now_ms: u32, log: &mut LogBuffer<N>) {
        if let Some(can) = self.can.as_mut() {
            while let Some(frame) = can.receive() {
                self.heard.frame(raw_id(&frame));
            }
        }
        if self.air_plus.is_set() {
            let readings = self.readings();
            if let Err(refusal) = self.gate.allows(now_ms, HvReadings { volts: &readings }) {
                self.air_plus.clear();
                self.gate.revoke();
                log.line(format_args!("pin 11 (AIR+) low: {refusal}"));
            }
        }
    }

    fn command<const N: usize>(
        &mut self,
        command: Command<'_>,
        now_ms: u32,
        log: &mut LogBuffer<N>,
    ) -> Reply {
        Reply::Say(match command {
            Command::ConfirmHvDisconnected => {
                let readings = self.readings();
                match self.gate.confirm(now_ms, HvReadings { volts: &readings }) {
                    Ok(()) => "HV outputs armed for 30 s (both converters read below 60 V)",
                    Err(refusal) => {
                        log.line(format_args!("refused: {refusal}"));
                        "not confirmed"
                    }
                }
            }
            Command::Output {
                signal: "air-plus-close",
                level,
            } => self.air_plus(level.high(), now_ms, log),
            Command::Output {
                signal: "led",
                level,
            } => {
                if level.high() {
                    self.led.set();
                } else {
                    self.led.clear();
                }
                "led set"
            }
            Command::Output { .. } => "no such output on the PCC: air-plus-close, led",
            Command::AllOff => {
                self.air_plus.clear();
                self.gate.revoke();
                "every output low"
            }
            Command::CanTest => {
                let result = self.can.as_mut().map(|can| {
                    let frame = StandardId::new(HEARTBEAT_ID)
                        .and_then(|id| CanFrame::new(id, &[0xA5, 0x5A, 2]));
                    frame.map(|frame| can.self_test(&frame))
                });
                log.line(format_args!(
                    "{}",
                    SelfTestLine {
                        name: "CAN2",
                        result: result.flatten()
                    }
                ));
                self.heartbeats = true;
                "heartbeats 0x7F2 every second from now"
            }
            Command::Calibrate(_)
            | Command::CalSave
            | Command::CalLoad
            | Command::I2cScan
            | Command::DtiEnable => "not on the PCC",
            // The loop answers these itself.
            Command::Help | Command::Report | Command::WatchdogTest | Command::Bootloader => {
                "taken by the bench loop"
            }
        })
    }

    fn report<const N: usize>(
        &mut self,
        now_ms: u32,
        elapsed_ms: u32,
        levels: &[bool; 2],
        log: &mut LogBuffer<N>,
    ) {
        let edges = EDGES.each_ref().map(|edges| edges.load(Ordering::Relaxed));
        let counts = self
            .thermistors
            .each_mut()
            .map(|input| self.adc.read_blocking(input));
        if let (true, Some(can)) = (self.heartbeats, self.can.as_mut()) {
            self.heartbeat = self.heartbeat.wrapping_add(1);
            if let Some(frame) =
                StandardId::new(HEARTBEAT_ID).and_then(|id| CanFrame::new(id, &[self.heartbeat]))
            {
                let _queued = can.transmit(&frame);
            }
        }
        let mut vf = board::REVISION.voltage_freq.map(|pin| VfReading {
            input: DigitalReading {
                pin,
                high: false,
                edges: 0,
                hz: 0.0,
            },
            vf: VfConfig::PCC_BOARD,
        });
        for (((reading, high), before), after) in
            vf.iter_mut().zip(*levels).zip(self.edges_before).zip(edges)
        {
            reading.input.high = high;
            reading.input.edges = after;
            reading.input.hz = edge_rate_hz(before, after, elapsed_ms);
        }
        self.volts = vf.map(|reading| Some(reading.volts()));
        let [pin1, pin2] = board::REVISION.thermistors;
        let [counts1, counts2] = counts;
        BringupReport {
            header: ReportHeader {
                now_ms,
                dropped: log.dropped(),
            },
            vf,
            thermistors: [
                AnalogReading {
                    pin: pin1,
                    counts: counts1,
                    divider: 1.0,
                },
                AnalogReading {
                    pin: pin2,
                    counts: counts2,
                    divider: 1.0,
                },
            ],
            bus: BusLine {
                name: "CAN2",
                status: self.can.as_ref().map(|can| can.status()),
                heard: &self.heard,
            },
            air_plus: self.air_plus.is_set(),
        }
        .write(log);
        self.edges_before = edges;
        self.heard = Heard::default();
    }

    fn toggle_led(&mut self) {
        self.led.toggle();
    }
}

fn raw_id(frame: &CanFrame) -> u32 {
    match frame.id() {
        Id::Standard(id) => u32::from(id.as_raw()),
        Id::Extended(id) => id.as_raw(),
    }
}
