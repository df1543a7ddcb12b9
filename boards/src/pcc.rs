//! The precharge controller (Teensy 4.0) on the comp car.
//!
//! One relay output: pin 11 closes AIR+. AIR- and the precharge relay are switched by the
//! shutdown circuit on the board, not by the Teensy; the board has no input that reads the
//! shutdown circuit. (An earlier version of this firmware drove AIR+/AIR-/precharge drivers on
//! pins 2/3/4 and read a Shutdown_in on pin 12: none of them exist on the team's board.)

use crate::{Mode, Pin};

/// One revision of the PCC board.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Revision {
    /// The revision's name, as the bring-up image prints it.
    pub name: &'static str,
    /// CAN2 transmit and receive (BMS, charger, CCM, Pi; status 0x222).
    pub can: [Pin; 2],
    /// The one relay output: high closes AIR+ (bypassing the precharge resistor).
    pub air_plus: Pin,
    /// V/F converter outputs: accumulator, then tractive system (rising edges counted).
    pub voltage_freq: [Pin; 2],
    /// Precharge-resistor thermistors (read by the bring-up image only).
    pub thermistors: [Pin; 2],
    /// The Teensy's on-board LED.
    pub led: Pin,
}

impl Revision {
    /// Every pin, in the order `cargo xtask pins` prints them.
    pub const fn pins(&self) -> [Pin; 8] {
        let [can_tx, can_rx] = self.can;
        let [accumulator, tractive] = self.voltage_freq;
        let [thermistor1, thermistor2] = self.thermistors;
        [
            can_tx,
            can_rx,
            self.air_plus,
            accumulator,
            tractive,
            thermistor1,
            thermistor2,
            self.led,
        ]
    }
}

/// The team's comp-car PCC (Anteater-Electric-Racing/embedded-mz at 0c18690, `fsae-pcc/`,
/// April 2026).
pub const COMP_CAR: Revision = Revision {
    name: "pcc comp car (embedded-mz, April 2026)",
    can: [
        Pin::team(
            1,
            "vehicle-can-tx",
            Mode::CanTx(2),
            "embedded-mz@0c18690 fsae-pcc/src/can.cpp:46,53-56 (FlexCAN_T4 CAN2, default pins 1/0, 500 kbit/s)",
        ),
        Pin::team(
            0,
            "vehicle-can-rx",
            Mode::CanRx(2),
            "embedded-mz@0c18690 fsae-pcc/src/can.cpp:46,53-56 (FlexCAN_T4 CAN2, default pins 1/0, 500 kbit/s)",
        ),
    ],
    air_plus: Pin::team(
        11,
        "air-plus-close",
        Mode::OutputPullDown,
        "embedded-mz@0c18690 fsae-pcc/src/utils.h:12 (SHUTDOWN_CTRL_PIN 11), precharge.cpp:205,298,309,329 (LOW in STANDBY, HIGH \
         in ONLINE and CHARGING: \"Close AIR+\", LOW in ERROR); gpio.cpp:8 leaves it an INPUT, so the team switches \
         the pad's pull: check the driver stage on the bench",
    ),
    voltage_freq: [
        Pin::team(
            14,
            "accumulator-vf",
            Mode::InputPullDown,
            "embedded-mz@0c18690 fsae-pcc/src/utils.h:15, gpio.cpp:9 (INPUT_PULLDOWN)",
        ),
        Pin::team(
            15,
            "tractive-vf",
            Mode::InputPullDown,
            "embedded-mz@0c18690 fsae-pcc/src/utils.h:16, gpio.cpp:10 (INPUT_PULLDOWN)",
        ),
    ],
    thermistors: [
        Pin::team(
            21,
            "thermistor-1",
            Mode::Analog(7),
            "embedded-mz@0c18690 fsae-pcc/src/precharge.cpp:19,416 (analogRead(7) = A7 = pin 21)",
        ),
        Pin::team(
            22,
            "thermistor-2",
            Mode::Analog(8),
            "embedded-mz@0c18690 fsae-pcc/src/precharge.cpp:20,417 (analogRead(8) = A8 = pin 22)",
        ),
    ],
    led: Pin::teensy(
        13,
        "led",
        Mode::Output,
        "Teensy 4.0 schematic: the on-board LED on pin 13",
    ),
};

const _: () = assert!(crate::distinct(&COMP_CAR.pins()));

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pin_11_is_the_only_output_that_switches_hv() {
        let outputs: [u8; 2] = [COMP_CAR.air_plus.number, COMP_CAR.led.number];
        assert_eq!(outputs, [11, 13]);
        for pin in COMP_CAR.pins() {
            if matches!(pin.mode, Mode::Output | Mode::OutputPullDown) {
                assert!(outputs.contains(&pin.number), "{pin:?}");
            }
        }
        assert_eq!(COMP_CAR.air_plus.mode, Mode::OutputPullDown);
    }

    #[test]
    fn none_of_the_removed_relay_pins_is_used() {
        for pin in COMP_CAR.pins() {
            assert!(![2, 3, 4, 12].contains(&pin.number), "{pin:?}");
        }
    }
}
