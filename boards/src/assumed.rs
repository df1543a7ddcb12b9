//! What the images run with that no one has yet checked on the team's hardware, and the bench
//! day's step that settles each: the one list that docs/bench-day.md's table ("Still assumed,
//! and the step that settles it"), its printable sheet and the race images' start-up and
//! `status` lines are made from.
//!
//! When a step settles an item, delete its entry here (and change the source text where it
//! lives, so the bring-up prints it as fact): the next `cargo xtask docs` drops it from the
//! page and the sheet, and the next build from the images.

/// Which images print an item: the board whose behaviour rests on it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Board {
    /// The CCM (and the inverter it drives).
    Ccm,
    /// The PCC.
    Pcc,
    /// Both.
    Both,
}

/// One assumption.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Assumed {
    /// What is assumed, in a few words.
    pub what: &'static str,
    /// The value or behaviour assumed (empty when `what` says it all).
    pub assumed: &'static str,
    /// Where it lives (a file, a tool).
    pub lives: &'static str,
    /// The bench day's step that settles it.
    pub settled: &'static str,
    /// The board whose images print it.
    pub board: Board,
}

impl Assumed {
    /// Every item `board`'s images print.
    pub fn for_board(board: Board) -> impl Iterator<Item = &'static Self> {
        ASSUMED
            .iter()
            .filter(move |item| item.board == board || item.board == Board::Both)
    }
}

