//! The bring-up images' loop, one for both boards: what every step does (feed the watchdog
//! unless a `watchdog test` stopped it, obey `bootloader` and `restart` with every output
//! safe, let the board read its inputs and check its tests and gates, take the typed lines,
//! print the report every second) and the commands every board answers alike (`help`,
//! `report` (and `status`), `watchdog test`, `panic test`, `bootloader`, `restart`, and a line
//! it does not understand). What differs between the boards (their inputs, outputs and
//! checks) is the [`BenchBoard`] each image implements.
//!
//! Portable and host-tested: the image moves data between it and the hardware.

use crate::bringup::ReportHeader;
use crate::command::HELP;
use crate::{Command, CommandError, LogBuffer, Reboot, RebootRequest};

/// A typed line, handed from the USB interrupt to the bench loop.
pub type Line = heapless::String<64>;

/// Lines typed faster than the bench loop takes them: the rest are dropped.
pub const QUEUED_LINES: usize = 4;

/// What a board's answer to a command is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reply {
    /// Printed after the command: `> <line>: <text>`.
    Say(&'static str),
    /// Print the report now (`report`).
    ReportNow,
}

/// One board's bring-up image, as the loop drives it.
pub trait BenchBoard {
    /// What the image reads outside the loop's board (inputs shared with an interrupt), read
    /// at every step and passed to [`Self::step`] and [`Self::report`].
    type Shared;
    /// The board, in messages ("CCM", "PCC").
    const NAME: &'static str;
    /// What the safe state is, in messages ("every output off").
    const SAFE: &'static str;
    /// What its panic handler does, in messages.
    const PANIC: &'static str;

    /// Services the hardware watchdog.
    fn feed_watchdog(&mut self);
    /// Every output to its safe level (before the bootloader).
    fn all_off(&mut self);
    /// Every step: read what arrived, sample what a test records, check every gate again and
    /// stop what it no longer allows.
    fn step<const N: usize>(&mut self, now_ms: u32, shared: &Self::Shared, log: &mut LogBuffer<N>);
    /// A command the board answers itself (outputs, tests, calibration).
    fn command<const N: usize>(
        &mut self,
        command: Command<'_>,
        now_ms: u32,
        log: &mut LogBuffer<N>,
    ) -> Reply;
    /// Every second (and on `report`): `header`, then every input, bus and counter.
    /// `elapsed_ms` is the time since the last report, for edge rates.
    fn report<const N: usize>(
        &mut self,
        header: ReportHeader,
        elapsed_ms: u32,
        shared: &Self::Shared,
        log: &mut LogBuffer<N>,
    );
    /// The LED, toggled with every report: a running loop blinks.
    fn toggle_led(&mut self);
}

/// What the image does after a step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[must_use]
pub enum After {
    /// Wait for the next step.
    Continue,
    /// Every output is safe: reboot into the bootloader now.
    Bootloader,
    /// Every output is safe: restart the image now.
    Restart,
    /// `panic test`: panic now, so the panic handler runs as it would on a fault.
    Panic,
}

/// The loop's own state: whether it still feeds the watchdog, when it last reported.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BenchLoop {
    feeding: bool,
    last_report_ms: u32,
    /// The log's dropped lines at the last report.
    dropped_at_report: u32,
    /// `report` was typed: report at this step, over the time since the last one (so edge
    /// rates stay true).
    report_now: bool,
    /// `panic test` was typed: panic once this step's lines are in the log.
    panic_now: bool,
}

impl Default for BenchLoop {
    fn default() -> Self {
        Self::new()
    }
}

impl BenchLoop {
    /// Feeding the watchdog; the first report a second after start.
    pub const fn new() -> Self {
        Self {
            feeding: true,
            last_report_ms: 0,
            dropped_at_report: 0,
            report_now: false,
            panic_now: false,
        }
    }

