//! The PCC's board as the bring-up bench (`aer_pcc::bench`) drives it: pin 11, the LED, the
//! thermistor inputs, CAN2 and the watchdog; the bench's decisions are all in the library.

use crate::EDGES;
use aer_console::LogBuffer;
use aer_console::usb::UsbConsole;
use aer_flexcan::{BusStatus, CanFrame, Flexcan, SelfTestError};
use aer_pcc::bench::PccHardware;
use aer_pcc::hw::{self, SetupFailed, board};
use core::sync::atomic::Ordering;
use teensy4_bsp::hal::{adc, gpio};
use teensy4_bsp::ral;

/// What the bench drives and reads on the Teensy.
pub struct TeensyPcc {
    air_plus: gpio::Output,
    led: gpio::Output,
    adc: adc::Adc,
    thermistors: [adc::AnalogInput; 2],
    can: Option<Flexcan<{ board::CAN_INSTANCE }>>,
    wdog: ral::wdog::WDOG1,
}

impl TeensyPcc {
    /// The set-up board; hands back what the image shares with interrupts (the V/F inputs,
    /// the console). A controller that did not start is reported and left out.
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
        let teensy = Self {
            air_plus: board.air_plus,
            led: board.led,
            adc,
            thermistors,
            can,
            wdog: board.wdog,
        };
        Ok((teensy, board.vf, board.console))
    }
}

impl PccHardware for TeensyPcc {
    fn set_air_plus(&mut self, high: bool) {
        if high {
            self.air_plus.set();
        } else {
            self.air_plus.clear();
        }
    }

    fn set_led(&mut self, high: bool) {
        if high {
            self.led.set();
        } else {
            self.led.clear();
        }
    }

    fn led(&self) -> bool {
        self.led.is_set()
    }

    fn thermistors(&mut self) -> [u16; 2] {
        self.thermistors
            .each_mut()
            .map(|input| self.adc.read_blocking(input))
    }

    fn edges(&self) -> [u32; 2] {
        EDGES.each_ref().map(|edges| edges.load(Ordering::Relaxed))
    }

    fn receive(&mut self) -> Option<CanFrame> {
        self.can.as_mut()?.receive()
    }

    fn transmit(&mut self, frame: &CanFrame) -> bool {
        self.can
            .as_mut()
            .is_some_and(|can| can.transmit(frame).is_ok())
    }

    fn self_test(&mut self, frame: &CanFrame) -> Option<Result<(), SelfTestError>> {
        self.can.as_mut().map(|can| can.self_test(frame))
    }

    fn bus_status(&self) -> Option<BusStatus> {
        self.can.as_ref().map(|can| can.status())
    }

    fn feed_watchdog(&mut self) {
        hw::feed_watchdog(&self.wdog);
    }
}
