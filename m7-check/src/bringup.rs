//! The bring-up images' portable logic: typed commands, the console's log buffer, the HV
//! gate, the pedal calibration and the report lines, run with scripted input. Everything but
//! the registers, so a bench report reads the same as on the host.

use crate::Digest;
use aer_boards::{ccm, pcc};
use aer_ccm::calibration::{BenchPoint, BenchRecorder, BenchSample};
use aer_console::bringup::{AnalogReading, DigitalReading, Heard, ResetCause, edge_rate_hz};
use aer_console::hv_gate::{HvGate, HvReading, HvSensor};
use aer_console::{Command, LineReader, LogBuffer};
use core::fmt::Write;

/// Writes the bring-up transcript lines.
pub fn checks(out: &mut impl Write) -> core::fmt::Result {
    let mut reader = LineReader::<64>::new();
    let mut log = LogBuffer::<4_096>::new();
    let typed =
        b"help\rout pump1 40\nout air-plus-close on\rconfirm hv-disconnected\ncal rest\rbogus 1\n";
    for &byte in typed {
        if let Some(line) = reader.push(byte) {
            log.line(format_args!("{line} -> {:?}", Command::parse(line)));
        }
    }
    let mut gate = HvGate::new(60.0, 10);
    let sensor = |volts: Option<f32>, at_ms: u32| HvSensor {
        name: "tractive system",
        reading: volts.map_or(HvReading::Silent, |volts| HvReading::Volts { volts, at_ms }),
        silent: "no pulses",
    };
    log.line(format_args!(
        "gate {:?} {:?} {:?}",
        gate.confirm(1_000, &[sensor(Some(60.0), 1_000)]),
        gate.confirm(1_000, &[sensor(None, 1_000)]),
        gate.confirm(1_000, &[sensor(Some(12.5), 1_000)])
    ));
    log.line(format_args!(
        "gate {:?} {:?} {:?} {:?} {:?}",
        gate.allows(999 + 30_000, &[sensor(Some(12.5), 999 + 30_000)]),
        gate.allows(1_000 + 29_999, &[sensor(Some(12.5), 1_000 + 29_990)]),
        gate.allows(1_000 + 29_999, &[sensor(Some(12.5), 1_000 + 29_988)]),
        gate.allows(1_000 + 30_000, &[sensor(Some(12.5), 1_000 + 30_000)]),
        gate.allows(1_000 + 10, &[sensor(Some(60.0), 1_010)])
    ));
    let mut calibration = BenchRecorder::default();
    for (point, apps) in [
        (BenchPoint::Rest, [0.512f32, 0.771]),
        (BenchPoint::Full, [2.793, 4.187]),
    ] {
        calibration.start(point);
        let mut step = 0u32;
        while calibration.recording() {
            let wobble = (step % 7) as f32 * 0.001;
            calibration.sample(&BenchSample {
                pedals: [Some(apps[0] + wobble), Some(apps[1] - wobble)],
                brakes: [0.52 + wobble, 0.53 - wobble],
                shocks: [4.98 - wobble; 4],
            });
            step += 1;
        }
    }
    log.line(format_args!("{:?}", calibration.pedals()));
    log.line(format_args!("{}", ResetCause(0x13)));
    let divider = ccm::COMP_CAR.adc_divider;
    for (pin, counts) in ccm::COMP_CAR.pins().into_iter().zip((0u16..).step_by(181)) {
        if matches!(pin.mode, aer_boards::Mode::Analog(_)) {
            log.line(format_args!(
                "{}",
                AnalogReading {
                    pin,
                    counts,
                    divider
                }
            ));
        }
    }
    for (pin, edges) in pcc::COMP_CAR
        .voltage_freq
        .into_iter()
        .zip([1_234u32, 98_765])
    {
        let hz = edge_rate_hz(edges - 1_000, edges, 1_003);
        log.line(format_args!(
            "{}",
            DigitalReading {
                pin,
                high: edges % 2 == 0,
                edges,
                hz
            }
        ));
    }
    let mut heard = Heard::default();
    for id in (0..40u32).map(|i| 0x100 + (i * 37) % 11) {
        heard.frame(id);
    }
    log.line(format_args!("heard {heard}"));

    let mut digest = Digest::default();
    let mut chunk = [0u8; 61];
    let mut lines = 0;
    loop {
        let count = log.peek(&mut chunk);
        if count == 0 {
            break;
        }
        let bytes = chunk.get(..count).unwrap_or(&[]);
        lines += bytes.iter().filter(|&&byte| byte == b'\n').count();
        digest.bytes(bytes);
        log.consume(count);
    }
    writeln!(
        out,
        "bringup lines={lines} dropped={} discarded={} digest={:08x}",
        log.dropped(),
        reader.discarded(),
        digest.value()
    )
}
