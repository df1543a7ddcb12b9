//! The CCM's board as the bring-up bench (`aer_ccm::bench`) drives it: the on-chip ADC inputs
//! in the board table's order, the pedal front-end, the buttons, the outputs, both CAN
//! controllers, the calibration's flash and the watchdog; the bench's decisions are all in
//! the library.

use crate::WHEEL_EDGES;
use aer_ccm::apps::PedalVolts;
use aer_ccm::bench::{Bus, CcmHardware, Output};
#[cfg(feature = "pedals-ads1115")]
use aer_ccm::hw::pedals::{self, PedalFrontEnd};
use aer_ccm::hw::{self, SetupFailed, flash::TeensyFlash, pwm::PwmBlock};
use aer_console::usb::UsbConsole;
use aer_console::{Level, LogBuffer};
use aer_flexcan::{BusStatus, CanFrame, Flexcan, SelfTestError};
use core::sync::atomic::Ordering;
use teensy4_bsp::hal::{adc, flexpwm::Channel, gpio};
use teensy4_bsp::ral;

/// The on-chip ADC inputs, in the board table's order of analog pins: the pedals (on that
/// option), BSE1, BSE2, the shocks and thermistor 1.
#[cfg(not(feature = "pedals-ads1115"))]
const ANALOG: usize = 9;
#[cfg(feature = "pedals-ads1115")]
const ANALOG: usize = 7;

/// The image's analog inputs are the board table's, one for one.
const _: () = {
    let pins = hw::board::REVISION.pins();
    let mut analog = 0;
    let mut index = 0;
    while index < pins.len() {
        if let aer_boards::Mode::Analog(_) = pins[index].mode {
            analog += 1;
        }
        index += 1;
    }
    assert!(
        analog == ANALOG,
        "the board table lists another number of analog inputs than the image reads"
    );
};

/// What the bench drives and reads on the Teensy.
pub struct TeensyCcm {
    adc: adc::Adc,
    analog: [adc::AnalogInput; ANALOG],
    #[cfg(feature = "pedals-ads1115")]
    ads: PedalFrontEnd,
    buttons: [gpio::Input; 2],
    brake_light: gpio::Output,
    led: gpio::Output,
    pumps: PwmBlock,
    fan: PwmBlock,
    buzzer: PwmBlock,
    vehicle_can: Option<Flexcan<3>>,
    inverter_can: Option<Flexcan<2>>,
    wdog: ral::wdog::WDOG1,
    flash: TeensyFlash,
}

impl TeensyCcm {
    /// The set-up board; hands back what the image shares with interrupts (the wheel inputs,
    /// the console). A controller that did not start is reported and left out.
    pub fn new<const N: usize>(
        board: hw::Ccm,
        log: &mut LogBuffer<N>,
    ) -> Result<(Self, [gpio::Input; 2], Option<UsbConsole>), SetupFailed> {
        let adc = board.adc;
        let thermistor = adc
            .input::<_, 1>(board.thermistor)
            .map_err(|_| SetupFailed)?;
        let [bse1, bse2] = board.brakes;
        let [s1, s2, s3, s4] = board.shocks;
        #[cfg(not(feature = "pedals-ads1115"))]
        let analog = {
            let [apps1, apps2] = board.pedals;
            [apps1, apps2, bse1, bse2, s1, s2, s3, s4, thermistor]
        };
        #[cfg(feature = "pedals-ads1115")]
        let analog = [bse1, bse2, s1, s2, s3, s4, thermistor];
        let vehicle_can = board
            .vehicle_can
            .map_err(|error| log.line(format_args!("CAN3 did not start: {error}")))
            .ok();
        let inverter_can = board
            .inverter_can
            .map_err(|error| log.line(format_args!("CAN2 did not start: {error}")))
            .ok();
        let teensy = Self {
            adc,
            analog,
            #[cfg(feature = "pedals-ads1115")]
            ads: board.pedals,
            buttons: [board.ready_to_move, board.launch],
            brake_light: board.brake_light,
            led: board.led,
            pumps: board.pumps,
            fan: board.fan,
            buzzer: board.buzzer,
            vehicle_can,
            inverter_can,
            wdog: board.wdog,
            flash: TeensyFlash::new(board.board.built_for),
        };
        Ok((teensy, board.wheels, board.console))
    }
}

impl CcmHardware for TeensyCcm {
    type Flash = TeensyFlash;

