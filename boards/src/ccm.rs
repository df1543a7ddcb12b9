//! The central computer (Teensy 4.1) on the comp car.
//!
//! Two CAN transceivers: FlexCAN2 (the inverter) and FlexCAN3 (BMS, charger, PCC, IMD, the Pi
//! and the ISO-TP telemetry). FlexCAN1 is not wired: its pins 22/23 are analog inputs here.

use crate::{Mode, Pin};

/// How the pedal sensors reach the CCM: a board option. The safety logic reads volts at the
/// sensors either way.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pedals {
    /// APPS1 and APPS2 on on-chip ADC inputs, behind the board's voltage divider (the team's
    /// comp-car code).
    OnChipAdc {
        /// APPS1, APPS2.
        apps: [Pin; 2],
    },
    /// An ADS1115 on LPI2C1 reads both sensors (the team's documentation).
    Ads1115 {
        /// Data, clock.
        i2c: [Pin; 2],
        /// 7-bit address.
        address: u8,
    },
}

/// One revision of the CCM board.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Revision {
    /// The revision's name, as the bring-up image prints it.
    pub name: &'static str,
    /// FlexCAN2 transmit, receive: the inverter.
    pub inverter_can: [Pin; 2],
    /// FlexCAN3 transmit, receive: BMS, charger, PCC, IMD, the Pi, ISO-TP telemetry.
    pub vehicle_can: [Pin; 2],
    /// The pedal front-end.
    pub pedals: Pedals,
    /// Brake pressure sensors BSE1 (front), BSE2 (rear).
    pub brakes: [Pin; 2],
    /// Shock potentiometers 1-4 (FL, FR, RL, RR).
    pub shocks: [Pin; 4],
    /// Coolant thermistor.
    pub thermistor: Pin,
    /// Front wheel-speed sensors, left and right.
    pub wheel_speed: [Pin; 2],
    /// Ready-to-move button (active high).
    pub ready_to_move: Pin,
    /// Launch-control button (active high).
    pub launch: Pin,
    /// Brake light driver (high = on).
    pub brake_light: Pin,
    /// Coolant pumps 1 and 2 (PWM).
    pub pumps: [Pin; 2],
    /// Radiator fan (PWM).
    pub fan: Pin,
    /// Ready-to-drive buzzer (PWM tone).
    pub buzzer: Pin,
    /// The Teensy's on-board LED.
    pub led: Pin,
    /// Volts at a sensor per volt at an analog pin (the divider in front of the ADC).
    pub adc_divider: f32,
}

/// Number of pins a CCM revision uses.
pub const PIN_COUNT: usize = 23;

impl Revision {
    /// Every pin, in the order `cargo xtask pins` prints them.
    pub const fn pins(&self) -> [Pin; PIN_COUNT] {
        let [can2_tx, can2_rx] = self.inverter_can;
        let [can3_tx, can3_rx] = self.vehicle_can;
        let [pedal1, pedal2] = match self.pedals {
            Pedals::OnChipAdc { apps } => apps,
            Pedals::Ads1115 { i2c, .. } => i2c,
        };
        let [bse1, bse2] = self.brakes;
        let [shock1, shock2, shock3, shock4] = self.shocks;
        let [wheel1, wheel2] = self.wheel_speed;
        let [pump1, pump2] = self.pumps;
        [
            can2_tx,
            can2_rx,
            can3_tx,
            can3_rx,
            pedal1,
            pedal2,
            bse1,
            bse2,
            shock1,
            shock2,
            shock3,
            shock4,
            self.thermistor,
            wheel1,
            wheel2,
            self.ready_to_move,
            self.launch,
            self.brake_light,
            pump1,
            pump2,
            self.fan,
            self.buzzer,
            self.led,
        ]
    }
}

