//! What the bring-up images report, without hardware types: reset causes, the readings'
//! report lines, edge rates, the buses, the start-up lines. The gate in front of the outputs
//! that matter at high voltage is [`crate::hv_gate`].

use crate::board_check::BoardCheck;
use crate::log::LogBuffer;
use aer_boards::assumed::{Assumed, Board as AssumedBoard};
use aer_boards::{Mode, Pin};
use aer_flexcan::{BusStatus, FaultState, SelfTestError};
use core::fmt;

/// The i.MX RT1062's reset causes (SRC_SRSR bits, RM "System Reset Controller").
pub const RESET_CAUSES: [(u32, &str); 9] = [
    (1 << 0, "power-on (IPP_RESET_B)"),
    (1 << 1, "core lockup or software reset (LOCKUP_SYSRESETREQ)"),
    (1 << 2, "CSU reset"),
    (1 << 3, "reset button (IPP_USER_RESET_B)"),
    (1 << 4, "watchdog WDOG1/WDOG2 (WDOG_RST_B)"),
    (1 << 5, "JTAG reset"),
    (1 << 6, "JTAG software reset"),
    (1 << 7, "watchdog WDOG3"),
    (1 << 8, "temperature sensor"),
];

/// SRC_SRSR as a list of causes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ResetCause(pub u32);

impl fmt::Display for ResetCause {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "reset cause (SRC_SRSR {:#05x}):", self.0)?;
        let mut any = false;
        for (bit, cause) in RESET_CAUSES {
            if self.0 & bit != 0 {
                write!(f, " {cause};")?;
                any = true;
            }
        }
        if !any {
            f.write_str(" none recorded")?;
        }
        Ok(())
    }
}

/// One analog input as the report prints it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AnalogReading {
    /// The pin (its signal, its ADC channel).
    pub pin: Pin,
    /// 12-bit counts.
    pub counts: u16,
    /// Volts at the sensor per volt at the pin.
    pub divider: f32,
}

impl fmt::Display for AnalogReading {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let channel = match self.pin.mode {
            Mode::Analog(channel) => channel,
            _ => u8::MAX,
        };
        let pin_v = f32::from(self.counts.min(4_095)) * 3.3 / 4_095.0;
        write!(
            f,
            "analog A{channel} pin {} {}: {} counts, {:.3} V at the pin, {:.3} V at the sensor",
            self.pin.number,
            self.pin.signal,
            self.counts,
            pin_v,
            pin_v * self.divider
        )
    }
}

/// One digital input: its level and its rising edges.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DigitalReading {
    /// The pin.
    pub pin: Pin,
    /// The level now.
    pub high: bool,
    /// Rising edges since start-up.
    pub edges: u32,
    /// Rising edges per second over the last report period.
    pub hz: f32,
}

impl fmt::Display for DigitalReading {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "digital pin {} {} ({}): {}, {} edges, {:.1} Hz",
            self.pin.number,
            self.pin.signal,
            self.pin.mode.label(),
            if self.high { "high" } else { "low" },
            self.edges,
            self.hz
        )
    }
}

/// Edges per second from two readings of a free-running edge counter `elapsed_ms` apart.
pub fn edge_rate_hz(before: u32, after: u32, elapsed_ms: u32) -> f32 {
    if elapsed_ms == 0 {
        return 0.0;
    }
    after.wrapping_sub(before) as f32 * 1_000.0 / elapsed_ms as f32
}

/// What a bus delivered since the last report: frames per identifier (the first
/// [`HEARD_IDS`] identifiers; the rest counted together).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Heard {
    ids: [(u32, u32); HEARD_IDS],
    distinct: usize,
    others: u32,
}

/// Identifiers a report lists per bus.
pub const HEARD_IDS: usize = 8;

impl Heard {
    /// Counts a frame with raw identifier `id`.
    pub fn frame(&mut self, id: u32) {
        let known = self
            .ids
            .iter_mut()
            .take(self.distinct)
            .find(|(seen, _)| *seen == id);
        match known {
            Some((_, count)) => *count = count.saturating_add(1),
            None => match self.ids.get_mut(self.distinct) {
                Some(slot) => {
                    *slot = (id, 1);
                    self.distinct += 1;
                }
                None => self.others = self.others.saturating_add(1),
            },
        }
    }

    /// Frames counted.
    pub fn total(&self) -> u32 {
        self.ids
            .iter()
            .take(self.distinct)
            .fold(self.others, |sum, (_, count)| sum.saturating_add(*count))
    }
}

impl fmt::Display for Heard {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} frames", self.total())?;
        for (id, count) in self.ids.iter().take(self.distinct) {
            write!(f, ", {id:#05x} x{count}")?;
        }
        if self.others > 0 {
            write!(f, ", {} more of other ids", self.others)?;
        }
        Ok(())
    }
}