    /// One step at `now_ms`: `lines` are what was typed since the last one.
    pub fn step<B: BenchBoard, const N: usize>(
        &mut self,
        board: &mut B,
        now_ms: u32,
        lines: impl IntoIterator<Item = Line>,
        reboot: &RebootRequest,
        shared: &B::Shared,
        log: &mut LogBuffer<N>,
    ) -> After {
        if self.feeding {
            board.feed_watchdog();
        }
        if let Some(reboot) = reboot.take() {
            board.all_off();
            return match reboot {
                Reboot::Bootloader => After::Bootloader,
                Reboot::Restart => After::Restart,
            };
        }
        board.step(now_ms, shared, log);
        for line in lines {
            match self.command(board, &line, now_ms, reboot, log) {
                Some(Reply::Say(text)) => {
                    log.line(format_args!("> {line}: {text}"));
                }
                Some(Reply::ReportNow) => self.report_now = true,
                None => {}
            }
        }
        let elapsed_ms = now_ms.wrapping_sub(self.last_report_ms);
        if elapsed_ms >= 1_000 || self.report_now {
            self.last_report_ms = now_ms;
            self.report_now = false;
            board.toggle_led();
            let header = ReportHeader {
                now_ms,
                dropped: log.dropped().wrapping_sub(self.dropped_at_report),
                dropped_total: log.dropped(),
            };
            self.dropped_at_report = header.dropped_total;
            board.report(header, elapsed_ms, shared, log);
        }
        if self.panic_now {
            self.panic_now = false;
            return After::Panic;
        }
        After::Continue
    }

