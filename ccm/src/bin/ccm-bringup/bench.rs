//! The CCM's bench checks, as the bring-up loop (`aer_console::bench`) drives them: every
//! analog input, the buttons and wheel-speed inputs, both CAN controllers (and a DTI on the
//! inverter bus), the outputs on command, the pedal and brake calibration, the I2C scan on
//! the ADS1115 board, and the DTI's command-timeout test behind the HV gate.

use crate::WHEEL_EDGES;
use aer_boards::Pin;
use aer_ccm::calibration::{BenchPoint, BenchRecorder, EPK};
use aer_ccm::console::bringup::{self, Report};
use aer_ccm::console::dti::DtiBench;
#[cfg(feature = "pedals-ads1115")]
use aer_ccm::hw::pedals::{self, PedalFrontEnd};
use aer_ccm::hw::{self, SetupFailed, board, flash::TeensyFlash, pwm::PwmBlock};
use aer_console::bench::{BenchBoard, Reply};
use aer_console::bringup::{
    AnalogReading, BusLine, DigitalReading, Heard, HvGate, HvReadings, ReportHeader, SelfTestLine,
    edge_rate_hz,
};
use aer_console::usb::UsbConsole;
use aer_console::{Command, Level, LogBuffer, PedalPosition};
use aer_flexcan::{CanFrame, Flexcan};
use core::sync::atomic::Ordering;
use embedded_can::{ExtendedId, Frame, Id, StandardId};
use teensy4_bsp::hal::{adc, flexpwm::Channel, gpio};
use teensy4_bsp::ral;

/// Discharged below this (V): the rules' 60 V DC.
const DISCHARGED_V: f32 = 60.0;
/// Heartbeats this board sends on `can` (not identifiers of the car's schema).
const HEARTBEAT_IDS: [u16; 2] = [0x7F3, 0x7F2];

/// The analog inputs the on-chip ADC reads: the pedals (on that option), BSE1, BSE2, the
/// shocks and thermistor 1, each with its board entry.
#[cfg(not(feature = "pedals-ads1115"))]
const ANALOG: usize = 9;
#[cfg(feature = "pedals-ads1115")]
const ANALOG: usize = 7;

/// Where BSE1 and BSE2 sit in `analog` (after the pedals on the on-chip ADC).
#[cfg(not(feature = "pedals-ads1115"))]
const BRAKES: [usize; 2] = [2, 3];
#[cfg(feature = "pedals-ads1115")]
const BRAKES: [usize; 2] = [0, 1];

/// Everything the bench drives and reads, and what its tests remember.
pub struct CcmBench {
    adc: adc::Adc,
    analog: [(Pin, adc::AnalogInput); ANALOG],
    #[cfg(feature = "pedals-ads1115")]
    ads: PedalFrontEnd,
    buttons: [(Pin, gpio::Input); 2],
    brake_light: gpio::Output,
    led: gpio::Output,
    pumps: PwmBlock,
    fan: PwmBlock,
    buzzer: PwmBlock,
    vehicle_can: Option<Flexcan<3>>,
    inverter_can: Option<Flexcan<2>>,
    wdog: ral::wdog::WDOG1,
    calibration: BenchRecorder,
    flash: TeensyFlash,
    heard: [Heard; 2],
    dti: DtiBench,
    gate: HvGate,
    heartbeats: bool,
    heartbeat: u8,
    wheels_before: [u32; 2],
    buttons_before: [bool; 2],
    button_edges: [u32; 2],
}

