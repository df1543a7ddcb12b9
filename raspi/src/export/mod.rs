//! Session exports: the store's rows (or a recorded log's, decoded) as files engineers open
//! after a test day: MCAP for Foxglove and PlotJuggler, Parquet for pandas/polars, CSV for
//! spreadsheets. Each carries the session's metadata (driver, track, run, notes) and what
//! every column means (label, unit, values), all from the generated schema. Beside them, the
//! session's frames from the raw log in the bus tools' formats: BLF, ASC and MF4.
//!
//! [`load`] selects and reads the rows, [`column_descriptions`](crate::column_descriptions) says what each column is, and [`mcap`],
//! [`parquet`] and [`csv`] write them, with the session's [`calibration`] record; [`frames`]
//! writes the frames.

pub mod calibration;
pub mod columns;
pub mod csv;
pub mod frames;
pub mod layouts;
pub mod load;
pub mod mcap;
pub mod parquet;
pub mod raw_log;

use crate::store::{
    self,
    session::{self, Session},
};
use columns::TableData;
use load::Selection;
use rusqlite::Connection;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};
use thiserror::Error;

/// Why an export failed.
#[derive(Debug, Error)]
pub enum ExportError {
    #[error("cannot read {path}: {source}")]
    Read {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("cannot write {path}: {source}")]
    Write {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("reading the store: {0}")]
    Store(#[from] rusqlite::Error),
    #[error("no session {0} in the store (`aer-raspi session list` shows them)")]
    NoSession(i64),
    #[error("writing CSV: {0}")]
    Csv(#[from] ::csv::Error),
    #[error("writing Parquet: {0}")]
    Parquet(#[from] ::parquet::errors::ParquetError),
    #[error("writing MCAP: {0}")]
    Mcap(#[from] ::mcap::McapError),
    #[error(
        "BLF, ASC and MF4 hold the raw log's frames, and it has none for this selection (is the raw log where the configuration says? the demo's is aer-demo-raw/, read with --demo; `aer-raspi raw-export` reads segments)"
    )]
    NoFrames,
    #[error("internal error: {0}")]
    Internal(&'static str),
}

impl ExportError {
    fn write(path: &Path, source: std::io::Error) -> Self {
        Self::Write {
            path: path.to_owned(),
            source,
        }
    }
}

/// The export formats.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, clap::ValueEnum)]
pub enum Format {
    Mcap,
    Parquet,
    Csv,
    /// Vector binary logging (CANalyzer, CANoe): the raw log's frames.
    Blf,
    /// Vector ASCII logging (CANalyzer, CANoe): the raw log's frames.
    Asc,
    /// ASAM MDF 4 bus logging (CANape, asammdf): the raw log's frames.
    Mf4,
}

impl Format {
    /// Every format, in declaration order: what an export writes unless told otherwise.
    pub fn all() -> Vec<Self> {
        <Self as clap::ValueEnum>::value_variants().to_vec()
    }

    /// True for the formats that hold frames (from the raw log) rather than decoded rows.
    pub fn holds_frames(self) -> bool {
        frames::file_name(self).is_some()
    }
}

/// A file written, with the rows it holds.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Written {
    pub path: PathBuf,
    pub bytes: u64,
    pub rows: usize,
}

impl Written {
    fn file(path: &Path, rows: usize) -> Result<Self, ExportError> {
        let bytes = std::fs::metadata(path)
            .map_err(|e| ExportError::write(path, e))?
            .len();
        Ok(Self {
            path: path.to_owned(),
            bytes,
            rows,
        })
    }
}

/// Creates `dir` and writes each table with rows to `dir/<table>.<extension>` with
/// `write_table` (the layout of the per-table formats).
fn per_table(
    dir: &Path,
    tables: &[TableData],
    extension: &str,
    mut write_table: impl FnMut(&Path, &TableData) -> Result<(), ExportError>,
) -> Result<Vec<Written>, ExportError> {
    std::fs::create_dir_all(dir).map_err(|e| ExportError::write(dir, e))?;
    let mut written = Vec::new();
    for data in tables.iter().filter(|t| t.rows > 0) {
        let path = dir.join(format!("{}.{extension}", data.table.name));
        write_table(&path, data)?;
        written.push(Written::file(&path, data.rows)?);
    }
    Ok(written)
}

/// An enum column's named values as `0=OFF; 1=STANDBY`, the form `columns.csv` and the
/// Parquet metadata share.
pub(crate) fn value_names(values: &[(i128, &str)]) -> String {
    values
        .iter()
        .map(|(value, label)| format!("{value}={label}"))
        .collect::<Vec<_>>()
        .join("; ")
}

/// What one format's export wrote, and how long it took.
#[derive(Debug, Clone)]
pub struct FormatReport {
    pub format: Format,
    pub files: Vec<Written>,
    pub elapsed: Duration,
}

/// What an export wrote.
#[derive(Debug, Clone)]
pub struct Report {
    /// Rows selected, per table with any.
    pub rows: Vec<(&'static str, usize)>,
    /// Reading the rows from the store.
    pub load: Duration,
    pub formats: Vec<FormatReport>,
    /// The frames the bus-logging formats hold, if any were asked for and a source given.
    pub frames: Option<frames::source::Summary>,
    /// Entries of the session's calibration record the export carries.
    pub calibration_entries: usize,
}

/// An export's settings.
#[derive(Debug, Clone)]
pub struct Request {
    pub selection: Selection,
    pub formats: Vec<Format>,
    pub out_dir: PathBuf,
    /// `aer/<car>`: MCAP channels take the live topics' names.
    pub topic_root: String,
    /// Metadata for an export of a log (which has no session of its own), or extra keys.
    pub extra: Vec<(String, String)>,
    /// Where the bus-logging formats take the frames from; without it they are not written.
    pub frames: Option<frames::source::FrameSource>,
    /// The bus-logging formats were asked for by name: no frames is an error, found before
    /// anything is written.
    pub frames_required: bool,
}

/// The metadata every export carries: the session's (if one was chosen), what was selected,
/// the schema's fingerprints, and `extra`.
fn metadata(
    session: Option<(&Session, &[(i64, i64)])>,
    selection: Selection,
    extra: &[(String, String)],
) -> Vec<(String, String)> {
    let mut out = vec![(
        "time_base".to_owned(),
        "ts_us: when the Pi received each frame (telemetry: the packet's last frame), microseconds since the Unix epoch, UTC".to_owned(),
    )];
    if let Some((s, steps)) = session {
        out.push(("session".into(), s.id.to_string()));
        out.push(("driver".into(), s.metadata.driver.clone()));
        out.push(("track".into(), s.metadata.track.clone()));
        out.push((
            "run".into(),
            s.metadata.run.map(|r| r.to_string()).unwrap_or_default(),
        ));
        out.push(("notes".into(), s.metadata.notes.clone()));
        out.push(("source".into(), s.source.clone()));
        out.push(("started_us".into(), s.started_us.to_string()));
        out.push((
            "ended_us".into(),
            s.ended_us.map(|t| t.to_string()).unwrap_or_default(),
        ));
        out.push(("started_utc".into(), store::utc(s.started_us)));
        out.push((
            "ended_utc".into(),
            s.ended_us.map(store::utc).unwrap_or_default(),
        ));
        out.push(("clock".into(), s.clock.clone()));
        let steps: Vec<String> = steps
            .iter()
            .map(|&(at, step)| store::clock::describe_step(at, step))
            .collect();
        out.push((
            "clock_steps".into(),
            if steps.is_empty() {
                "none".into()
            } else {
                steps.join("; ")
            },
        ));
    }
    if let Some(from) = selection.from_us {
        out.push(("from_us".into(), from.to_string()));
    }
    if let Some(to) = selection.to_us {
        out.push(("to_us".into(), to.to_string()));
    }
    out.push((
        "telemetry_fingerprint".into(),
        columns::fingerprint(aer::telemetry::TELEMETRY_FINGERPRINT),
    ));
    out.push((
        "dbc_fingerprint".into(),
        columns::fingerprint(aer::can::SCHEMA_FINGERPRINT),
    ));
    for (key, value) in extra {
        match out.iter_mut().find(|(k, _)| k == key) {
            Some(slot) => slot.1.clone_from(value),
            None => out.push((key.clone(), value.clone())),
        }
    }
    out
}

/// Exports the selected rows of `db` in every requested format.
pub fn export(db: &Connection, request: &Request) -> Result<Report, ExportError> {
    let session = match request.selection.session {
        Some(id) => Some((
            session::get(db, id)?.ok_or(ExportError::NoSession(id))?,
            store::session::clock_steps(db, id)?,
        )),
        None => None,
    };
    let started = Instant::now();
    let tables = load::tables(db, request.selection)?;
    let selection = request.selection;
    let entries =
        store::calibration::list(db, selection.session, selection.from_us, selection.to_us)?;
    let load = started.elapsed();
    let mut metadata = metadata(
        session.as_ref().map(|(s, steps)| (s, steps.as_slice())),
        request.selection,
        &request.extra,
    );
    metadata.extend(calibration::metadata(&entries, &tables));
    let record = calibration::CalibrationTable::of(&entries);
    let wants_frames = request.formats.iter().any(|f| f.holds_frames());
    let summary = match &request.frames {
        Some(source) if wants_frames => Some(source.summary()?),
        _ => None,
    };
    let frames_found = summary.as_ref().map_or(0, |s| s.frames);
    if request.frames_required && wants_frames && frames_found == 0 {
        return Err(ExportError::NoFrames);
    }
    let rows_found: usize = tables.iter().map(|t| t.rows).sum();
    let mut formats = Vec::new();
    // Nothing selected writes nothing: the caller says so, and the folder stays empty.
    let writes = if rows_found == 0 && frames_found == 0 {
        &[][..]
    } else {
        &request.formats[..]
    };
    for &format in writes {
        let started = Instant::now();
        let files = match (frames::file_name(format), &request.frames, &summary) {
            (None, _, _) => write(format, &tables, (&entries, &record), &metadata, request)?,
            (Some(name), Some(source), Some(summary)) if summary.frames > 0 => {
                std::fs::create_dir_all(&request.out_dir)
                    .map_err(|e| ExportError::write(&request.out_dir, e))?;
                let path = request.out_dir.join(name);
                vec![frames::write(format, source, summary, &path, &metadata)?]
            }
            (Some(_), _, _) => Vec::new(),
        };
        formats.push(FormatReport {
            format,
            files,
            elapsed: started.elapsed(),
        });
    }
    Ok(Report {
        rows: tables
            .iter()
            .filter(|t| t.rows > 0)
            .map(|t| (t.table.name, t.rows))
            .collect(),
        load,
        formats,
        frames: summary,
        calibration_entries: entries.len(),
    })
}

fn write(
    format: Format,
    tables: &[TableData],
    (entries, record): (&[store::calibration::Entry], &calibration::CalibrationTable),
    metadata: &[(String, String)],
    request: &Request,
) -> Result<Vec<Written>, ExportError> {
    let dir = &request.out_dir;
    match format {
        Format::Mcap => {
            let mut written = vec![mcap::write(
                &dir.join("session.mcap"),
                tables,
                entries,
                metadata,
                &request.topic_root,
            )?];
            written.extend(layouts::write(dir, &request.topic_root)?);
            Ok(written)
        }
        Format::Parquet => {
            let dir = dir.join("parquet");
            let mut written = parquet::write(&dir, tables, metadata)?;
            if record.rows > 0 {
                written.push(parquet::write_calibration(&dir, record, metadata)?);
            }
            Ok(written)
        }
        Format::Csv => csv::write(&dir.join("csv"), tables, record, metadata),
        Format::Blf | Format::Asc | Format::Mf4 => {
            Err(ExportError::Internal("frames are written by frames::write"))
        }
    }
}
