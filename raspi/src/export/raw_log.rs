//! Raw log segments as candump `-l` text (the same timestamps, interfaces, ids and data), or
//! as a BLF, ASC or MF4 file for the bus tools.

use super::frames::{self, source::FrameSource, source::expand};
use super::{Format, Written};
use aer_host::formats::raw_format::SegmentReader;
use anyhow::{Context, Result, bail};
use std::io::Write;
use std::path::{Path, PathBuf};

/// Writes every frame of `paths` (segments, or folders of them, oldest first) to `out` as
/// `format`, a bus-logging format, with the file names as metadata.
pub fn to_file(paths: &[PathBuf], format: Format, out: &Path) -> Result<Written> {
    if !format.holds_frames() {
        bail!("{format:?} holds decoded rows: `aer-raspi export --log SEGMENT` writes it");
    }
    let source = FrameSource {
        files: expand(paths),
        from_us: None,
        to_us: None,
    };
    let summary = source.summary()?;
    if summary.frames == 0 {
        bail!(
            "no frames in {} ({} damaged blocks): nothing written",
            paths
                .iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(", "),
            summary.skipped
        );
    }
    let named: Vec<String> = source
        .files
        .iter()
        .map(|p| p.display().to_string())
        .collect();
    let metadata = vec![("raw_log".to_owned(), named.join(", "))];
    let written = frames::write(format, &source, &summary, out, &metadata)?;
    if summary.skipped > 0 {
        eprintln!(
            "{} damaged blocks skipped (`aer-raspi raw-export` without --format names them)",
            summary.skipped
        );
    }
    Ok(written)
}

/// Writes every frame of `paths` (segments, or folders of them, oldest first) to `out`, one
/// candump line each. Damage is reported on stderr with the file and block, and skipped. A
/// reader that goes away (`| head`) ends the export quietly.
pub fn candump(paths: &[PathBuf], out: impl Write) -> Result<()> {
    let mut out = std::io::BufWriter::new(out);
    match write_all(paths, &mut out).and_then(|()| out.flush().map_err(Into::into)) {
        Err(error)
            if error
                .downcast_ref::<std::io::Error>()
                .is_some_and(|e| e.kind() == std::io::ErrorKind::BrokenPipe) =>
        {
            Ok(())
        }
        other => other,
    }
}

fn write_all(paths: &[PathBuf], out: &mut impl Write) -> Result<()> {
    for path in expand(paths) {
        let data = std::fs::read(&path).with_context(|| format!("reading {}", path.display()))?;
        let reader = SegmentReader::new(&data)
            .with_context(|| format!("{} is not a raw log segment", path.display()))?;
        for item in reader {
            match item {
                Ok(frame) => writeln!(out, "{}", frame.to_candump())?,
                Err(error) => eprintln!("{}: {error}", path.display()),
            }
        }
    }
    Ok(())
}
