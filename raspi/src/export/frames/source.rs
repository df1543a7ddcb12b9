//! Where an export's frames come from (raw log segments, or a recorded log), read in two
//! passes: the first learns what the writers' headers need ([`Summary`]), the second hands
//! each frame over. Two reads of the files rather than the frames held in memory: a long
//! session is millions of frames, and the Pi has little memory to spare.

use super::channels::Channels;
use crate::export::ExportError;
use aer_host::formats::candump::parse_line;
use aer_host::formats::raw_format::{Frame, SegmentReader};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// The frames of an export: every frame of `files` received within the window.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct FrameSource {
    /// Raw log segments (oldest first), or one candump log or raw log segment.
    pub files: Vec<PathBuf>,
    /// Receive times, microseconds since the Unix epoch, inclusive.
    pub from_us: Option<u64>,
    pub to_us: Option<u64>,
}

/// What a pass over the frames found.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Summary {
    pub frames: u64,
    /// The earliest and latest receive time (frames from several buses can arrive a little
    /// out of time order, so these are the extremes, not the first and last).
    pub first_us: u64,
    pub last_us: u64,
    pub channels: Channels,
    /// Lines or blocks that do not parse, and segments gone before they were read (retention
    /// pruned them): skipped, and said in the export's notes.
    pub skipped: u64,
}

impl FrameSource {
    /// The first pass: what the frames span and which buses they came on.
    pub fn summary(&self) -> Result<Summary, ExportError> {
        let mut summary = Summary {
            first_us: u64::MAX,
            ..Summary::default()
        };
        let skipped = self.each(|frame| {
            summary.frames += 1;
            summary.first_us = summary.first_us.min(frame.frame.ts_us);
            summary.last_us = summary.last_us.max(frame.frame.ts_us);
            summary.channels.add(&frame.interface);
            Ok(())
        })?;
        summary.skipped = skipped;
        if summary.frames == 0 {
            summary.first_us = 0;
        }
        Ok(summary)
    }

    /// Calls `each` with every frame in the window, in the files' order; the lines or blocks
    /// skipped because they do not parse.
    pub fn each(
        &self,
        mut each: impl FnMut(&Frame) -> Result<(), ExportError>,
    ) -> Result<u64, ExportError> {
        let window = self.from_us.unwrap_or(0)..=self.to_us.unwrap_or(u64::MAX);
        let mut skipped = 0;
        for path in &self.files {
            let data = match std::fs::read(path) {
                Ok(data) => data,
                Err(error)
                    if error.kind() == std::io::ErrorKind::NotFound && self.files.len() > 1 =>
                {
                    skipped += 1;
                    continue;
                }
                Err(source) => {
                    return Err(ExportError::Read {
                        path: path.clone(),
                        source,
                    });
                }
            };
            skipped += each_in_file(&data, |frame| {
                if window.contains(&frame.frame.ts_us) {
                    each(frame)
                } else {
                    Ok(())
                }
            })?;
        }
        Ok(skipped)
    }
}

/// Every frame of one file, a raw log segment or candump text; the parts skipped.
fn each_in_file(
    data: &[u8],
    mut each: impl FnMut(&Frame) -> Result<(), ExportError>,
) -> Result<u64, ExportError> {
    let mut skipped = 0;
    if let Ok(reader) = SegmentReader::new(data) {
        for item in reader {
            match item {
                Ok(frame) => each(&frame)?,
                Err(_) => skipped += 1,
            }
        }
        return Ok(skipped);
    }
    // candump text names each line's interface; the frame's `bus` indexes `interfaces`.
    let mut interfaces: Vec<Arc<str>> = Vec::new();
    let text = String::from_utf8_lossy(data);
    for line in text.lines().filter(|l| !l.trim().is_empty()) {
        let parsed = parse_line(line, |name| {
            // At most 255 names: index 255 stands for "one too many" and is skipped below.
            let index = match interfaces.iter().position(|known| &**known == name) {
                Some(index) => index,
                None if interfaces.len() < usize::from(u8::MAX) => {
                    interfaces.push(name.into());
                    interfaces.len() - 1
                }
                None => usize::from(u8::MAX),
            };
            u8::try_from(index).unwrap_or(u8::MAX)
        });
        let Ok(frame) = parsed else {
            skipped += 1;
            continue;
        };
        let Some(interface) = interfaces.get(usize::from(frame.bus)) else {
            skipped += 1;
            continue;
        };
        each(&Frame {
            interface: interface.clone(),
            frame,
        })?;
    }
    Ok(skipped)
}

/// The segment files `paths` name, folders expanded to their segments in time order.
pub fn expand(paths: &[PathBuf]) -> Vec<PathBuf> {
    paths
        .iter()
        .flat_map(|path| {
            if Path::is_dir(path) {
                crate::rawlog::segments::list(path)
                    .into_iter()
                    .map(|(p, _)| p)
                    .collect()
            } else {
                vec![path.clone()]
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_that_do_not_parse_are_counted_and_the_window_holds() {
        let dir = tempfile::tempdir().expect("dir");
        let log = dir.path().join("run.log");
        std::fs::write(
            &log,
            "(1.000001) can0 123#11\nnot a frame\n(2.000000) can1 12345678#\n(3.500000) can0 7FF#00\n",
        )
        .expect("log");
        let source = FrameSource {
            files: vec![log],
            from_us: None,
            to_us: Some(2_000_000),
        };
        let summary = source.summary().expect("read");
        assert_eq!(summary.frames, 2, "the third frame is after the window");
        assert_eq!(summary.skipped, 1);
        assert_eq!((summary.first_us, summary.last_us), (1_000_001, 2_000_000));
        assert_eq!(summary.channels.describe(), "1 = can0, 2 = can1");
        let missing = FrameSource {
            files: vec![dir.path().join("gone.log")],
            ..FrameSource::default()
        };
        assert!(matches!(missing.summary(), Err(ExportError::Read { .. })));
    }
}