    /// The commands every board answers alike; the rest go to the board. `None`: the answer
    /// is already in the log.
    fn command<B: BenchBoard, const N: usize>(
        &mut self,
        board: &mut B,
        line: &str,
        now_ms: u32,
        reboot: &RebootRequest,
        log: &mut LogBuffer<N>,
    ) -> Option<Reply> {
        let reply = match Command::parse(line) {
            Ok(Command::Help) => {
                for text in HELP {
                    log.line(format_args!("{text}"));
                }
                return None;
            }
            Ok(Command::Report | Command::Status) => Reply::ReportNow,
            Ok(Command::PanicTest) => {
                self.panic_now = true;
                log.line(format_args!(
                    "> {line}: panicking on purpose: the panic handler {}",
                    B::PANIC
                ));
                return None;
            }
            Ok(Command::WatchdogTest) => {
                self.feeding = false;
                log.line(format_args!(
                    "> {line}: watchdog no longer fed: the {} resets within 1 s and reports the cause",
                    B::NAME
                ));
                return None;
            }
            Ok(Command::Bootloader) => {
                reboot.request(Reboot::Bootloader);
                log.line(format_args!(
                    "> {line}: rebooting into the bootloader, {}",
                    B::SAFE
                ));
                return None;
            }
            Ok(Command::Restart) => {
                reboot.request(Reboot::Restart);
                log.line(format_args!("> {line}: restarting, {}", B::SAFE));
                return None;
            }
            Ok(command) => board.command(command, now_ms, log),
            Err(CommandError::Unknown(_)) => Reply::Say("unknown command: `help`"),
            Err(CommandError::Usage(usage)) => Reply::Say(usage),
        };
        Some(reply)
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::string::String;
    use std::vec::Vec;

    /// A board that records what the loop asked of it.
    #[derive(Default)]
    struct Recorder {
        fed: u32,
        all_off: u32,
        steps: u32,
        commands: Vec<String>,
        reports: Vec<(u32, u32, u8)>,
        headers: Vec<ReportHeader>,
        led: bool,
    }

    impl BenchBoard for Recorder {
        type Shared = u8;
        const NAME: &'static str = "XCU";
        const SAFE: &'static str = "every output off";
        const PANIC: &'static str = "stops";

        fn feed_watchdog(&mut self) {
            self.fed += 1;
        }
        fn all_off(&mut self) {
            self.all_off += 1;
        }
        fn step<const N: usize>(&mut self, _: u32, _: &u8, _: &mut LogBuffer<N>) {
            self.steps += 1;
        }
        fn command<const N: usize>(
            &mut self,
            command: Command<'_>,
            _: u32,
            _: &mut LogBuffer<N>,
        ) -> Reply {
            self.commands.push(std::format!("{command:?}"));
            Reply::Say("done")
        }
        fn report<const N: usize>(
            &mut self,
            header: ReportHeader,
            elapsed_ms: u32,
            shared: &u8,
            _: &mut LogBuffer<N>,
        ) {
            self.reports.push((header.now_ms, elapsed_ms, *shared));
            self.headers.push(header);
        }
        fn toggle_led(&mut self) {
            self.led = !self.led;
        }
    }

    fn line(text: &str) -> Line {
        let mut line = Line::new();
        line.push_str(text).expect("fits");
        line
    }

    fn logged(log: &mut LogBuffer<4096>) -> String {
        let mut bytes = [0u8; 4096];
        let count = log.peek(&mut bytes);
        log.consume(count);
        String::from_utf8_lossy(&bytes[..count]).into_owned()
    }

    #[test]
    fn reports_every_second_and_on_request_with_what_the_image_read() {
        let (mut bench, mut board, mut log) = (
            BenchLoop::new(),
            Recorder::default(),
            LogBuffer::<4096>::new(),
        );
        let reboot = RebootRequest::new();
        for now in (0..2_500).step_by(10) {
            let _ = bench.step(&mut board, now, [], &reboot, &7, &mut log);
        }
        assert_eq!(board.reports, [(1_000, 1_000, 7), (2_000, 1_000, 7)]);
        assert_eq!(board.steps, 250);
        assert_eq!(board.fed, 250);
        // `report` prints at once; the next is a second after it.
        let _ = bench.step(&mut board, 2_500, [line("report")], &reboot, &7, &mut log);
        let _ = bench.step(&mut board, 3_000, [], &reboot, &7, &mut log);
        assert_eq!(board.reports.last(), Some(&(2_500, 500, 7)));
        assert!(board.led, "the LED toggles with every report");
        assert!(
            !logged(&mut log).contains("report"),
            "nothing printed but the report"
        );
    }

    #[test]
    fn the_common_commands_are_answered_alike_and_the_rest_go_to_the_board() {
        let (mut bench, mut board, mut log) = (
            BenchLoop::new(),
            Recorder::default(),
            LogBuffer::<4096>::new(),
        );
        let reboot = RebootRequest::new();
        let typed = ["help", "out led on", "fly", "out", "watchdog test"].map(line);
        let _ = bench.step(&mut board, 10, typed, &reboot, &0, &mut log);
        let text = logged(&mut log);
        for help in HELP {
            assert!(text.contains(help), "{help}");
        }
        assert!(text.contains("> out led on: done"), "{text}");
        assert!(text.contains("> fly: unknown command: `help`"), "{text}");
        assert!(
            text.contains("> out: out <signal> on|off|<0-100>"),
            "{text}"
        );
        assert!(
            text.contains("> watchdog test: watchdog no longer fed: the XCU resets within 1 s"),
            "{text}"
        );
        assert_eq!(board.commands.len(), 1, "{:?}", board.commands);
        // No longer fed from the next step on.
        let fed = board.fed;
        let _ = bench.step(&mut board, 20, [], &reboot, &0, &mut log);
        assert_eq!(board.fed, fed);
    }

    #[test]
    fn bootloader_makes_every_output_safe_before_the_reboot() {
        let (mut bench, mut board, mut log) = (
            BenchLoop::new(),
            Recorder::default(),
            LogBuffer::<4096>::new(),
        );
        let reboot = RebootRequest::new();
        let after = bench.step(&mut board, 10, [line("bootloader")], &reboot, &0, &mut log);
        assert_eq!(after, After::Continue, "asked, obeyed at the next step");
        assert!(
            logged(&mut log)
                .contains("> bootloader: rebooting into the bootloader, every output off")
        );
        let after = bench.step(&mut board, 20, [], &reboot, &0, &mut log);
        assert_eq!((after, board.all_off), (After::Bootloader, 1));
        // The host's 134 baud asks the same way.
        reboot.request(Reboot::Bootloader);
        let after = bench.step(&mut board, 30, [], &reboot, &0, &mut log);
        assert_eq!((after, board.all_off), (After::Bootloader, 2));
        // `restart` too makes every output safe first.
        let after = bench.step(&mut board, 40, [line("restart")], &reboot, &0, &mut log);
        assert_eq!(after, After::Continue);
        assert!(logged(&mut log).contains("> restart: restarting, every output off"));
        let after = bench.step(&mut board, 50, [], &reboot, &0, &mut log);
        assert_eq!((after, board.all_off), (After::Restart, 3));
    }

    #[test]
    fn the_report_header_counts_drops_since_the_last_report_and_in_all() {
        let (mut bench, mut board, mut log) = (
            BenchLoop::new(),
            Recorder::default(),
            LogBuffer::<64>::new(),
        );
        let reboot = RebootRequest::new();
        // Nobody reads: three lines of 40 bytes fit once, the rest drop.
        for _ in 0..3 {
            log.line(format_args!("{:40}", "a line nobody reads"));
        }
        let _ = bench.step(&mut board, 1_000, [], &reboot, &0, &mut log);
        let mut drained = [0u8; 64];
        let count = log.peek(&mut drained);
        log.consume(count);
        let _ = bench.step(&mut board, 2_000, [], &reboot, &0, &mut log);
        let counts: Vec<(u32, u32)> = board
            .headers
            .iter()
            .map(|header| (header.dropped, header.dropped_total))
            .collect();
        assert_eq!(counts, [(2, 2), (0, 2)], "a terminal that reads sees 0 now");
    }
}