/// The team's comp-car CCM (Anteater-Electric-Racing/embedded-mz at 0c18690, `fsae-ccm/`,
/// April 2026), pedals on the on-chip ADC as the team's code reads them (the divider:
/// `fsae-ccm/src/utils/utils.h:68`, ADC_VOLTAGE_DIVIDER).
pub const COMP_CAR: Revision = Revision {
    name: "ccm comp car (embedded-mz, April 2026), pedals on the on-chip ADC",
    inverter_can: [
        Pin::team(
            1,
            "inverter-can-tx",
            Mode::CanTx(2),
            "embedded-mz@0c18690 fsae-ccm/src/peripherals/can.cpp:21,32-36 (FlexCAN_T4 CAN2, default pins 1/0)",
        ),
        Pin::team(
            0,
            "inverter-can-rx",
            Mode::CanRx(2),
            "embedded-mz@0c18690 fsae-ccm/src/peripherals/can.cpp:21,32-36 (FlexCAN_T4 CAN2, default pins 1/0)",
        ),
    ],
    vehicle_can: [
        Pin::team(
            31,
            "vehicle-can-tx",
            Mode::CanTx(3),
            "embedded-mz@0c18690 fsae-ccm/src/peripherals/can.cpp:22,38-45 (FlexCAN_T4 CAN3, default pins 31/30; ISO-TP written on CAN3)",
        ),
        Pin::team(
            30,
            "vehicle-can-rx",
            Mode::CanRx(3),
            "embedded-mz@0c18690 fsae-ccm/src/peripherals/can.cpp:22,38-45 (FlexCAN_T4 CAN3, default pins 31/30; ISO-TP written on CAN3)",
        ),
    ],
    pedals: Pedals::OnChipAdc {
        apps: [
            Pin::team(
                19,
                "apps1",
                Mode::Analog(5),
                "embedded-mz@0c18690 fsae-ccm/src/peripherals/adc.cpp:21,46 (APPS_1_INDEX 5 = A5)",
            ),
            Pin::team(
                18,
                "apps2",
                Mode::Analog(4),
                "embedded-mz@0c18690 fsae-ccm/src/peripherals/adc.cpp:22,46 (APPS_2_INDEX 4 = A4)",
            ),
        ],
    },
    brakes: [
        Pin::team(
            17,
            "bse1",
            Mode::Analog(3),
            "embedded-mz@0c18690 fsae-ccm/src/peripherals/adc.cpp:23,46 (BSE_1_INDEX 3 = A3; front: assumed, check on the bench)",
        ),
        Pin::team(
            16,
            "bse2",
            Mode::Analog(2),
            "embedded-mz@0c18690 fsae-ccm/src/peripherals/adc.cpp:24,46 (BSE_2_INDEX 2 = A2; rear: assumed, check on the bench)",
        ),
    ],
    shocks: [
        Pin::team(
            20,
            "shock1",
            Mode::Analog(6),
            "embedded-mz@0c18690 fsae-ccm/src/peripherals/adc.cpp:25,46 (SUSP_TRAV_LINPOT1 6 = A6)",
        ),
        Pin::team(
            21,
            "shock2",
            Mode::Analog(7),
            "embedded-mz@0c18690 fsae-ccm/src/peripherals/adc.cpp:26,46 (SUSP_TRAV_LINPOT2 7 = A7)",
        ),
        Pin::team(
            22,
            "shock3",
            Mode::Analog(8),
            "embedded-mz@0c18690 fsae-ccm/src/peripherals/adc.cpp:27,46 (SUSP_TRAV_LINPOT3 8 = A8)",
        ),
        Pin::team(
            23,
            "shock4",
            Mode::Analog(9),
            "embedded-mz@0c18690 fsae-ccm/src/peripherals/adc.cpp:28,46 (SUSP_TRAV_LINPOT4 9 = A9)",
        ),
    ],
    thermistor: Pin::team(
        14,
        "thermistor1",
        Mode::Analog(0),
        "embedded-mz@0c18690 fsae-ccm/src/peripherals/adc.cpp:20,46 (THERMISTOR_1_INDEX 0 = A0; thermistors 2-4, lines 29-31, index past the 10-entry table: not fitted)",
    ),
    wheel_speed: [
        Pin::team(
            2,
            "wheel-speed1",
            Mode::InputPullUp,
            "embedded-mz@0c18690 fsae-ccm/src/utils/utils.h:55, peripherals/gpio.cpp:12 (INPUT_PULLUP; vehicle/controls/bypass.h:3 puts a TSSI bypass here, unused)",
        ),
        Pin::team(
            3,
            "wheel-speed2",
            Mode::InputPullUp,
            "embedded-mz@0c18690 fsae-ccm/src/utils/utils.h:56, peripherals/gpio.cpp:13 (INPUT_PULLUP; vehicle/controls/bypass.h:4 puts TSSI feedback here, unused)",
        ),
    ],
    ready_to_move: Pin::team(
        36,
        "ready-to-move",
        Mode::InputPullDown,
        "embedded-mz@0c18690 fsae-ccm/src/utils/utils.h:57, peripherals/gpio.cpp:14 (INPUT_PULLDOWN), vehicle/devices/rtm.cpp:3 (500 ms debounce)",
    ),
    launch: Pin::assumed(
        33,
        "launch",
        Mode::InputPullDown,
        "assumed: no launch button in the team's code; open = off (pull-down), check on the bench",
    ),
    brake_light: Pin::team(
        9,
        "brake-light",
        Mode::Output,
        "embedded-mz@0c18690 fsae-ccm/src/utils/utils.h:58, peripherals/gpio.cpp:15 (OUTPUT)",
    ),
    pumps: [
        Pin::team(
            29,
            "pump1",
            Mode::Pwm(25_000),
            "embedded-mz@0c18690 fsae-ccm/src/vehicle/devices/thermal.cpp:4,6,8 (25 kHz, 8-bit duty)",
        ),
        Pin::team(
            28,
            "pump2",
            Mode::Pwm(25_000),
            "embedded-mz@0c18690 fsae-ccm/src/vehicle/devices/thermal.cpp:4,6,9 (25 kHz, 8-bit duty)",
        ),
    ],
    fan: Pin::team(
        7,
        "fan",
        Mode::Pwm(500),
        "embedded-mz@0c18690 fsae-ccm/src/vehicle/devices/thermal.cpp:5,10 (500 Hz)",
    ),
    buzzer: Pin::assumed(
        4,
        "rtd-buzzer",
        Mode::Pwm(2_000),
        "assumed: no ready-to-drive buzzer pin in the team's code; check on the bench",
    ),
    led: Pin::teensy(
        13,
        "led",
        Mode::Output,
        "Teensy 4.1 schematic: the on-board LED on pin 13",
    ),
    adc_divider: 1.515_151,
};

