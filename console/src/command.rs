//! What a team member can type on the console. Every command that moves an output is
//! explicit and typed in full; the PCC's AIR+ output also needs a confirmation that the high
//! voltage is disconnected, typed just before.

/// A parsed command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Command<'a> {
    /// List the commands.
    Help,
    /// Print one full report now (inputs, buses, counters).
    Report,
    /// Set an output: `out <signal> on|off|<0-100>` (percent for PWM outputs).
    Output {
        /// The signal's name, as `cargo xtask pins` prints it.
        signal: &'a str,
        /// What to drive.
        level: Level,
    },
    /// `confirm hv-disconnected`: the tractive system is disconnected and discharged; arms
    /// the HV-switching outputs for [`crate::bringup::HV_CONFIRMATION_MS`].
    ConfirmHvDisconnected,
    /// Every output back to its safe level.
    AllOff,
    /// `can`: the CAN controllers' loopback self-test, then a heartbeat on each bus.
    CanTest,
    /// `cal rest` / `cal full`: record the pedal sensors (and, at rest, the brake sensors'
    /// zero) with the pedal released or fully pressed.
    Calibrate(PedalPosition),
    /// `cal save`: save the calibration the bench measured (the schema's defaults with the
    /// recorded sensors) to the CCM's flash, as the race image's XCP save does.
    CalSave,
    /// `cal load`: read the flash back as start-up would, and say what it would load.
    CalLoad,
    /// `i2c scan`: every 7-bit address that acknowledges (ADS1115 boards).
    I2cScan,
    /// `watchdog test`: stop feeding the watchdog; the next start reports the reset cause.
    WatchdogTest,
    /// `dti enable` (CCM): one second of zero current with drive enable to the DTI, then
    /// silence, to time its command timeout; needs the HV confirmation and the DTI's own DC
    /// link reading below 60 V.
    DtiEnable,
    /// `bootloader`: reboot into the Teensy's bootloader (as `teensy_loader_cli -s` does).
    Bootloader,
}

/// An output level.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Level {
    /// Low / 0 %.
    Off,
    /// High / 100 %.
    On,
    /// PWM duty in percent (0-100).
    Percent(u8),
}

/// A pedal calibration point.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PedalPosition {
    /// Pedal released.
    Rest,
    /// Pedal fully pressed.
    Full,
}

