//! The USB serial console both firmwares talk on.
//!
//! Portable, `no_std` and host-tested: the bounded log ([`log`]), typed commands
//! ([`command`]), the bring-up images' report lines ([`bringup`]) and the gate in front of
//! what matters at high voltage ([`hv_gate`]), and which Teensy an image runs on
//! ([`board_check`]). Behind the `firmware` feature, `usb` is the Teensy's USB CDC device that
//! carries them, with the reboot into the bootloader that `teensy_loader_cli -s` asks for,
//! and `chip` the boot ROM's flash driver that reads and writes the Teensy's flash.
#![no_std]

pub mod bench;
pub mod board_check;
pub mod bringup;
#[cfg(feature = "firmware")]
pub mod chip;
pub mod command;
pub mod hv_gate;
pub mod log;
#[cfg(feature = "firmware")]
pub mod usb;

pub use command::{Command, CommandError, Level, PedalPosition, ShockCorner, ShockPoint};

/// A value the race firmware logs when it changes (a state, a fault map, a bus's health).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Watch<T> {
    last: Option<T>,
}

/// Nothing seen yet, whatever `T` is.
impl<T> Default for Watch<T> {
    fn default() -> Self {
        Self { last: None }
    }
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

/// `id` as 16 upper-case hex digits in `text` (a USB serial number).
pub fn serial_number(id: u64, text: &mut [u8; 16]) -> &str {
    const DIGITS: &[u8; 16] = b"0123456789ABCDEF";
    for (index, slot) in text.iter_mut().enumerate() {
        let shift = 60 - 4 * index;
        *slot = DIGITS
            .get(((id >> shift) & 0xF) as usize)
            .copied()
            .unwrap_or(b'0');
    }
    core::str::from_utf8(text).unwrap_or("0000000000000000")
}

/// What a person asked the image to do with the chip.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reboot {
    /// Hand the chip to the Teensy's bootloader, to be flashed (`bootloader`, or 134 baud
    /// from the host as `teensy_loader_cli -s` sets it).
    Bootloader,
    /// Start the image again from reset (`restart`): a software reset, which clears what a
    /// watchdog restart latched, as a power cycle does (even with the Teensy fed by USB).
    Restart,
}

/// A [`Reboot`] request from the console or the USB host, handed from the USB interrupt to
/// the task that knows whether it is safe to obey.
#[derive(Debug, Default)]
pub struct RebootRequest(core::sync::atomic::AtomicU8);

impl RebootRequest {
    /// No request.
    pub const fn new() -> Self {
        Self(core::sync::atomic::AtomicU8::new(0))
    }

    /// Asks for `reboot` (a later request replaces an earlier one not yet taken).
    pub fn request(&self, reboot: Reboot) {
        let code = match reboot {
            Reboot::Bootloader => 1,
            Reboot::Restart => 2,
        };
        self.0.store(code, core::sync::atomic::Ordering::Relaxed);
    }

    /// Takes the request: `Some` once per request.
    pub fn take(&self) -> Option<Reboot> {
        match self.0.swap(0, core::sync::atomic::Ordering::Relaxed) {
            1 => Some(Reboot::Bootloader),
            2 => Some(Reboot::Restart),
            _ => None,
        }
    }
}

/// A `status` request from the race console, handed from the USB interrupt to the task that
/// prints the state.
#[derive(Debug, Default)]
pub struct StatusRequest(core::sync::atomic::AtomicBool);

impl StatusRequest {
    /// No request.
    pub const fn new() -> Self {
        Self(core::sync::atomic::AtomicBool::new(false))
    }

    /// Asks for the status lines.
    pub fn request(&self) {
        self.0.store(true, core::sync::atomic::Ordering::Relaxed);
    }

    /// Takes the request: true once per request.
    pub fn take(&self) -> bool {
        self.0.swap(false, core::sync::atomic::Ordering::Relaxed)
    }
}

#[cfg(test)]
mod tests {
    use super::Watch;

    #[test]
    fn serial_numbers_are_sixteen_hex_digits_of_the_id() {
        let mut text = [0u8; 16];
        assert_eq!(
            super::serial_number(0x0123_4567_89AB_CDEF, &mut text),
            "0123456789ABCDEF"
        );
        assert_eq!(super::serial_number(5, &mut text), "0000000000000005");
    }

    #[test]
    fn a_reboot_request_is_taken_once() {
        use super::Reboot;
        let request = super::RebootRequest::new();
        assert_eq!(request.take(), None);
        request.request(Reboot::Bootloader);
        request.request(Reboot::Bootloader);
        assert_eq!(request.take(), Some(Reboot::Bootloader));
        assert_eq!(request.take(), None);
        request.request(Reboot::Bootloader);
        request.request(Reboot::Restart);
        assert_eq!(request.take(), Some(Reboot::Restart), "the later request");
        assert_eq!(request.take(), None);
    }

    #[test]
    fn a_watch_reports_the_first_value_and_every_change_once() {
        let mut watch = Watch::new();
        assert_eq!(watch.changed(1), Some(1));
        assert_eq!(watch.changed(1), None);
        assert_eq!(watch.changed(2), Some(2));
        assert_eq!(watch.changed(2), None);
    }
}
