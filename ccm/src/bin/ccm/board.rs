//! The CCM board (Teensy 4.1): pin assignments and hardware constants, in one place.
//!
//! vehicle-facts.md fixes the buses (CAN1: BMS, charger, PCC, Pi; CAN2: inverter) and the
//! ADS1115 for the pedals; the pins below are this firmware's choice (Teensy 4.1 defaults for
//! CAN1/CAN2/I2C) and must match the harness before the car runs.

use teensy4_bsp::pins::t41 as pins;

/// CAN bit rate of both buses.
pub const CAN_BITRATE: u32 = 500_000;

/// The board's signals.
pub struct Pins {
    /// CAN1 TX/RX (pins 22/23): BMS, PCC, charger, Pi telemetry.
    pub can1: (pins::P22, pins::P23),
    /// CAN2 TX/RX (pins 1/0): inverter.
    pub can2: (pins::P1, pins::P0),
    /// LPI2C1 SCL/SDA (pins 19/18): the ADS1115 with both pedal sensors.
    pub i2c: (pins::P19, pins::P18),
    /// Brake pressure sensors, front and rear (A0 = pin 14, A1 = pin 15), through a 5 V ->
    /// 3.3 V divider.
    pub brakes: (pins::P14, pins::P15),
    /// Shock potentiometers FL, FR, RL, RR (A2, A3, A6, A7 = pins 16, 17, 20, 21).
    pub shocks: (pins::P16, pins::P17, pins::P20, pins::P21),
    /// Front wheel-speed sensors, left and right (pins 30, 31; GPIO3, one interrupt).
    pub wheels: (pins::P30, pins::P31),
    /// Radiator fan and coolant pump PWM (pins 2, 3: FlexPWM4 submodule 2, A and B).
    pub cooling: (pins::P2, pins::P3),
    /// Ready-to-drive buzzer PWM (pin 4: FlexPWM2 submodule 0, A).
    pub buzzer: pins::P4,
    /// Ready-to-move button (pin 32, active high).
    pub ready_to_move: pins::P32,
    /// Launch-control button (pin 33, active high).
    pub launch: pins::P33,
    /// Brake light driver (pin 34, high = on).
    pub brake_light: pins::P34,
}

/// Assigns the Teensy's pins to the board's signals.
pub fn pins(pins: pins::Pins) -> Pins {
    Pins {
        can1: (pins.p22, pins.p23),
        can2: (pins.p1, pins.p0),
        i2c: (pins.p19, pins.p18),
        brakes: (pins.p14, pins.p15),
        shocks: (pins.p16, pins.p17, pins.p20, pins.p21),
        wheels: (pins.p30, pins.p31),
        cooling: (pins.p2, pins.p3),
        buzzer: pins.p4,
        ready_to_move: pins.p32,
        launch: pins.p33,
        brake_light: pins.p34,
    }
}

/// Brake sensor divider: volts at the sensor per volt at the ADC pin (assumed 5 V -> 3.3 V).
pub const BRAKE_DIVIDER: f32 = 5.0 / 3.3;
/// Shock sensor divider (same assumption as the team's formula: 4095 counts = 5 V).
pub const ADC_REFERENCE_V: f32 = 3.3;
/// PWM frequency of fan and pump (Hz): above hearing.
pub const COOLING_PWM_HZ: u32 = 25_000;
/// Buzzer tone (Hz).
pub const BUZZER_HZ: u32 = 2_000;
