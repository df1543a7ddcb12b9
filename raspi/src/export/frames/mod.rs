//! Every CAN frame of an export in the bus-logging formats the team's bus tools open: BLF and
//! ASC (CANalyzer, CANoe) and MF4 (ASAM MDF 4 bus logging: CANape, asammdf). Where the other
//! formats hold the decoded rows, these hold the frames as the buses carried them, from the
//! raw log: each frame's receive time (to the microsecond), bus, identifier, extended flag and
//! data, whether the schema knows the frame or not.

pub mod asc;
pub mod blf;
pub mod channels;
pub mod mf4;
mod order;
pub mod source;

use super::{ExportError, Format, Written};
use aer_host::formats::raw_format::Frame;
use source::{FrameSource, Summary};
use std::io::{self, BufWriter};
use std::path::{Path, PathBuf};

/// A bus-logging file being written: given each frame with its channel, in source order.
pub trait FrameWriter {
    fn frame(&mut self, frame: &Frame, channel: u16) -> io::Result<()>;
    /// Completes the file (trailer, header counts).
    fn finish(self: Box<Self>) -> io::Result<()>;
}

/// The file a bus-logging format is written to in an export folder, `None` for the formats
/// of decoded rows.
pub fn file_name(format: Format) -> Option<&'static str> {
    match format {
        Format::Blf => Some("session.blf"),
        Format::Asc => Some("session.asc"),
        Format::Mf4 => Some("session.mf4"),
        Format::Mcap | Format::Parquet | Format::Csv => None,
    }
}

/// Writes every frame of `source` to `path` in `format` (a bus-logging one), with
/// `metadata` where the format has room for it.
pub fn write(
    format: Format,
    source: &FrameSource,
    summary: &Summary,
    path: &Path,
    metadata: &[(String, String)],
) -> Result<Written, ExportError> {
    let failed = |e: io::Error| ExportError::Write {
        path: path.to_owned(),
        source: e,
    };
    if !format.holds_frames() {
        return Err(ExportError::Internal("not a bus-logging format"));
    }
    let file = BufWriter::new(std::fs::File::create(path).map_err(failed)?);
    let written = (|| {
        let mut writer: Box<dyn FrameWriter> = match format {
            Format::Blf => Box::new(blf::BlfWriter::new(file, summary).map_err(failed)?),
            Format::Asc => Box::new(asc::AscWriter::new(file, summary, metadata).map_err(failed)?),
            _ => Box::new(mf4::Mf4Writer::new(file, summary, metadata).map_err(failed)?),
        };
        let mut ordered = order::TimeOrder::default();
        let mut emit = |frame: &Frame| {
            writer
                .frame(frame, summary.channels.of(&frame.interface))
                .map_err(failed)
        };
        source.each(|frame| ordered.push(frame, &mut emit))?;
        ordered.finish(&mut emit)?;
        writer.finish().map_err(failed)
    })();
    if let Err(error) = written {
        // A file cut short would read as a shorter session.
        let _ = std::fs::remove_file(path);
        return Err(error);
    }
    Written::file(path, usize::try_from(summary.frames).unwrap_or(usize::MAX))
}

/// The raw log segments in `dir` that may hold frames received from `from_us` to `to_us`:
/// each segment runs from its start to the next one's.
pub fn segments_between(dir: &Path, from_us: u64, to_us: u64) -> Vec<PathBuf> {
    let listed = crate::rawlog::segments::list(dir);
    let starts: Vec<u64> = listed
        .iter()
        .map(|(path, _)| crate::rawlog::segments::started_us(path).unwrap_or(0))
        .collect();
    listed
        .iter()
        .enumerate()
        .filter(|(i, _)| {
            let start = starts.get(*i).copied().unwrap_or(0);
            let next = starts.get(i + 1).copied().unwrap_or(u64::MAX);
            start <= to_us && next > from_us
        })
        .map(|(_, (path, _))| path.clone())
        .collect()
}