/// One CAN controller's line in a report: its state and counters, then what it heard.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BusLine<'a> {
    /// The controller and its bus: `CAN3 (vehicle)`.
    pub name: &'a str,
    /// Its state, `None` when it did not start.
    pub status: Option<BusStatus>,
    /// What it received since the last report.
    pub heard: &'a Heard,
}

impl fmt::Display for BusLine<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let Some(status) = self.status else {
            return write!(f, "{}: did not start (see the start-up lines)", self.name);
        };
        write!(f, "{}: {status}; heard {}", self.name, self.heard)?;
        // A transmitter nobody acknowledges counts up to error-passive and stays there: the
        // usual sight of a board alone on its bus, not necessarily a fault.
        if status.state != FaultState::ErrorActive && self.heard.total() == 0 {
            f.write_str(
                " -- nothing heard: a board alone on a bus goes error-passive (no node acknowledges); with other nodes powered, check wiring, termination, transceiver",
            )?;
        }
        Ok(())
    }
}

/// The `can` command's loopback self-test of one controller.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SelfTestLine<'a> {
    /// The controller and its bus.
    pub name: &'a str,
    /// The result; `None` when the controller did not start.
    pub result: Option<Result<(), SelfTestError>>,
}

impl fmt::Display for SelfTestLine<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} loopback self-test: ", self.name)?;
        match self.result {
            Some(Ok(())) => f.write_str("passed"),
            Some(Err(error)) => write!(f, "FAILED: {error}"),
            None => f.write_str("not run: the controller did not start"),
        }
    }
}

/// The Teensy 4's clocks as the board support package sets them (the images check their
/// BSP's constants against these at compile time).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Clocks {
    /// Core (Hz).
    pub core_hz: u32,
    /// IPG, the peripherals' bus (Hz).
    pub ipg_hz: u32,
    /// PERCLK, the timers' clock (Hz).
    pub perclk_hz: u32,
    /// The CAN bit rate (bit/s), from the 24 MHz oscillator.
    pub can_bitrate: u32,
}

impl Clocks {
    /// teensy4-bsp 0.6: core 600 MHz, IPG 150 MHz, PERCLK 1 MHz; CAN at 500 kbit/s.
    pub const TEENSY4: Self = Self {
        core_hz: 600_000_000,
        ipg_hz: 150_000_000,
        perclk_hz: 1_000_000,
        can_bitrate: 500_000,
    };
}

impl fmt::Display for Clocks {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "clocks: core {} MHz, IPG {} MHz, PERCLK {} MHz, CAN from the 24 MHz oscillator at {} kbit/s",
            self.core_hz / 1_000_000,
            self.ipg_hz / 1_000_000,
            self.perclk_hz / 1_000_000,
            self.can_bitrate / 1_000
        )
    }
}

/// What an image prints once at start-up: who it is, why it started, its clocks and every
/// pin of its board with the pin's source.
#[derive(Debug, Clone, Copy)]
pub struct Startup<'a> {
    /// The image and what it is built for: `AER CCM bring-up`.
    pub image: &'a str,
    /// The board revision's name.
    pub board: &'a str,
    /// The fingerprints it was built with, by name.
    pub fingerprints: &'a [(&'a str, u32)],
    /// SRC_SRSR at start.
    pub reset: ResetCause,
    /// The clocks, for a bring-up image (the race images leave them out).
    pub clocks: Option<Clocks>,
    /// The pins to list (empty for the race images).
    pub pins: &'a [Pin],
    /// The board check's result (the image runs only on the right board).
    pub check: BoardCheck,
}

impl Startup<'_> {
    /// Queues the start-up lines; returns how many did not fit (counted by the log too).
    pub fn write<const N: usize>(&self, log: &mut LogBuffer<N>) -> u32 {
        let mut missed = 0;
        let mut line = |args: fmt::Arguments<'_>| {
            if !log.line(args) {
                missed += 1;
            }
        };
        line(format_args!("{self}"));
        line(format_args!("{}", self.reset));
        line(format_args!("{}", self.check));
        if let Some(clocks) = self.clocks {
            line(format_args!("{clocks}"));
        }
        for pin in self.pins {
            line(format_args!(
                "pin {:>2} {:<16} {:<15} {}",
                pin.number,
                pin.signal,
                pin.mode.label(),
                pin.source.text()
            ));
        }
        missed
    }
}

impl fmt::Display for Startup<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}, board {}", self.image, self.board)?;
        for (name, fingerprint) in self.fingerprints {
            write!(f, ", {name} {fingerprint:#010x}")?;
        }
        Ok(())
    }
}

/// One fact an image runs with that the bench day has not settled yet.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AssumedLine(pub &'static Assumed);

impl fmt::Display for AssumedLine {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let Assumed {
            what,
            assumed,
            settled,
            ..
        } = self.0;
        write!(f, "assumed: {what}")?;
        if !assumed.is_empty() {
            write!(f, ": {assumed}")?;
        }
        write!(f, " (settled in {settled})")
    }
}

