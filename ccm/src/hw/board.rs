//! The CCM board (Teensy 4.1): the typed pins for the board revision this image is built for
//! (`aer_boards::ccm`, the one description of the board). Each pin here is checked against it
//! when this compiles, so the firmware and `cargo xtask pins` cannot disagree.

use aer_boards::ccm::Revision;
#[cfg(not(feature = "pedals-ads1115"))]
use aer_boards::ccm::{COMP_CAR as BOARD, Pedals};
#[cfg(feature = "pedals-ads1115")]
use aer_boards::ccm::{COMP_CAR_ADS1115 as BOARD, Pedals};
use aer_boards::{Mode, check};
use teensy4_bsp::pins::t41 as pins;

/// The board revision this image is built for.
pub const REVISION: Revision = BOARD;

/// CAN bit rate of both buses.
pub const CAN_BITRATE: u32 = 500_000;

const _: () = {
    let [tx, rx] = BOARD.inverter_can;
    check(tx, 1, Mode::CanTx(2));
    check(rx, 0, Mode::CanRx(2));
    let [tx, rx] = BOARD.vehicle_can;
    check(tx, 31, Mode::CanTx(3));
    check(rx, 30, Mode::CanRx(3));
    match BOARD.pedals {
        Pedals::OnChipAdc {
            apps: [apps1, apps2],
        } => {
            check(apps1, 19, Mode::Analog(5));
            check(apps2, 18, Mode::Analog(4));
        }
        Pedals::Ads1115 {
            i2c: [sda, scl], ..
        } => {
            check(sda, 18, Mode::I2cSda);
            check(scl, 19, Mode::I2cScl);
        }
    }
    let [bse1, bse2] = BOARD.brakes;
    check(bse1, 17, Mode::Analog(3));
    check(bse2, 16, Mode::Analog(2));
    let [s1, s2, s3, s4] = BOARD.shocks;
    check(s1, 20, Mode::Analog(6));
    check(s2, 21, Mode::Analog(7));
    check(s3, 22, Mode::Analog(8));
    check(s4, 23, Mode::Analog(9));
    check(BOARD.thermistor, 14, Mode::Analog(0));
    let [w1, w2] = BOARD.wheel_speed;
    check(w1, 2, Mode::InputPullUp);
    check(w2, 3, Mode::InputPullUp);
    check(BOARD.ready_to_move, 36, Mode::InputPullDown);
    check(BOARD.launch, 33, Mode::InputPullDown);
    check(BOARD.brake_light, 9, Mode::Output);
    let [pump1, pump2] = BOARD.pumps;
    check(pump1, 29, Mode::Pwm(PUMP_PWM_HZ));
    check(pump2, 28, Mode::Pwm(PUMP_PWM_HZ));
    check(BOARD.fan, 7, Mode::Pwm(FAN_PWM_HZ));
    check(BOARD.buzzer, 4, Mode::Pwm(BUZZER_HZ));
    check(BOARD.led, 13, Mode::Output);
};

/// Pumps' PWM frequency (Hz): FlexPWM3 submodule 1, A (pin 29) and B (pin 28).
pub const PUMP_PWM_HZ: u32 = 25_000;
/// Fan's PWM frequency (Hz): FlexPWM1 submodule 3, B (pin 7).
pub const FAN_PWM_HZ: u32 = 500;
/// Buzzer tone (Hz): FlexPWM2 submodule 0, A (pin 4).
pub const BUZZER_HZ: u32 = 2_000;

/// Thermistor 1's pin (A0).
pub type ThermistorPin = pins::P14;

/// The pedal front-end's pins: APPS1 (A5) and APPS2 (A4) on the on-chip ADC, or, with the
/// ADS1115 option, LPI2C1's SCL (19) and SDA (18).
pub type PedalPins = (pins::P19, pins::P18);

/// The board's signals. Ports: wheel speed (2, 3) and launch (33) are GPIO4 (wheel edges
/// interrupt on GPIO4_COMBINED_0_15); ready-to-move (36), brake light (9) and the LED (13)
/// are GPIO2.
pub struct Pins {
    /// FlexCAN2 TX/RX (pins 1/0): the inverter.
    pub inverter_can: (pins::P1, pins::P0),
    /// FlexCAN3 TX/RX (pins 31/30): BMS, charger, PCC, IMD, the Pi, ISO-TP telemetry.
    pub vehicle_can: (pins::P31, pins::P30),
    /// APPS1 (A5), APPS2 (A4) on the on-chip ADC, or LPI2C1 SCL/SDA for the ADS1115.
    pub pedals: PedalPins,
    /// BSE1 (A3), BSE2 (A2).
    pub brakes: (pins::P17, pins::P16),
    /// Shock potentiometers 1-4 (A6-A9).
    pub shocks: (pins::P20, pins::P21, pins::P22, pins::P23),
    /// Thermistor 1 (A0).
    pub thermistor: ThermistorPin,
    /// Front wheel-speed sensors 1 and 2.
    pub wheels: (pins::P2, pins::P3),
    /// Ready-to-move button (active high).
    pub ready_to_move: pins::P36,
    /// Launch-control button (active high; assumed).
    pub launch: pins::P33,
    /// Brake light driver (high = on).
    pub brake_light: pins::P9,
    /// Pumps 1 and 2 (PWM).
    pub pumps: (pins::P29, pins::P28),
    /// Fan (PWM).
    pub fan: pins::P7,
    /// Ready-to-drive buzzer (PWM; assumed).
    pub buzzer: pins::P4,
    /// The on-board LED.
    pub led: pins::P13,
}

/// Assigns the Teensy's pins to the board's signals.
pub fn pins(pins: pins::Pins) -> Pins {
    Pins {
        inverter_can: (pins.p1, pins.p0),
        vehicle_can: (pins.p31, pins.p30),
        pedals: (pins.p19, pins.p18),
        brakes: (pins.p17, pins.p16),
        shocks: (pins.p20, pins.p21, pins.p22, pins.p23),
        thermistor: pins.p14,
        wheels: (pins.p2, pins.p3),
        ready_to_move: pins.p36,
        launch: pins.p33,
        brake_light: pins.p9,
        pumps: (pins.p29, pins.p28),
        fan: pins.p7,
        buzzer: pins.p4,
        led: pins.p13,
    }
}
