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
    /// the HV-switching outputs for [`crate::hv_gate::HV_CONFIRMATION_MS`] while the board's
    /// own readings agree.
    ConfirmHvDisconnected,
    /// `confirm wheels-off-ground` (CCM): the car is on stands with the driven wheels free;
    /// with the PCC ONLINE, arms `dti enable` at high voltage for
    /// [`crate::hv_gate::HV_CONFIRMATION_MS`].
    ConfirmWheelsOffGround,
    /// Every output back to its safe level.
    AllOff,
    /// `can`: the CAN controllers' loopback self-test, then a heartbeat on each bus.
    CanTest,
    /// `cal rest` / `cal full`: record the pedal sensors (and, at rest, the brake sensors'
    /// zero) with the pedal released or fully pressed.
    Calibrate(PedalPosition),
    /// `cal shock <fl|fr|rl|rr|all> extended|compressed`: record one shock sensor (or all
    /// four) at full extension or full compression.
    CalibrateShock {
        /// Which sensor.
        corner: ShockCorner,
        /// Which end of its travel.
        point: ShockPoint,
    },
    /// `cal save`: save the sensors measured this session to the CCM's flash, over what
    /// start-up loads now (every other value kept), as the race image's XCP save does.
    CalSave,
    /// `cal load`: read the flash back as start-up would, and say what it would load.
    CalLoad,
    /// `cal erase`: erase both saved copies, so start-up runs `ccm/calibration.toml` again.
    CalErase,
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
    /// `restart`: start the image again (a software reset: clears what a watchdog restart
    /// latched, as a power cycle does).
    Restart,
    /// `status` (race images): the state, what is latched, and what the image runs with that
    /// the bench day has not settled.
    Status,
    /// `panic test` (CCM bring-up): panic on purpose, so the bench sees what the panic handler
    /// sends the inverter and that the board restarts.
    PanicTest,
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

/// A shock sensor, by the corner the board table maps it to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ShockCorner {
    /// Front left (input 1).
    FrontLeft,
    /// Front right (input 2).
    FrontRight,
    /// Rear left (input 3).
    RearLeft,
    /// Rear right (input 4).
    RearRight,
    /// All four at once.
    All,
}

impl ShockCorner {
    /// The corners one by one, in input order.
    pub const EACH: [Self; 4] = [
        Self::FrontLeft,
        Self::FrontRight,
        Self::RearLeft,
        Self::RearRight,
    ];

    fn parse(word: &str) -> Option<Self> {
        match word {
            "fl" => Some(Self::FrontLeft),
            "fr" => Some(Self::FrontRight),
            "rl" => Some(Self::RearLeft),
            "rr" => Some(Self::RearRight),
            "all" => Some(Self::All),
            _ => None,
        }
    }

    /// The sensors' indices (0-3) this names.
    pub fn indices(self) -> &'static [usize] {
        match self {
            Self::FrontLeft => &[0],
            Self::FrontRight => &[1],
            Self::RearLeft => &[2],
            Self::RearRight => &[3],
            Self::All => &[0, 1, 2, 3],
        }
    }

    /// The short name typed and printed: `fl`, `fr`, `rl`, `rr`, `all`.
    pub const fn name(self) -> &'static str {
        match self {
            Self::FrontLeft => "fl",
            Self::FrontRight => "fr",
            Self::RearLeft => "rl",
            Self::RearRight => "rr",
            Self::All => "all",
        }
    }
}

