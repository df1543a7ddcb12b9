//! The CCM bring-up image's lines: start-up (every pin with its source), the report every
//! second (every analog input, every digital input with its edge rate, both buses, the DTI),
//! the sensor calibration in the form `ccm/calibration.toml` takes, and the saved copies:
//! `cal save` (what was measured, over what start-up loads now), `cal load`, `cal erase`.

use super::CalibrationLine;
use super::dti::DtiBench;
use crate::apps::PedalVolts;
use crate::calibration::SensorCalibration;
use crate::calibration::bench::{BenchPoint, BenchRecorder, PedalResult};
use crate::calibration::store::{self, CalibrationFlash, CalibrationStore, crc32};
use aer::calibration::VehicleState;
use aer_console::LogBuffer;
use aer_console::board_check::BoardCheck;
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
    check: BoardCheck,
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
        check,
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

/// What the recording has after `point` completed: one line, then, once a group is complete
/// and checked, the lines for `ccm/calibration.toml`. Returns the lines that did not fit.
pub fn calibration<const N: usize>(
    log: &mut LogBuffer<N>,
    recorder: &BenchRecorder,
    point: BenchPoint,
) -> u32 {
    let mut missed = 0;
    let mut line = |args: fmt::Arguments<'_>| missed += u32::from(!log.line(args));
    match point {
        BenchPoint::Rest | BenchPoint::Full => {
            let result = recorder.pedals();
            line(format_args!("{result}"));
            if let PedalResult::Complete(pedals, brakes, Ok(())) = result {
                let sensors = SensorCalibration {
                    pedals,
                    brakes,
                    shocks: crate::calibration::ShockCalibration::DEFAULT,
                };
                for toml in sensors.pedal_toml_lines() {
                    line(format_args!("    {toml}"));
                }
            }
        }
        BenchPoint::Shock { .. } => {
            let result = recorder.shocks();
            line(format_args!("{result}"));
            if let Some((shocks, Ok(()))) = result.complete() {
                for toml in shocks.toml_lines() {
                    line(format_args!("    {toml}"));
                }
            }
        }
    }
    missed
}

/// `cal save`: the sensors this session measured and checked, over what start-up loads now
/// (the newest good saved copy, else the defaults with `file`, `ccm/calibration.toml`'s
/// sensors), every other value (the tuned ones) kept; saved as the newest copy, and the line
/// says where and over what. Refused when nothing was measured, a measurement was refused, or
/// the tractive system is live (the DTI reports 60 V or more on its DC link, or `dti enable`
/// runs). Returns the lines that did not fit.
pub fn cal_save<const N: usize>(
    log: &mut LogBuffer<N>,
    flash: &mut impl CalibrationFlash,
    recorder: &BenchRecorder,
    file: SensorCalibration,
    epk: &[u8],
    tractive_live: bool,
) -> u32 {
    let measured = match recorder.measured() {
        Ok(measured) => measured,
        Err(why) => return u32::from(!log.line(format_args!("{why}"))),
    };
    let (mut store, loaded) = CalibrationStore::load(flash, epk);
    let over = loaded.startup;
    let calibration = measured.applied_to(loaded.or_measured(file).calibration);
    let page = calibration.to_page();
    let state = VehicleState {
        moving: false,
        tractive_live,
    };
    let written = match store.save(flash, &page, epk, state) {
        Ok(store::Startup::Saved { slot, generation }) => {
            let base = Base(over);
            log.line(format_args!(
                "saved as copy {} (generation {generation}), checksum 0x{:08X}: the {} measured now, over {base}; every other value as it was",
                slot.name(),
                crc32(&page),
                measured.what(),
            ))
        }
        Ok(other) => log.line(format_args!("{other}")),
        Err(error) => log.line(format_args!("{error}")),
    };
    u32::from(!written)
}

/// What a save went over, in words.
struct Base(store::Startup);

impl fmt::Display for Base {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.0 {
            store::Startup::Saved { slot, generation } => {
                write!(f, "copy {} (generation {generation})", slot.name())
            }
            _ => f.write_str("the schema's defaults with ccm/calibration.toml's sensors"),
        }
    }
}

/// `cal load`: what start-up would load now, as the race image's start-up line says it.
/// Returns the lines that did not fit.
pub fn cal_load<const N: usize>(
    log: &mut LogBuffer<N>,
    flash: &mut impl CalibrationFlash,
    file: SensorCalibration,
    file_source: &str,
    epk: &[u8],
) -> u32 {
    let (_, loaded) = CalibrationStore::load(flash, epk);
    let loaded = loaded.or_measured(file);
    let line = CalibrationLine {
        startup: loaded.startup,
        checksum: crc32(&loaded.calibration.to_page()),
        file_source,
    };
    u32::from(!log.line(format_args!("{line}")))
}

/// `cal erase`: both saved copies erased, so start-up runs the file's sensors on the
/// defaults; refused while the tractive system is live. Returns the lines that did not fit.
pub fn cal_erase<const N: usize>(
    log: &mut LogBuffer<N>,
    flash: &mut impl CalibrationFlash,
    epk: &[u8],
    tractive_live: bool,
) -> u32 {
    let (mut store, _) = CalibrationStore::load(flash, epk);
    let state = VehicleState {
        moving: false,
        tractive_live,
    };
    let written = match store.erase(flash, state) {
        Ok(()) => log.line(format_args!(
            "erased both saved copies: start-up now runs ccm/calibration.toml's sensors on the schema's defaults (`cal load` says so)"
        )),
        Err(error) => log.line(format_args!("{}", Erase(error))),
    };
    u32::from(!written)
}

/// A refused erase, in words.
struct Erase(store::SaveError);

impl fmt::Display for Erase {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.0 {
            store::SaveError::NotAllowedNow => {
                f.write_str("not erased: only with the tractive system off")
            }
            store::SaveError::Flash(_) | store::SaveError::EpkTooLong => f.write_str(
                "not erased: the flash failed (a copy may remain; `cal load` says which)",
            ),
        }
    }
}