/// Everything still assumed, in the page's order.
pub const ASSUMED: [Assumed; 26] = [
    Assumed {
        what: "which board an image runs on",
        assumed: "the boot ROM's FlexSPI read, and a 2 MiB flash repeating its boot block and IVT 2 MiB on",
        lives: "`console/src/chip.rs`, `console/src/board_check.rs`",
        settled: "step 1 (the start-up line `board: ... checked`; 1.2, an image on the other board)",
        board: Board::Both,
    },
    Assumed {
        what: "CCM pin 33: launch button, open = off",
        assumed: "input with pull-down",
        lives: "`boards/src/ccm.rs`",
        settled: "step 3",
        board: Board::Ccm,
    },
    Assumed {
        what: "CCM pin 4: ready-to-drive buzzer",
        assumed: "PWM output",
        lives: "`boards/src/ccm.rs`",
        settled: "step 3",
        board: Board::Ccm,
    },
    Assumed {
        what: "BSE1 = front, BSE2 = rear",
        assumed: "",
        lives: "`boards/src/ccm.rs`",
        settled: "step 3",
        board: Board::Ccm,
    },
    Assumed {
        what: "shock1-4 = front left, front right, rear left, rear right",
        assumed: "the team's LINPOT1-4 in that order",
        lives: "`boards/src/ccm.rs`",
        settled: "step 3",
        board: Board::Ccm,
    },
    Assumed {
        what: "the 1.515 divider in front of every CCM analog input",
        assumed: "the team's `ADC_VOLTAGE_DIVIDER`",
        lives: "`adc_divider`, `boards/src/ccm.rs`",
        settled: "step 3 (a meter on a sensor)",
        board: Board::Ccm,
    },
    Assumed {
        what: "which pedal front-end a board has (on-chip ADC or ADS1115)",
        assumed: "the comp car's code: on-chip",
        lives: "the image you flash",
        settled: "step 0 (look at the board), step 3",
        board: Board::Ccm,
    },
    Assumed {
        what: "ADS1115 board: I2C on pins 18/19, address 0x48",
        assumed: "",
        lives: "`boards/src/ccm.rs`, `ccm/src/ads1115.rs`",
        settled: "step 3",
        board: Board::Ccm,
    },
    Assumed {
        what: "wheel-speed encoder teeth",
        assumed: "24",
        lives: "`WHEEL_TEETH`, `ccm/src/constants.rs`",
        settled: "step 3",
        board: Board::Ccm,
    },
    Assumed {
        what: "pedal, brake and shock calibration",
        assumed: "placeholders (shocks: 5.00 V extended, 4.86 V compressed)",
        lives: "`ccm/calibration.toml`, the saved copy",
        settled: "step 5",
        board: Board::Ccm,
    },
    Assumed {
        what: "a released brake reads 0.50-0.70 V",
        assumed: "the sensors' nominal 0.5 V, plus 100 psi",
        lives: "`BSE_ZERO_V`, `ccm/src/constants.rs`",
        settled: "step 5 (the released reading)",
        board: Board::Ccm,
    },
    Assumed {
        what: "brake sensors: 2,000 psi at 4.5 V; brakes engaged above 30 psi",
        assumed: "",
        lives: "`ccm/src/constants.rs`",
        settled: "step 5, with the team's brake test",
        board: Board::Ccm,
    },
    Assumed {
        what: "PCC V/F scaling (0.001275 V/Hz, 66.4 : 1 divider)",
        assumed: "from the parts list",
        lives: "`pcc/src/constants.rs`",
        settled: "step 6b",
        board: Board::Pcc,
    },
    Assumed {
        what: "PCC precharge-resistor thermistors: 10 kOhm NTC (beta 3880) under a 6.8 kOhm divider, limit 69 degC",
        assumed: "the team's `precharge.cpp`",
        lives: "`THERMISTORS`, `pcc/src/constants.rs`",
        settled: "step 6a (the report's room temperature)",
        board: Board::Pcc,
    },
    Assumed {
        what: "PCC pin 11 driver stage holds AIR+ open from pin 11 high, unpowered and in the bootloader",
        assumed: "its own pull-down",
        lives: "the PCC board",
        settled: "step 6c",
        board: Board::Pcc,
    },
    Assumed {
        what: "the V/F test points for the signal generator",
        assumed: "at the board's converter outputs",
        lives: "the PCC board",
        settled: "step 6d",
        board: Board::Pcc,
    },
    Assumed {
        what: "precharge window 8.2-9.2 s at 90 %",
        assumed: "the team's design",
        lives: "`pcc/src/constants.rs`",
        settled: "step 8.1",
        board: Board::Pcc,
    },
    Assumed {
        what: "the bootloader is entered with the watchdog running (`bootloader` hands the chip over with WDOG1 on)",
        assumed: "PJRC's own soft reboot does",
        lives: "`console/src/usb.rs`",
        settled: "step 1 (every later flash)",
        board: Board::Pcc,
    },
    Assumed {
        what: "DTI command timeout",
        assumed: "100 ms",
        lives: "the DTI tool; `DTI_ASSUMED_COMMAND_TIMEOUT_MS`",
        settled: "step 7 or 8.3 (`dti enable`: PASS)",
        board: Board::Ccm,
    },
    Assumed {
        what: "a CCM panic disables the DTI itself (drive disable and 0 A on CAN2, register-level)",
        assumed: "the FlexCAN mailbox the panic handler writes",
        lives: "`ccm/src/hw/panic.rs`, `flexcan/src/emergency.rs`",
        settled: "step 7 (`panic test`)",
        board: Board::Ccm,
    },
    Assumed {
        what: "DTI node id 0x41, CAN map 2.5 (the report prints 25), status periods 10/100 ms",
        assumed: "",
        lives: "`schema/aer.dbc`",
        settled: "step 4",
        board: Board::Ccm,
    },
    Assumed {
        what: "motor pole pairs 10, torque constant 0.75 Nm/A",
        assumed: "an EMRAX 228 HV",
        lives: "`params/src/lib.rs`",
        settled: "step 8.4 (pole pairs); the torque constant on a dyno",
        board: Board::Ccm,
    },
    Assumed {
        what: "the calibration's flash slots at 0x1FE000 / 0x1FF000 and the boot ROM's FlexSPI NOR driver (erase, program)",
        assumed: "never run on hardware",
        lives: "`ccm/src/hw/flash.rs`",
        settled: "step 5b",
        board: Board::Ccm,
    },
    Assumed {
        what: "a reflash keeps the saved calibration",
        assumed: "unknown",
        lives: "the Teensy loader",
        settled: "step 5b",
        board: Board::Ccm,
    },
    Assumed {
        what: "USB serial on the Teensy, FlexCAN3 classic mode",
        assumed: "never run on hardware",
        lives: "`console/`, `flexcan/`",
        settled: "steps 1 and 4",
        board: Board::Both,
    },
    Assumed {
        what: "XCP on CAN2 (0x6F0 / 0x6F1, the inverter bus) with a real master",
        assumed: "host and car model only",
        lives: "`ccm/src/bin/ccm/xcp.rs`",
        settled: "step 4 (a CANape or pyxcp session on the inverter bus)",
        board: Board::Ccm,
    },
];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_item_names_where_it_lives_and_the_step_that_settles_it() {
        for item in &ASSUMED {
            assert!(!item.what.is_empty() && !item.lives.is_empty(), "{item:?}");
            assert!(item.settled.starts_with("step"), "{item:?}");
        }
        assert!(Assumed::for_board(Board::Ccm).count() > 0);
        assert!(Assumed::for_board(Board::Pcc).count() > 0);
    }
}