/// An end of a shock sensor's travel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ShockPoint {
    /// Fully extended (droop): the zero its travel is measured from.
    Extended,
    /// Fully compressed (on the bump stop): the end of its travel.
    Compressed,
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
        let rest: [Option<&str>; 4] = [words.next(), words.next(), words.next(), words.next()];
        let command = match (first, rest) {
            ("help" | "?", [None, ..]) => Self::Help,
            ("report", [None, ..]) => Self::Report,
            ("out", [Some(signal), Some(level), None, _]) => Self::Output {
                signal,
                level: Level::parse(level).ok_or(CommandError::Usage(OUT_USAGE))?,
            },
            ("out", _) => return Err(CommandError::Usage(OUT_USAGE)),
            ("confirm", [Some("hv-disconnected"), None, ..]) => Self::ConfirmHvDisconnected,
            ("confirm", [Some("wheels-off-ground"), None, ..]) => Self::ConfirmWheelsOffGround,
            ("confirm", _) => {
                return Err(CommandError::Usage(
                    "confirm hv-disconnected | confirm wheels-off-ground",
                ));
            }
            ("off", [None, ..]) => Self::AllOff,
            ("can", [None, ..]) => Self::CanTest,
            ("cal", [Some("rest"), None, ..]) => Self::Calibrate(PedalPosition::Rest),
            ("cal", [Some("full"), None, ..]) => Self::Calibrate(PedalPosition::Full),
            ("cal", [Some("shock"), Some(corner), Some(point), None]) => {
                let corner = ShockCorner::parse(corner).ok_or(CommandError::Usage(SHOCK_USAGE))?;
                let point = match point {
                    "extended" => ShockPoint::Extended,
                    "compressed" => ShockPoint::Compressed,
                    _ => return Err(CommandError::Usage(SHOCK_USAGE)),
                };
                Self::CalibrateShock { corner, point }
            }
            ("cal", [Some("shock"), ..]) => return Err(CommandError::Usage(SHOCK_USAGE)),
            ("cal", [Some("save"), None, ..]) => Self::CalSave,
            ("cal", [Some("load"), None, ..]) => Self::CalLoad,
            ("cal", [Some("erase"), None, ..]) => Self::CalErase,
            ("cal", _) => {
                return Err(CommandError::Usage(
                    "cal rest | cal full | cal shock <corner> extended|compressed | cal save | cal load | cal erase",
                ));
            }
            ("i2c", [Some("scan"), None, ..]) => Self::I2cScan,
            ("watchdog", [Some("test"), None, ..]) => Self::WatchdogTest,
            ("dti", [Some("enable"), None, ..]) => Self::DtiEnable,
            ("bootloader", [None, ..]) => Self::Bootloader,
            ("restart", [None, ..]) => Self::Restart,
            ("status", [None, ..]) => Self::Status,
            ("panic", [Some("test"), None, ..]) => Self::PanicTest,
            ("help" | "?" | "report" | "off" | "can" | "bootloader" | "restart" | "status", _) => {
                return Err(CommandError::Usage("no arguments"));
            }
            ("panic", _) => return Err(CommandError::Usage("panic test")),
            ("i2c", _) => return Err(CommandError::Usage("i2c scan")),
            ("watchdog", _) => return Err(CommandError::Usage("watchdog test")),
            ("dti", _) => return Err(CommandError::Usage("dti enable")),
            (other, _) => return Err(CommandError::Unknown(other)),
        };
        Ok(command)
    }
}

const OUT_USAGE: &str = "out <signal> on|off|<0-100>";
const SHOCK_USAGE: &str = "cal shock fl|fr|rl|rr|all extended|compressed";

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
pub const HELP: [&str; 19] = [
    "help                       this list",
    "report                     print every input, bus and counter now",
    "out <signal> on|off|<pct>  drive one output (names as in `cargo xtask pins`)",
    "confirm hv-disconnected    HV off and discharged (the board's live readings must agree): arms HV outputs for 30 s",
    "confirm wheels-off-ground  car on stands, driven wheels free (CCM): with the PCC ONLINE, arms `dti enable` at HV for 30 s",
    "off                        every output back to its safe level, confirmations revoked",
    "can                        loopback self-test of each controller, then heartbeats",
    "cal rest | cal full        record the pedal and brake sensors, released / pedal pressed (CCM)",
    "cal shock <c> extended     record a shock sensor fully extended; <c> = fl fr rl rr all (CCM)",
    "cal shock <c> compressed   record a shock sensor fully compressed (CCM)",
    "cal save | cal load        save what was measured to flash (tuned values kept) / what start-up loads (CCM)",
    "cal erase                  erase the saved copies: start-up runs ccm/calibration.toml (CCM)",
    "i2c scan                   addresses that answer (ADS1115 board)",
    "dti enable                 1 s of drive enable at 0 A, then silence: times the DTI's timeout (CCM)",
    "watchdog test              stop feeding the watchdog: the chip resets within 1 s",
    "panic test                 panic on purpose: the inverter's stop frames on CAN2, then a restart (CCM)",
    "bootloader                 reboot into the Teensy bootloader",
    "restart                    start the image again (clears a watchdog restart's latch)",
    "(the race images accept only `status`, and `bootloader` and `restart` in a safe state; 134 baud asks for the bootloader)",
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
            Err(CommandError::Usage(
                "confirm hv-disconnected | confirm wheels-off-ground"
            ))
        );
        assert_eq!(
            Command::parse("confirm wheels-off-ground"),
            Ok(Command::ConfirmWheelsOffGround)
        );
        assert_eq!(Command::parse("restart"), Ok(Command::Restart));
        assert_eq!(Command::parse("status"), Ok(Command::Status));
        assert_eq!(Command::parse("panic test"), Ok(Command::PanicTest));
        assert_eq!(
            Command::parse("panic"),
            Err(CommandError::Usage("panic test"))
        );
        assert_eq!(Command::parse("cal erase"), Ok(Command::CalErase));
        assert_eq!(
            Command::parse("cal shock rr compressed"),
            Ok(Command::CalibrateShock {
                corner: ShockCorner::RearRight,
                point: ShockPoint::Compressed
            })
        );
        assert_eq!(
            Command::parse("cal shock all extended"),
            Ok(Command::CalibrateShock {
                corner: ShockCorner::All,
                point: ShockPoint::Extended
            })
        );
        for bad in [
            "cal shock",
            "cal shock fl",
            "cal shock xx extended",
            "cal shock fl halfway",
            "cal shock fl extended now",
        ] {
            assert_eq!(
                Command::parse(bad),
                Err(CommandError::Usage(SHOCK_USAGE)),
                "{bad}"
            );
        }
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