/// The same board with the pedals on an ADS1115 (the team's documentation): LPI2C1 on pins
/// 18/19, which then are not APPS inputs.
pub const COMP_CAR_ADS1115: Revision = Revision {
    name: "ccm comp car, pedals on an ADS1115 (the team's documentation)",
    pedals: Pedals::Ads1115 {
        i2c: [
            Pin::assumed(
                18,
                "i2c-sda",
                Mode::I2cSda,
                "assumed: the docs' ADS1115 on LPI2C1 (SDA 18); the team's code has no I2C",
            ),
            Pin::assumed(
                19,
                "i2c-scl",
                Mode::I2cScl,
                "assumed: the docs' ADS1115 on LPI2C1 (SCL 19); the team's code has no I2C",
            ),
        ],
        address: 0x48,
    },
    ..COMP_CAR
};

const _: () = assert!(crate::distinct(&COMP_CAR.pins()));
const _: () = assert!(crate::distinct(&COMP_CAR_ADS1115.pins()));

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn can1_pins_are_analog_inputs_and_the_buses_are_can2_and_can3() {
        let pins = COMP_CAR.pins();
        let mode = |number: u8| {
            pins.iter()
                .find(|pin| pin.number == number)
                .map(|pin| pin.mode)
        };
        assert_eq!(mode(22), Some(Mode::Analog(8)));
        assert_eq!(mode(23), Some(Mode::Analog(9)));
        assert!(
            pins.iter()
                .all(|pin| !matches!(pin.mode, Mode::CanTx(1) | Mode::CanRx(1)))
        );
        assert_eq!(mode(1), Some(Mode::CanTx(2)));
        assert_eq!(mode(31), Some(Mode::CanTx(3)));
        assert_eq!(mode(30), Some(Mode::CanRx(3)));
    }

    #[test]
    fn analog_channel_n_is_teensy_pin_14_plus_n() {
        for revision in [COMP_CAR, COMP_CAR_ADS1115] {
            for pin in revision.pins() {
                if let Mode::Analog(channel) = pin.mode {
                    assert_eq!(pin.number, 14 + channel, "{pin:?}");
                }
            }
        }
    }

    #[test]
    fn the_ads1115_option_changes_only_the_pedal_pins() {
        let (adc, ads) = (COMP_CAR.pins(), COMP_CAR_ADS1115.pins());
        for i in 0..PIN_COUNT {
            assert_eq!(adc[i] != ads[i], i == 4 || i == 5, "{:?}", adc[i]);
        }
    }
}
