//! Raw log segments as candump `-l` text: the same timestamps, interfaces, ids and data.

use super::segments;
use aer_host::raw_format::SegmentReader;
use anyhow::{Context, Result};
use std::io::Write;
use std::path::{Path, PathBuf};

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

/// The segment files `paths` name, folders expanded to their segments in time order.
fn expand(paths: &[PathBuf]) -> Vec<PathBuf> {
    paths
        .iter()
        .flat_map(|path| {
            if Path::is_dir(path) {
                segments::list(path).into_iter().map(|(p, _)| p).collect()
            } else {
                vec![path.clone()]
            }
        })
        .collect()
}
