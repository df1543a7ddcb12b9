//! The CCM bring-up image's lines: start-up (every pin with its source), the report every
//! second (every analog input, every digital input with its edge rate, both buses, the DTI),
//! and the sensor calibration in the form `ccm/calibration.toml` takes.

use super::dti::DtiBench;
use crate::apps::PedalVolts;
use crate::calibration::store::{self, CalibrationFlash, CalibrationStore, crc32};
use crate::calibration::{BenchRecorder, BenchResult, Calibration};
use aer::calibration::VehicleState;
use aer_console::LogBuffer;
use aer_console::bringup::{
    AnalogReading, BusLine, Clocks, DigitalReading, ReportHeader, ResetCause, Startup,
};
use core::fmt;

/// Bytes of log the bring-up image keeps for the host: the start-up lines and several
/// reports, for a terminal opened a few seconds after power-up.
pub const LOG_BYTES: usize = 16_384;

/// The bring-up image's start-up lines. Returns the lines that did not fit.
pub fn startup<const N: usize>(
    log: &mut LogBuffer<N>,
    board: &aer_boards::ccm::Revision,
    reset: ResetCause,
) -> u32 {
    let mut missed = Startup {
        image: "AER CCM bring-up",
        board: board.name,
        fingerprints: &[
            ("schema", aer::can::SCHEMA_FINGERPRINT),
            ("telemetry", aer::telemetry::TELEMETRY_FINGERPRINT),
        ],
        reset,
        clocks: Some(Clocks::TEENSY4),
        pins: &board.pins(),
    }
    .write(log);
    if !log.line(format_args!(
        "every output is off; `help` lists the commands"
    )) {
        missed += 1;
    }
    missed
}

/// One report: what every input of the board reads now.
#[derive(Debug, Clone, Copy)]
pub struct Report<'a> {
    /// Time and dropped lines.
    pub header: ReportHeader,
    /// Every on-chip ADC input.
    pub analog: &'a [AnalogReading],
    /// The ADS1115 pedal front-end's last conversions and its I2C errors (that board
    /// option only).
    pub ads1115: Option<(PedalVolts, u32)>,
    /// Every digital input.
    pub digital: &'a [DigitalReading],
    /// CAN3 (vehicle), then CAN2 (inverter).
    pub buses: [BusLine<'a>; 2],
    /// The DTI on the inverter bus.
    pub dti: &'a DtiBench,
    /// The brake light output.
    pub brake_light: bool,
}

impl Report<'_> {
    /// Queues the report's lines; returns how many did not fit.
    pub fn write<const N: usize>(&self, log: &mut LogBuffer<N>) -> u32 {
        let mut missed = 0;
        let mut line = |args: fmt::Arguments<'_>| {
            if !log.line(args) {
                missed += 1;
            }
        };
        line(format_args!("{}", self.header));
        for reading in self.analog {
            line(format_args!("{reading}"));
        }
        if let Some((volts, errors)) = self.ads1115 {
            line(format_args!(
                "ADS1115 pedals: APPS1 {}, APPS2 {}, I2C errors {errors}",
                Volts(volts[0]),
                Volts(volts[1])
            ));
        }
        for reading in self.digital {
            line(format_args!("{reading}"));
        }
        for bus in &self.buses {
            line(format_args!("{bus}"));
        }
        line(format_args!("CAN2 (inverter) {}", self.dti.check));
        line(format_args!("{}", self.dti.timeout));
        line(format_args!(
            "brake light {}",
            if self.brake_light { "on" } else { "off" }
        ));
        missed
    }
}

/// A conversion, or its absence.
struct Volts(Option<f32>);

impl fmt::Display for Volts {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.0 {
            Some(volts) => write!(f, "{volts:.3} V"),
            None => f.write_str("no conversion"),
        }
    }
}

/// The calibration's state after `cal rest` / `cal full`: one line, then, once both points
/// are in, the lines for `ccm/calibration.toml`. Returns the lines that did not fit.
pub fn calibration<const N: usize>(log: &mut LogBuffer<N>, recorder: &BenchRecorder) -> u32 {
    let result = recorder.result();
    let mut missed = u32::from(!log.line(format_args!("{result}")));
    if let BenchResult::Complete(calibration, _) = result {
        for toml in calibration.toml_lines() {
            missed += u32::from(!log.line(format_args!("    {toml}")));
        }
    }
    missed
}

/// The calibration `cal save` saves: the schema's defaults with the sensors the bench measured
/// (`cal rest` and `cal full` this session, else `ccm/calibration.toml`'s).
pub fn bench_calibration(recorder: &BenchRecorder) -> Calibration {
    let sensors = match recorder.result() {
        BenchResult::Complete(sensors, _) => sensors,
        _ => crate::calibration::measured::MEASURED,
    };
    sensors.applied_to(Calibration::DEFAULT)
}

/// `cal save`: saves `calibration` as the newest copy and says where, or why not. The bench
/// image never commands torque; the tractive system counts as live while the DTI reports 60 V
/// or more on its DC link, or `dti enable` runs. Returns the lines that did not fit.
pub fn cal_save<const N: usize>(
    log: &mut LogBuffer<N>,
    flash: &mut impl CalibrationFlash,
    calibration: &Calibration,
    epk: &[u8],
    tractive_live: bool,
) -> u32 {
    let (mut store, _) = CalibrationStore::load(flash, epk);
    let page = calibration.to_page();
    let state = VehicleState {
        moving: false,
        tractive_live,
    };
    let written = match store.save(flash, &page, epk, state) {
        Ok(store::Startup::Saved { slot, generation }) => log.line(format_args!(
            "saved as copy {} (generation {generation}), checksum 0x{:08X}",
            slot.name(),
            crc32(&page)
        )),
        Ok(other) => log.line(format_args!("{other}")),
        Err(error) => log.line(format_args!("{error}")),
    };
    u32::from(!written)
}

/// `cal load`: what start-up would load now, and its checksum. Returns the lines that did not
/// fit.
pub fn cal_load<const N: usize>(
    log: &mut LogBuffer<N>,
    flash: &mut impl CalibrationFlash,
    epk: &[u8],
) -> u32 {
    let (_, loaded) = CalibrationStore::load(flash, epk);
    let written = log.line(format_args!(
        "{}, checksum 0x{:08X}",
        loaded.startup,
        crc32(&loaded.calibration.to_page())
    ));
    u32::from(!written)
}