    fn analog(&mut self, index: usize) -> u16 {
        self.analog
            .get_mut(index)
            .map_or(0, |input| self.adc.read_blocking(input))
    }

    #[cfg(not(feature = "pedals-ads1115"))]
    fn ads1115(&mut self) -> Option<(PedalVolts, u32)> {
        None
    }

    #[cfg(feature = "pedals-ads1115")]
    fn ads1115(&mut self) -> Option<(PedalVolts, u32)> {
        Some(pedals::read(&mut self.adc, &mut self.ads))
    }

    fn buttons(&self) -> [bool; 2] {
        self.buttons.each_ref().map(|input| input.is_set())
    }

    fn wheel_edges(&self) -> [u32; 2] {
        WHEEL_EDGES
            .each_ref()
            .map(|edges| edges.load(Ordering::Relaxed))
    }

    fn set_output(&mut self, output: Output, level: Level) {
        let digital = |pin: &gpio::Output| {
            if level.high() {
                pin.set();
            } else {
                pin.clear();
            }
        };
        match output {
            Output::BrakeLight => digital(&self.brake_light),
            Output::Led => digital(&self.led),
            Output::Pump1 => self.pumps.set_duty(Channel::A, level.duty()),
            Output::Pump2 => self.pumps.set_duty(Channel::B, level.duty()),
            Output::Fan => self.fan.set_duty(Channel::B, level.duty()),
            Output::Buzzer => self.buzzer.set_duty(Channel::A, level.duty() / 2.0),
        }
    }

    fn brake_light(&self) -> bool {
        self.brake_light.is_set()
    }

    fn toggle_led(&mut self) {
        self.led.toggle();
    }

    fn receive(&mut self, bus: Bus) -> Option<CanFrame> {
        match bus {
            Bus::Vehicle => self.vehicle_can.as_mut()?.receive(),
            Bus::Inverter => self.inverter_can.as_mut()?.receive(),
        }
    }

    fn transmit(&mut self, bus: Bus, frame: &CanFrame, latest: bool) -> bool {
        let sent = match (bus, latest) {
            (Bus::Vehicle, false) => self.vehicle_can.as_mut().map(|can| can.transmit(frame)),
            (Bus::Vehicle, true) => self
                .vehicle_can
                .as_mut()
                .map(|can| can.transmit_latest(frame)),
            (Bus::Inverter, false) => self.inverter_can.as_mut().map(|can| can.transmit(frame)),
            (Bus::Inverter, true) => self
                .inverter_can
                .as_mut()
                .map(|can| can.transmit_latest(frame)),
        };
        sent.is_some_and(|sent| sent.is_ok())
    }

    fn self_test(&mut self, bus: Bus, frame: &CanFrame) -> Option<Result<(), SelfTestError>> {
        match bus {
            Bus::Vehicle => self.vehicle_can.as_mut().map(|can| can.self_test(frame)),
            Bus::Inverter => self.inverter_can.as_mut().map(|can| can.self_test(frame)),
        }
    }

    fn bus_status(&self, bus: Bus) -> Option<BusStatus> {
        match bus {
            Bus::Vehicle => self.vehicle_can.as_ref().map(|can| can.status()),
            Bus::Inverter => self.inverter_can.as_ref().map(|can| can.status()),
        }
    }

    #[cfg(not(feature = "pedals-ads1115"))]
    fn i2c_scan(&mut self, _: &mut dyn FnMut(core::fmt::Arguments<'_>)) -> Option<()> {
        None
    }

    /// Every 7-bit address that acknowledges a one-byte read, then the ADS1115's config
    /// register. Each transaction is bounded by the controller's pin-low timeout.
    #[cfg(feature = "pedals-ads1115")]
    fn i2c_scan(&mut self, log: &mut dyn FnMut(core::fmt::Arguments<'_>)) -> Option<()> {
        use embedded_hal::i2c::I2c;
        let mut byte = [0u8; 1];
        for address in 0x08u8..0x78 {
            if self.ads.bus().read(address, &mut byte).is_ok() {
                log(format_args!("i2c: {address:#04x} answers"));
            }
        }
        let config = self.ads.read_config();
        log(format_args!("ADS1115 config register: {config:04x?}"));
        Some(())
    }

    fn feed_watchdog(&mut self) {
        hw::feed_watchdog(&self.wdog);
    }

    fn flash(&mut self) -> &mut TeensyFlash {
        &mut self.flash
    }
}
