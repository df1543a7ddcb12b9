//! The PCC board (Teensy 4.0): pin assignments and hardware constants, in one place.
//!
//! From vehicle-facts.md: shutdown relay control on pin 11, V/F converter inputs on pins 14
//! (accumulator) and 15 (tractive system). The AIR+/AIR-/precharge relay drivers and the
//! Shutdown_in input are not documented there; the pins below are this firmware's choice and
//! must match the board's schematic before the first HV test.

use teensy4_bsp::hal::iomuxc::gpio::Pin as GpioPin;
use teensy4_bsp::pins::t40 as pins;

/// CAN bit rate of both car buses.
pub const CAN_BITRATE: u32 = 500_000;

/// FlexCAN instance wired to the transceiver: CAN2 (pin 1 TX, pin 0 RX). CAN1's pins 22/23
/// carry the precharge-resistor thermistors on this board.
pub const CAN_INSTANCE: u8 = 2;

/// The board's signals, taken from the Teensy 4.0 pins. Ports: pins 2-4 are GPIO4, 11-12
/// GPIO2, 14-15 GPIO1 (their edge interrupt is GPIO1_COMBINED_16_31).
pub struct Pins {
    /// CAN TX (pin 1).
    pub can_tx: pins::P1,
    /// CAN RX (pin 0).
    pub can_rx: pins::P0,
    /// Accumulator V/F converter output, rising edges counted (pin 14).
    pub accumulator_freq: pins::P14,
    /// Tractive-system V/F converter output (pin 15).
    pub tractive_freq: pins::P15,
    /// AIR+ driver, high = closed (pin 2).
    pub air_plus: pins::P2,
    /// AIR- driver, high = closed (pin 3).
    pub air_minus: pins::P3,
    /// Precharge relay driver, high = closed (pin 4).
    pub precharge: pins::P4,
    /// Shutdown relay control, high = position 1, tractive system connected (pin 11).
    pub shutdown_control: pins::P11,
    /// Shutdown_in, active high when the shutdown circuit is open (pin 12).
    pub shutdown_in: pins::P12,
}

/// GPIO4 bits of the relay drivers on pins 2, 3 and 4 (AIR+, AIR-, precharge): the panic
/// handler clears them without the HAL.
pub const RELAYS_GPIO4_MASK: u32 = 1 << <pins::P2 as GpioPin<4>>::OFFSET
    | 1 << <pins::P3 as GpioPin<4>>::OFFSET
    | 1 << <pins::P4 as GpioPin<4>>::OFFSET;
/// GPIO2 bit of the shutdown relay control on pin 11.
pub const SHUTDOWN_GPIO2_MASK: u32 = 1 << <pins::P11 as GpioPin<2>>::OFFSET;

/// Assigns the Teensy's pins to the board's signals.
pub fn pins(pins: pins::Pins) -> Pins {
    Pins {
        can_tx: pins.p1,
        can_rx: pins.p0,
        accumulator_freq: pins.p14,
        tractive_freq: pins.p15,
        air_plus: pins.p2,
        air_minus: pins.p3,
        precharge: pins.p4,
        shutdown_control: pins.p11,
        shutdown_in: pins.p12,
    }
}
