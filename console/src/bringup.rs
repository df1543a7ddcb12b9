//! What the bring-up images report and decide, without hardware types: reset causes, the
//! readings' report lines, edge rates, the pedal calibration, and the gate in front of the
//! outputs that switch high voltage.

use aer_boards::{Mode, Pin};
use core::fmt;

/// How long a typed `confirm hv-disconnected` arms the HV-switching outputs (ms).
pub const HV_CONFIRMATION_MS: u32 = 30_000;

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

/// The gate in front of an output that can switch high voltage (the PCC's AIR+): it may be
/// driven only within [`HV_CONFIRMATION_MS`] of a typed confirmation that the high voltage is
/// disconnected.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct HvGate {
    confirmed_ms: Option<u32>,
}

impl HvGate {
    /// The user confirmed at `now_ms` that the high voltage is disconnected.
    pub fn confirm(&mut self, now_ms: u32) {
        self.confirmed_ms = Some(now_ms);
    }

    /// Whether the HV outputs may move at `now_ms`.
    pub fn allows(&self, now_ms: u32) -> bool {
        self.confirmed_ms
            .is_some_and(|at| now_ms.wrapping_sub(at) < HV_CONFIRMATION_MS)
    }

    /// Forgets the confirmation (on `off`, or when it expired and the output dropped).
    pub fn revoke(&mut self) {
        self.confirmed_ms = None;
    }
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

/// Samples averaged for one calibration point (1 s at 1 kHz).
pub const CALIBRATION_SAMPLES: u32 = 1_000;

/// The pedal calibration: both sensors' volts averaged at rest and fully pressed, printed as
/// the values to put in `aer_ccm::apps::AppsCalibration`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PedalCalibration {
    /// Mean volts of APPS1, APPS2 at rest.
    pub rest: Option<[f32; 2]>,
    /// Mean volts of APPS1, APPS2 fully pressed.
    pub full: Option<[f32; 2]>,
    recording: Option<Recording>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Recording {
    full: bool,
    sums: [f32; 2],
    samples: u32,
}

impl PedalCalibration {
    /// Starts recording the rest (`full == false`) or fully pressed point.
    pub fn start(&mut self, full: bool) {
        self.recording = Some(Recording {
            full,
            sums: [0.0; 2],
            samples: 0,
        });
    }

    /// True while a point is being recorded.
    pub fn recording(&self) -> bool {
        self.recording.is_some()
    }

    /// Feeds one sample of both sensors (volts at the sensors; a missing reading is
    /// skipped). Returns true when the point just completed.
    pub fn sample(&mut self, volts: [Option<f32>; 2]) -> bool {
        let Some(recording) = self.recording.as_mut() else {
            return false;
        };
        let [Some(apps1), Some(apps2)] = volts else {
            return false;
        };
        if !(apps1.is_finite() && apps2.is_finite()) {
            return false;
        }
        recording.sums[0] += apps1;
        recording.sums[1] += apps2;
        recording.samples += 1;
        if recording.samples < CALIBRATION_SAMPLES {
            return false;
        }
        let n = recording.samples as f32;
        let mean = [recording.sums[0] / n, recording.sums[1] / n];
        if recording.full {
            self.full = Some(mean);
        } else {
            self.rest = Some(mean);
        }
        self.recording = None;
        true
    }
}

impl fmt::Display for PedalCalibration {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match (self.rest, self.full) {
            (Some([rest1, rest2]), Some([full1, full2])) => {
                write!(
                    f,
                    "pedal calibration: AppsCalibration {{ apps1: ({rest1:.3}, {full1:.3}), apps2: ({rest2:.3}, {full2:.3}) }}"
                )?;
                if (full1 - rest1).abs() < 0.5 || (full2 - rest2).abs() < 0.5 {
                    f.write_str(" -- less than 0.5 V of travel: check the sensor and repeat")?;
                }
                Ok(())
            }
            (Some([rest1, rest2]), None) => write!(
                f,
                "pedal calibration: rest APPS1 {rest1:.3} V, APPS2 {rest2:.3} V; now `cal full` with the pedal pressed"
            ),
            (None, Some([full1, full2])) => write!(
                f,
                "pedal calibration: full APPS1 {full1:.3} V, APPS2 {full2:.3} V; now `cal rest` with the pedal released"
            ),
            (None, None) => f.write_str("pedal calibration: `cal rest`, then `cal full`"),
        }
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
    fn the_hv_gate_opens_only_for_30_s_after_the_confirmation() {
        let mut gate = HvGate::default();
        assert!(!gate.allows(0));
        gate.confirm(u32::MAX - 10);
        assert!(gate.allows(u32::MAX));
        assert!(gate.allows(HV_CONFIRMATION_MS - 12), "across the wrap");
        assert!(!gate.allows(HV_CONFIRMATION_MS - 11));
        gate.confirm(5);
        gate.revoke();
        assert!(!gate.allows(6));
    }

    #[test]
    fn calibration_averages_a_second_of_samples_per_point() {
        let mut cal = PedalCalibration::default();
        assert!(!cal.sample([Some(1.0), Some(1.0)]), "not recording");
        cal.start(false);
        for i in 0..CALIBRATION_SAMPLES {
            let wobble = if i % 2 == 0 { 0.01 } else { -0.01 };
            let done = cal.sample([Some(0.5 + wobble), Some(0.75 - wobble)]);
            assert_eq!(done, i == CALIBRATION_SAMPLES - 1);
        }
        cal.start(true);
        for _ in 0..CALIBRATION_SAMPLES {
            cal.sample([Some(2.8), None]);
        }
        assert!(cal.recording(), "missing readings are not counted");
        for _ in 0..CALIBRATION_SAMPLES {
            cal.sample([Some(2.8), Some(4.2)]);
        }
        assert_eq!(
            format!("{cal}"),
            "pedal calibration: AppsCalibration { apps1: (0.500, 2.800), apps2: (0.750, 4.200) }"
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
