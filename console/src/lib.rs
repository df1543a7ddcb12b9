//! The USB serial console both firmwares talk on.
//!
//! Portable, `no_std` and host-tested: the bounded log ([`log`]), typed commands
//! ([`command`]) and the bring-up images' checks ([`bringup`]). Behind the `firmware` feature,
//! `usb` is the Teensy's USB CDC device that carries them, with the reboot into the
//! bootloader that `teensy_loader_cli -s` asks for.
#![no_std]

pub mod bringup;
pub mod command;
pub mod log;
#[cfg(feature = "firmware")]
pub mod usb;

pub use command::{Command, CommandError, Level, PedalPosition};

/// A value the race firmware logs when it changes (a state, a fault map, a bus's health).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Watch<T> {
    last: Option<T>,
}

impl<T: PartialEq + Copy> Watch<T> {
    /// Nothing seen yet.
    pub const fn new() -> Self {
        Self { last: None }
    }

    /// Records `value`; returns it when it differs from the last one (and the first time).
    pub fn changed(&mut self, value: T) -> Option<T> {
        if self.last == Some(value) {
            return None;
        }
        self.last = Some(value);
        Some(value)
    }
}
pub use log::{LineReader, LogBuffer};

/// The line rate a host sets to ask a Teensy to reboot into its bootloader (what
/// `teensy_loader_cli -s` sends, as PJRC's own USB serial does).
pub const REBOOT_BAUD: u32 = 134;

#[cfg(test)]
mod tests {
    use super::Watch;

    #[test]
    fn a_watch_reports_the_first_value_and_every_change_once() {
        let mut watch = Watch::new();
        assert_eq!(watch.changed(1), Some(1));
        assert_eq!(watch.changed(1), None);
        assert_eq!(watch.changed(2), Some(2));
        assert_eq!(watch.changed(2), None);
    }
}
