//! The team's boards, described once: every pin the CCM (Teensy 4.1) and the PCC (Teensy 4.0)
//! use, what it carries, how its pad is set up, and where that fact comes from.
//!
//! The firmware takes its pins from here (each typed pin in a firmware's `hw/board.rs` is checked
//! against this description when it compiles), `cargo xtask pins` prints it, and the bring-up
//! images name what they measure with it. `no_std`, no dependencies: the firmware, the host
//! tools and the documentation read the same tables.
//!
//! A board revision is a small table of its own ([`ccm::Revision`], [`pcc::Revision`]), not
//! edits across the firmware.
#![no_std]

pub mod assumed;
pub mod ccm;
pub mod pcc;

/// How a pad is used.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// A CAN controller's transmit line (FlexCAN instance).
    CanTx(u8),
    /// A CAN controller's receive line (FlexCAN instance).
    CanRx(u8),
    /// Digital input with the pad's 22 kOhm pull-up (an open line reads high).
    InputPullUp,
    /// Digital input with the pad's 100 kOhm pull-down (an open line reads low).
    InputPullDown,
    /// Push-pull output, low from reset.
    Output,
    /// Push-pull output with the pad's 100 kOhm pull-down set before it is driven low (the
    /// PCC's relay output). Before the firmware's init (in reset, in the bootloader, the first
    /// milliseconds after reset) the pad is an input with only its weak keeper: the board's
    /// driver stage must hold its load off by itself then.
    OutputPullDown,
    /// FlexPWM output at the given frequency (Hz).
    Pwm(u32),
    /// On-chip ADC input (`A<n>` on the Teensy's silk screen).
    Analog(u8),
    /// I2C data line.
    I2cSda,
    /// I2C clock line.
    I2cScl,
}

impl Mode {
    /// The short name `cargo xtask pins` prints: `can2-tx`, `input-pullup`, `pwm`, ...
    pub const fn label(self) -> &'static str {
        match self {
            Self::CanTx(1) => "can1-tx",
            Self::CanRx(1) => "can1-rx",
            Self::CanTx(2) => "can2-tx",
            Self::CanRx(2) => "can2-rx",
            Self::CanTx(_) => "can3-tx",
            Self::CanRx(_) => "can3-rx",
            Self::InputPullUp => "input-pullup",
            Self::InputPullDown => "input-pulldown",
            Self::Output => "output",
            Self::OutputPullDown => "output-pulldown",
            Self::Pwm(_) => "pwm",
            Self::Analog(_) => "analog",
            Self::I2cSda => "i2c-sda",
            Self::I2cScl => "i2c-scl",
        }
    }
}

/// Where a pin assignment comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Source {
    /// The team's firmware: repository, file and line.
    Team(&'static str),
    /// The Teensy itself (its schematic: the on-board LED, the CAN controllers' fixed pads).
    Teensy(&'static str),
    /// Not found in the team's code or documentation: this firmware's choice, to be checked
    /// on the bench with the bring-up image before the car runs.
    Assumed(&'static str),
}

impl Source {
    /// True when the assignment still has to be checked on the bench.
    pub const fn is_assumed(self) -> bool {
        matches!(self, Self::Assumed(_))
    }

    /// The source as one line of text.
    pub const fn text(self) -> &'static str {
        match self {
            Self::Team(text) | Self::Teensy(text) | Self::Assumed(text) => text,
        }
    }
}

/// One pin of a board.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Pin {
    /// The Teensy pin number (the silk screen's, not the pad's name).
    pub number: u8,
    /// What the pin carries, as the firmware and the bring-up image name it.
    pub signal: &'static str,
    /// How the pad is set up.
    pub mode: Mode,
    /// Where the assignment comes from.
    pub source: Source,
}

impl Pin {
    /// A pin whose assignment is read from the team's firmware.
    pub const fn team(number: u8, signal: &'static str, mode: Mode, at: &'static str) -> Self {
        Self {
            number,
            signal,
            mode,
            source: Source::Team(at),
        }
    }

    /// A pin fixed by the Teensy itself.
    pub const fn teensy(number: u8, signal: &'static str, mode: Mode, at: &'static str) -> Self {
        Self {
            number,
            signal,
            mode,
            source: Source::Teensy(at),
        }
    }

    /// A pin this firmware chose: check it on the bench.
    pub const fn assumed(number: u8, signal: &'static str, mode: Mode, why: &'static str) -> Self {
        Self {
            number,
            signal,
            mode,
            source: Source::Assumed(why),
        }
    }
}

/// True when `a` and `b` are the same mode, parameters included (usable in constants, where
/// `==` is not).
pub const fn same_mode(a: Mode, b: Mode) -> bool {
    match (a, b) {
        (Mode::CanTx(a), Mode::CanTx(b))
        | (Mode::CanRx(a), Mode::CanRx(b))
        | (Mode::Analog(a), Mode::Analog(b)) => a == b,
        (Mode::Pwm(a), Mode::Pwm(b)) => a == b,
        (Mode::InputPullUp, Mode::InputPullUp)
        | (Mode::InputPullDown, Mode::InputPullDown)
        | (Mode::Output, Mode::Output)
        | (Mode::OutputPullDown, Mode::OutputPullDown)
        | (Mode::I2cSda, Mode::I2cSda)
        | (Mode::I2cScl, Mode::I2cScl) => true,
        _ => false,
    }
}

/// Fails the build (used in a constant) when a firmware's typed pin `number` in `mode` is not
/// what the board description says for `pin`.
pub const fn check(pin: Pin, number: u8, mode: Mode) {
    assert!(
        pin.number == number,
        "board.rs and aer-boards disagree on a pin number"
    );
    assert!(
        same_mode(pin.mode, mode),
        "board.rs and aer-boards disagree on a pin's mode"
    );
}

/// True when no pin number appears twice in `pins`.
pub const fn distinct(pins: &[Pin]) -> bool {
    let mut i = 0;
    while i < pins.len() {
        let mut j = i + 1;
        while j < pins.len() {
            if pins[i].number == pins[j].number {
                return false;
            }
            j += 1;
        }
        i += 1;
    }
    true
}