/// The race images' list of what they run with unchecked, for `board`: a header line, then
/// one [`AssumedLine`] each. Returns how many lines did not fit.
pub fn write_assumed<const N: usize>(log: &mut LogBuffer<N>, board: AssumedBoard) -> u32 {
    let mut missed = 0;
    let count = Assumed::for_board(board).count();
    if !log.line(format_args!(
        "this image runs with {count} facts the bench day has not settled (docs/bench-day.md, \"Still assumed\"; the team's sheet records each check):"
    )) {
        missed += 1;
    }
    for item in Assumed::for_board(board) {
        if !log.line(format_args!("{}", AssumedLine(item))) {
            missed += 1;
        }
    }
    missed
}

/// The first line of every periodic report: when, and how many lines the log had to drop
/// because no terminal read them, since the last report and since start-up (a board
/// powered with no terminal open fills its log in seconds; what matters while you watch is
/// the first count).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReportHeader {
    /// Milliseconds since start-up.
    pub now_ms: u32,
    /// Lines dropped since the last report.
    pub dropped: u32,
    /// Lines dropped since start-up.
    pub dropped_total: u32,
}

impl fmt::Display for ReportHeader {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "--- t={} ms, log lines dropped {} since the last report ({} since start-up)",
            self.now_ms, self.dropped, self.dropped_total
        )
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::format;

    #[test]
    fn reset_causes_are_named_bit_by_bit() {
        assert_eq!(
            format!("{}", ResetCause(0x11)),
            "reset cause (SRC_SRSR 0x011): power-on (IPP_RESET_B); watchdog WDOG1/WDOG2 (WDOG_RST_B);"
        );
        assert_eq!(
            format!("{}", ResetCause(0)),
            "reset cause (SRC_SRSR 0x000): none recorded"
        );
    }

    #[test]
    fn bus_lines_read_as_words_and_explain_a_lone_board() {
        let mut heard = Heard::default();
        let active = BusStatus {
            state: FaultState::ErrorActive,
            tx_errors: 0,
            rx_errors: 0,
            rx_fifo_overflows: 0,
            bus_off_events: 0,
            tx_dropped: 0,
        };
        heard.frame(0x222);
        let line = BusLine {
            name: "CAN3 (vehicle)",
            status: Some(active),
            heard: &heard,
        };
        assert_eq!(
            format!("{line}"),
            "CAN3 (vehicle): error-active, tx errors 0, rx errors 0, rx overflows 0, bus-off 0x, tx dropped 0; heard 1 frames, 0x222 x1"
        );
        let alone = BusLine {
            name: "CAN2 (inverter)",
            status: Some(BusStatus {
                state: FaultState::ErrorPassive,
                tx_errors: 128,
                ..active
            }),
            heard: &Heard::default(),
        };
        assert!(
            format!("{alone}").ends_with(
                "; heard 0 frames -- nothing heard: a board alone on a bus goes error-passive (no node acknowledges); with other nodes powered, check wiring, termination, transceiver"
            ),
            "{alone}"
        );
        let dead = BusLine {
            name: "CAN2",
            status: None,
            heard: &heard,
        };
        assert_eq!(
            format!("{dead}"),
            "CAN2: did not start (see the start-up lines)"
        );
        let passed = SelfTestLine {
            name: "CAN2",
            result: Some(Ok(())),
        };
        assert_eq!(format!("{passed}"), "CAN2 loopback self-test: passed");
        let failed = SelfTestLine {
            name: "CAN2",
            result: Some(Err(SelfTestError::NothingReceived)),
        };
        assert_eq!(
            format!("{failed}"),
            "CAN2 loopback self-test: FAILED: the frame never came back"
        );
    }

    #[test]
    fn heard_frames_are_listed_per_id_up_to_a_limit() {
        let mut heard = Heard::default();
        for id in [0x222, 0x6B0, 0x222] {
            heard.frame(id);
        }
        assert_eq!(format!("{heard}"), "3 frames, 0x222 x2, 0x6b0 x1");
        for id in 0..20 {
            heard.frame(0x100 + id);
        }
        assert_eq!(heard.total(), 23);
        assert!(
            format!("{heard}").ends_with(", 14 more of other ids"),
            "{heard}"
        );
    }

    #[test]
    fn readings_print_the_pin_its_signal_and_its_units() {
        let pin = Pin::team(19, "apps1", Mode::Analog(5), "test");
        let line = format!(
            "{}",
            AnalogReading {
                pin,
                counts: 4_095,
                divider: 1.515_151
            }
        );
        assert_eq!(
            line,
            "analog A5 pin 19 apps1: 4095 counts, 3.300 V at the pin, 5.000 V at the sensor"
        );
        let pin = Pin::team(2, "wheel-speed1", Mode::InputPullUp, "test");
        let line = format!(
            "{}",
            DigitalReading {
                pin,
                high: true,
                edges: 120,
                hz: edge_rate_hz(20, 120, 1_000)
            }
        );
        assert_eq!(
            line,
            "digital pin 2 wheel-speed1 (input-pullup): high, 120 edges, 100.0 Hz"
        );
    }
}