impl CcmBench {
    /// The bench over the set-up board; hands back what the image shares with interrupts
    /// (the wheel inputs, the console). A controller that did not start is reported and left
    /// out.
    pub fn new<const N: usize>(
        board: hw::Ccm,
        log: &mut LogBuffer<N>,
    ) -> Result<(Self, [gpio::Input; 2], Option<UsbConsole>), SetupFailed> {
        let b = board::REVISION;
        let adc = board.adc;
        let thermistor = adc
            .input::<_, 1>(board.thermistor)
            .map_err(|_| SetupFailed)?;
        let [bse1, bse2] = board.brakes;
        let [s1, s2, s3, s4] = board.shocks;
        let [pin_bse1, pin_bse2] = b.brakes;
        let [pin_s1, pin_s2, pin_s3, pin_s4] = b.shocks;
        let common = [
            (pin_bse1, bse1),
            (pin_bse2, bse2),
            (pin_s1, s1),
            (pin_s2, s2),
            (pin_s3, s3),
            (pin_s4, s4),
            (b.thermistor, thermistor),
        ];
        #[cfg(not(feature = "pedals-ads1115"))]
        let analog = {
            let aer_boards::ccm::Pedals::OnChipAdc {
                apps: [pin_apps1, pin_apps2],
            } = b.pedals
            else {
                return Err(SetupFailed);
            };
            let [apps1, apps2] = board.pedals;
            let [c0, c1, c2, c3, c4, c5, c6] = common;
            [
                (pin_apps1, apps1),
                (pin_apps2, apps2),
                c0,
                c1,
                c2,
                c3,
                c4,
                c5,
                c6,
            ]
        };
        #[cfg(feature = "pedals-ads1115")]
        let analog = common;
        let vehicle_can = board
            .vehicle_can
            .map_err(|error| log.line(format_args!("CAN3 did not start: {error}")))
            .ok();
        let inverter_can = board
            .inverter_can
            .map_err(|error| log.line(format_args!("CAN2 did not start: {error}")))
            .ok();
        let bench = Self {
            adc,
            analog,
            #[cfg(feature = "pedals-ads1115")]
            ads: board.pedals,
            buttons: [
                (b.ready_to_move, board.ready_to_move),
                (b.launch, board.launch),
            ],
            brake_light: board.brake_light,
            led: board.led,
            pumps: board.pumps,
            fan: board.fan,
            buzzer: board.buzzer,
            vehicle_can,
            inverter_can,
            wdog: board.wdog,
            calibration: BenchRecorder::default(),
            flash: TeensyFlash::new(),
            heard: [Heard::default(); 2],
            dti: DtiBench::default(),
            gate: HvGate::new(DISCHARGED_V),
            heartbeats: false,
            heartbeat: 0,
            wheels_before: [0; 2],
            buttons_before: [false; 2],
            button_edges: [0; 2],
        };
        Ok((bench, board.wheels, board.console))
    }

    /// The DTI's own DC link reading, the HV gate's evidence.
    fn dc_link(&self, now_ms: u32) -> [(&'static str, Option<f32>); 1] {
        [("DTI DC link", self.dti.dc_link_v(now_ms))]
    }

    /// Both brake sensors (BSE1 front, BSE2 rear) in volts at the sensor, as the race image
    /// reads them.
    fn brake_volts(&mut self) -> [f32; 2] {
        let divider = board::REVISION.adc_divider;
        BRAKES.map(|index| {
            self.analog.get_mut(index).map_or(f32::NAN, |(_, input)| {
                aer_ccm::analog::sensor_volts(self.adc.read_blocking(input), divider)
            })
        })
    }

    /// Both pedal sensors in volts at the sensor, as the race image reads them.
    #[cfg(not(feature = "pedals-ads1115"))]
    fn pedal_volts(&mut self) -> aer_ccm::apps::PedalVolts {
        let [(_, apps1), (_, apps2), ..] = &mut self.analog;
        let counts = [self.adc.read_blocking(apps1), self.adc.read_blocking(apps2)];
        aer_ccm::analog::pedal_volts(counts, board::REVISION.adc_divider)
    }

    #[cfg(feature = "pedals-ads1115")]
    fn pedal_volts(&mut self) -> aer_ccm::apps::PedalVolts {
        pedals::read(&mut self.adc, &mut self.ads).0
    }

    /// Queues the `dti enable` test's frames on the inverter bus (each replaces a pending
    /// frame with its id). A frame that did not encode is not sent: the DTI sees silence.
    fn send_dti(&mut self, frames: Result<aer_ccm::OutFrames, aer::runtime::EncodeError>) {
        let (Some(can), Ok(frames)) = (self.inverter_can.as_mut(), frames) else {
            return;
        };
        for frame in frames.iter() {
            let can_frame = ExtendedId::new(frame.id)
                .map(Id::Extended)
                .and_then(|id| CanFrame::new(id, frame.data()));
            if let Some(can_frame) = can_frame {
                let _queued = can.transmit_latest(&can_frame);
            }
        }
    }

    fn send_heartbeats(&mut self) {
        self.heartbeat = self.heartbeat.wrapping_add(1);
        let counter = [self.heartbeat];
        if let (Some(can), Some(frame)) = (self.vehicle_can.as_mut(), heartbeat_frame(0, &counter))
        {
            let _queued = can.transmit(&frame);
        }
        if let (Some(can), Some(frame)) = (self.inverter_can.as_mut(), heartbeat_frame(1, &counter))
        {
            let _queued = can.transmit(&frame);
        }
    }

    fn output(&mut self, signal: &str, level: Level) -> &'static str {
        let digital = |pin: &gpio::Output| {
            if level.high() {
                pin.set();
            } else {
                pin.clear();
            }
        };
        match signal {
            "brake-light" => digital(&self.brake_light),
            "led" => digital(&self.led),
            "pump1" => self.pumps.set_duty(Channel::A, level.duty()),
            "pump2" => self.pumps.set_duty(Channel::B, level.duty()),
            "fan" => self.fan.set_duty(Channel::B, level.duty()),
            "rtd-buzzer" => self.buzzer.set_duty(Channel::A, level.duty() / 2.0),
            _ => return "no such output: brake-light, led, pump1, pump2, fan, rtd-buzzer",
        }
        "done"
    }