/// Why a line is not a command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CommandError<'a> {
    /// The first word is not a command.
    Unknown(&'a str),
    /// The command needs other arguments; the text says which.
    Usage(&'static str),
}

impl<'a> Command<'a> {
    /// Parses one typed line.
    pub fn parse(line: &'a str) -> Result<Self, CommandError<'a>> {
        let mut words = line.split_ascii_whitespace();
        let first = words.next().unwrap_or("");
        let rest: [Option<&str>; 3] = [words.next(), words.next(), words.next()];
        let command = match (first, rest) {
            ("help" | "?", [None, ..]) => Self::Help,
            ("report", [None, ..]) => Self::Report,
            ("out", [Some(signal), Some(level), None]) => Self::Output {
                signal,
                level: Level::parse(level).ok_or(CommandError::Usage(OUT_USAGE))?,
            },
            ("out", _) => return Err(CommandError::Usage(OUT_USAGE)),
            ("confirm", [Some("hv-disconnected"), None, _]) => Self::ConfirmHvDisconnected,
            ("confirm", _) => return Err(CommandError::Usage("confirm hv-disconnected")),
            ("off", [None, ..]) => Self::AllOff,
            ("can", [None, ..]) => Self::CanTest,
            ("cal", [Some("rest"), None, _]) => Self::Calibrate(PedalPosition::Rest),
            ("cal", [Some("full"), None, _]) => Self::Calibrate(PedalPosition::Full),
            ("cal", [Some("save"), None, _]) => Self::CalSave,
            ("cal", [Some("load"), None, _]) => Self::CalLoad,
            ("cal", _) => {
                return Err(CommandError::Usage(
                    "cal rest | cal full | cal save | cal load",
                ));
            }
            ("i2c", [Some("scan"), None, _]) => Self::I2cScan,
            ("watchdog", [Some("test"), None, _]) => Self::WatchdogTest,
            ("dti", [Some("enable"), None, _]) => Self::DtiEnable,
            ("bootloader", [None, ..]) => Self::Bootloader,
            ("help" | "?" | "report" | "off" | "can" | "bootloader", _) => {
                return Err(CommandError::Usage("no arguments"));
            }
            ("i2c", _) => return Err(CommandError::Usage("i2c scan")),
            ("watchdog", _) => return Err(CommandError::Usage("watchdog test")),
            ("dti", _) => return Err(CommandError::Usage("dti enable")),
            (other, _) => return Err(CommandError::Unknown(other)),
        };
        Ok(command)
    }
}

const OUT_USAGE: &str = "out <signal> on|off|<0-100>";

impl Level {
    fn parse(word: &str) -> Option<Self> {
        match word {
            "on" => Some(Self::On),
            "off" => Some(Self::Off),
            number => number
                .parse::<u8>()
                .ok()
                .filter(|percent| *percent <= 100)
                .map(Self::Percent),
        }
    }

    /// The level as a duty cycle (0..1).
    pub fn duty(self) -> f32 {
        match self {
            Self::Off => 0.0,
            Self::On => 1.0,
            Self::Percent(percent) => f32::from(percent) / 100.0,
        }
    }

    /// The level as a digital output: anything above 0 % is high.
    pub fn high(self) -> bool {
        match self {
            Self::Off | Self::Percent(0) => false,
            Self::On | Self::Percent(_) => true,
        }
    }
}

/// The help text, one command per line.
pub const HELP: [&str; 13] = [
    "help                       this list",
    "report                     print every input, bus and counter now",
    "out <signal> on|off|<pct>  drive one output (names as in `cargo xtask pins`)",
    "confirm hv-disconnected    HV off and discharged (the board's readings must agree): arms HV outputs for 30 s",
    "off                        every output back to its safe level",
    "can                        loopback self-test of each controller, then heartbeats",
    "cal rest | cal full        record the pedal and brake sensors (CCM)",
    "cal save | cal load        save the bench calibration to flash, read back what start-up loads (CCM)",
    "i2c scan                   addresses that answer (ADS1115 board)",
    "dti enable                 1 s of drive enable at 0 A, then silence: times the DTI's timeout (CCM)",
    "watchdog test              stop feeding the watchdog: the chip resets within 1 s",
    "bootloader                 reboot into the Teensy bootloader",
    "(the race images accept only `bootloader`, and only in a safe state; 134 baud asks the same)",
];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outputs_need_a_signal_and_a_level_in_range() {
        assert_eq!(
            Command::parse("out pump1 40"),
            Ok(Command::Output {
                signal: "pump1",
                level: Level::Percent(40)
            })
        );
        assert_eq!(
            Command::parse("out  brake-light   on"),
            Ok(Command::Output {
                signal: "brake-light",
                level: Level::On
            })
        );
        for bad in [
            "out",
            "out pump1",
            "out pump1 101",
            "out pump1 -1",
            "out a b c",
        ] {
            assert_eq!(
                Command::parse(bad),
                Err(CommandError::Usage(OUT_USAGE)),
                "{bad}"
            );
        }
    }

    #[test]
    fn every_command_parses_and_extra_words_are_refused() {
        assert_eq!(Command::parse("help"), Ok(Command::Help));
        assert_eq!(
            Command::parse("confirm hv-disconnected"),
            Ok(Command::ConfirmHvDisconnected)
        );
        assert_eq!(
            Command::parse("cal full"),
            Ok(Command::Calibrate(PedalPosition::Full))
        );
        assert_eq!(Command::parse("watchdog test"), Ok(Command::WatchdogTest));
        assert_eq!(Command::parse("dti enable"), Ok(Command::DtiEnable));
        assert_eq!(
            Command::parse("dti"),
            Err(CommandError::Usage("dti enable"))
        );
        assert_eq!(Command::parse("i2c scan"), Ok(Command::I2cScan));
        assert_eq!(
            Command::parse("bootloader now"),
            Err(CommandError::Usage("no arguments"))
        );
        assert_eq!(
            Command::parse("confirm hv"),
            Err(CommandError::Usage("confirm hv-disconnected"))
        );
        assert_eq!(
            Command::parse("relay on"),
            Err(CommandError::Unknown("relay"))
        );
    }

    #[test]
    fn levels_map_to_duty_and_digital_levels() {
        assert_eq!(Level::Percent(25).duty(), 0.25);
        assert!(!Level::Percent(0).high());
        assert!(Level::Percent(1).high());
        assert!(Level::On.high() && !Level::Off.high());
    }
}
