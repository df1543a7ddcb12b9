//! The PCC board (Teensy 4.0): the typed pins for `aer_boards::pcc::COMP_CAR`, the one
//! description of the board. Each pin here is checked against it when this compiles, so the
//! firmware and `cargo xtask pins` cannot disagree.

use aer_boards::pcc::{COMP_CAR as BOARD, Revision};
use aer_boards::{Mode, check};
use teensy4_bsp::hal::iomuxc::gpio::Pin as GpioPin;
use teensy4_bsp::pins::t40 as pins;

/// The board revision this image is built for.
pub const REVISION: Revision = BOARD;

/// CAN bit rate of the vehicle bus.
pub const CAN_BITRATE: u32 = 500_000;

/// The FlexCAN instance wired to the transceiver.
pub const CAN_INSTANCE: u8 = 2;

const _: () = {
    let [tx, rx] = BOARD.can;
    check(tx, 1, Mode::CanTx(CAN_INSTANCE));
    check(rx, 0, Mode::CanRx(CAN_INSTANCE));
    check(BOARD.air_plus, 11, Mode::OutputPullDown);
    let [accumulator, tractive] = BOARD.voltage_freq;
    check(accumulator, 14, Mode::InputPullDown);
    check(tractive, 15, Mode::InputPullDown);
    check(BOARD.led, 13, Mode::Output);
    let [thermistor1, thermistor2] = BOARD.thermistors;
    check(thermistor1, 21, Mode::Analog(7));
    check(thermistor2, 22, Mode::Analog(8));
};

/// The board's signals, taken from the Teensy 4.0 pins. Ports: pins 11 and 13 are GPIO2,
/// 14-15 GPIO1 (their edge interrupt is GPIO1_COMBINED_16_31).
pub struct Pins {
    /// CAN2 TX (pin 1).
    pub can_tx: pins::P1,
    /// CAN2 RX (pin 0).
    pub can_rx: pins::P0,
    /// Accumulator V/F converter output, rising edges counted (pin 14).
    pub accumulator_freq: pins::P14,
    /// Tractive-system V/F converter output (pin 15).
    pub tractive_freq: pins::P15,
    /// Close AIR+, high = closed (pin 11): the board's only relay output.
    pub air_plus: pins::P11,
    /// The on-board LED (pin 13).
    pub led: pins::P13,
    /// Precharge-resistor thermistors (A7 = pin 21, A8 = pin 22).
    pub thermistors: ThermistorPins,
}

/// The precharge-resistor thermistors' pins (A7 = pin 21, A8 = pin 22).
pub type ThermistorPins = (pins::P21, pins::P22);

/// GPIO2 bit of the AIR+ output on pin 11: the panic handler clears it without the HAL.
pub const AIR_PLUS_GPIO2_MASK: u32 = 1 << <pins::P11 as GpioPin<2>>::OFFSET;

/// Pulls pin 11's pad down (100 kOhm, the keeper off), without making it an output: the first
/// thing every PCC image does, before even the board check. After a watchdog reset from ONLINE
/// the pad's keeper would otherwise hold the level AIR+ was closed at for as long as the image
/// does not reach its outputs (a board it stops on). On a Teensy 4.1 pin 11 is the same pad,
/// and a pull-down there drives nothing.
pub fn park_air_plus(pins: &mut pins::Pins) {
    use teensy4_bsp::hal::iomuxc::{self, Config, PullKeeper};
    iomuxc::configure(
        &mut pins.p11,
        Config::modify().set_pull_keeper(Some(PullKeeper::Pulldown100k)),
    );
}

/// Assigns the Teensy's pins to the board's signals.
pub fn pins(pins: pins::Pins) -> Pins {
    Pins {
        can_tx: pins.p1,
        can_rx: pins.p0,
        accumulator_freq: pins.p14,
        tractive_freq: pins.p15,
        air_plus: pins.p11,
        led: pins.p13,
        thermistors: (pins.p21, pins.p22),
    }
}