    fn can_test<const N: usize>(&mut self, log: &mut LogBuffer<N>) -> &'static str {
        let vehicle = self
            .vehicle_can
            .as_mut()
            .zip(heartbeat_frame(0, &[0xA5, 0x5A, 3]))
            .map(|(can, frame)| can.self_test(&frame));
        let inverter = self
            .inverter_can
            .as_mut()
            .zip(heartbeat_frame(1, &[0xA5, 0x5A, 2]))
            .map(|(can, frame)| can.self_test(&frame));
        for (name, result) in [("CAN3 (vehicle)", vehicle), ("CAN2 (inverter)", inverter)] {
            log.line(format_args!("{}", SelfTestLine { name, result }));
        }
        self.heartbeats = true;
        "heartbeats 0x7F3 on CAN3 and 0x7F2 on CAN2 every second from now"
    }

    #[cfg(not(feature = "pedals-ads1115"))]
    fn i2c_scan<const N: usize>(&mut self, _: &mut LogBuffer<N>) -> &'static str {
        "this board reads the pedals on the on-chip ADC: no I2C (build with --features pedals-ads1115)"
    }

    /// Every 7-bit address that acknowledges a one-byte read, then the ADS1115's config
    /// register. Each transaction is bounded by the controller's pin-low timeout.
    #[cfg(feature = "pedals-ads1115")]
    fn i2c_scan<const N: usize>(&mut self, log: &mut LogBuffer<N>) -> &'static str {
        use embedded_hal::i2c::I2c;
        let mut byte = [0u8; 1];
        for address in 0x08u8..0x78 {
            if self.ads.bus().read(address, &mut byte).is_ok() {
                log.line(format_args!("i2c: {address:#04x} answers"));
            }
        }
        let config = self.ads.read_config();
        log.line(format_args!("ADS1115 config register: {config:04x?}"));
        "scan done"
    }
}

impl BenchBoard for CcmBench {
    /// The wheel-speed inputs' levels, read under their interrupt's lock.
    type Shared = [bool; 2];
    const NAME: &'static str = "CCM";
    const SAFE: &'static str = "every output off";

    fn feed_watchdog(&mut self) {
        hw::feed_watchdog(&self.wdog);
    }

    fn all_off(&mut self) {
        self.brake_light.clear();
        self.pumps.set_duty(Channel::A, 0.0);
        self.pumps.set_duty(Channel::B, 0.0);
        self.fan.set_duty(Channel::B, 0.0);
        self.buzzer.set_duty(Channel::A, 0.0);
    }

    fn step<const N: usize>(&mut self, now_ms: u32, log: &mut LogBuffer<N>) {
        if self.calibration.recording() {
            let (pedals, brakes) = (self.pedal_volts(), self.brake_volts());
            if self.calibration.sample(pedals, brakes) {
                bringup::calibration(log, &self.calibration);
            }
        }
        for ((_, input), (before, edges)) in self.buttons.iter().zip(
            self.buttons_before
                .iter_mut()
                .zip(self.button_edges.iter_mut()),
        ) {
            let high = input.is_set();
            if high && !*before {
                *edges = edges.wrapping_add(1);
            }
            *before = high;
        }
        let [heard_vehicle, heard_inverter] = &mut self.heard;
        if let Some(can) = self.vehicle_can.as_mut() {
            for _ in 0..8 {
                let Some(frame) = can.receive() else { break };
                heard_vehicle.frame(raw_id(&frame));
            }
        }
        if let Some(can) = self.inverter_can.as_mut() {
            // The inverter bus also feeds the DTI checks (node id, CAN map, drive, fault, DC
            // link, command timeout).
            for _ in 0..8 {
                let Some(frame) = can.receive() else { break };
                let id = raw_id(&frame);
                let extended = matches!(frame.id(), Id::Extended(_));
                self.dti.frame(now_ms, id, extended, frame.data());
                heard_inverter.frame(id);
            }
        }
        self.dti.poll(now_ms);
        if self.dti.test.active() {
            let dc_link = self.dc_link(now_ms);
            if let Err(refusal) = self.gate.allows(now_ms, HvReadings { volts: &dc_link }) {
                self.dti.test.stop();
                log.line(format_args!("dti enable stopped: {refusal}"));
            } else if let Some(frames) = self.dti.due(now_ms) {
                self.send_dti(frames);
            }
        }
    }

    fn command<const N: usize>(
        &mut self,
        command: Command<'_>,
        now_ms: u32,
        log: &mut LogBuffer<N>,
    ) -> Reply {
        let dc_link = self.dc_link(now_ms);
        let readings = HvReadings { volts: &dc_link };
        Reply::Say(match command {
            Command::Output { signal, level } => self.output(signal, level),
            Command::AllOff => {
                self.all_off();
                self.dti.test.stop();
                self.gate.revoke();
                "every output off"
            }
            Command::ConfirmHvDisconnected => match self.gate.confirm(now_ms, readings) {
                Ok(()) => {
                    "HV confirmed (the DTI reads its DC link below 60 V): `dti enable` armed for 30 s"
                }
                Err(refusal) => {
                    log.line(format_args!("refused: {refusal}"));
                    "not confirmed"
                }
            },
            Command::DtiEnable => match self.gate.allows(now_ms, readings) {
                Ok(()) => {
                    self.dti.test.start(now_ms);
                    "drive enable at 0 A for 1 s, then silence: the report's `DTI command timeout` line gives the result"
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
            Command::CalSave => {
                let calibration = bringup::bench_calibration(&self.calibration);
                let live = self.dti.test.active()
                    || dc_link
                        .iter()
                        .any(|(_, volts)| volts.is_some_and(|v| v >= DISCHARGED_V));
                bringup::cal_save(log, &mut self.flash, &calibration, EPK, live);
                "the line above says what was saved"
            }
            Command::CalLoad => {
                bringup::cal_load(log, &mut self.flash, EPK);
                "the line above is what start-up loads"
            }
            Command::I2cScan => self.i2c_scan(log),
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
        wheel_levels: &[bool; 2],
        log: &mut LogBuffer<N>,
    ) {
        if self.heartbeats {
            self.send_heartbeats();
        }
        let wheels_now = WHEEL_EDGES
            .each_ref()
            .map(|edges| edges.load(Ordering::Relaxed));
        let divider = board::REVISION.adc_divider;
        let analog: [AnalogReading; ANALOG] = core::array::from_fn(|index| {
            let (pin, counts) = self
                .analog
                .get_mut(index)
                .map_or((board::REVISION.thermistor, 0), |(pin, input)| {
                    (*pin, self.adc.read_blocking(input))
                });
            AnalogReading {
                pin,
                counts,
                divider,
            }
        });
        #[cfg(feature = "pedals-ads1115")]
        let ads1115 = Some((self.pedal_volts(), self.ads.bus_errors));
        #[cfg(not(feature = "pedals-ads1115"))]
        let ads1115 = None;
        let mut digital = [DigitalReading {
            pin: board::REVISION.led,
            high: false,
            edges: 0,
            hz: 0.0,
        }; 4];
        let wheels = board::REVISION
            .wheel_speed
            .into_iter()
            .zip(
                self.wheels_before
                    .into_iter()
                    .zip(wheels_now)
                    .zip(*wheel_levels),
            )
            .map(|(pin, ((before, after), high))| DigitalReading {
                pin,
                high,
                edges: after,
                hz: edge_rate_hz(before, after, elapsed_ms),
            });
        let buttons = self
            .buttons
            .iter()
            .zip(self.button_edges)
            .map(|((pin, input), edges)| DigitalReading {
                pin: *pin,
                high: input.is_set(),
                edges,
                hz: 0.0,
            });
        for (slot, reading) in digital.iter_mut().zip(wheels.chain(buttons)) {
            *slot = reading;
        }
        let [heard_vehicle, heard_inverter] = &self.heard;
        Report {
            header: ReportHeader {
                now_ms,
                dropped: log.dropped(),
            },
            analog: &analog,
            ads1115,
            digital: &digital,
            buses: [
                BusLine {
                    name: "CAN3 (vehicle)",
                    status: self.vehicle_can.as_ref().map(|can| can.status()),
                    heard: heard_vehicle,
                },
                BusLine {
                    name: "CAN2 (inverter)",
                    status: self.inverter_can.as_ref().map(|can| can.status()),
                    heard: heard_inverter,
                },
            ],
            dti: &self.dti,
            brake_light: self.brake_light.is_set(),
        }
        .write(log);
        self.wheels_before = wheels_now;
        self.heard = [Heard::default(); 2];
        self.dti.report_done();
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

fn heartbeat_frame(index: usize, payload: &[u8]) -> Option<CanFrame> {
    HEARTBEAT_IDS
        .get(index)
        .and_then(|&id| StandardId::new(id))
        .and_then(|id| CanFrame::new(id, payload))
}
