//! `aer-raspi export`: a session (or a time range, or a recorded log) as MCAP, Parquet and CSV,
//! and its frames (from the raw log) as BLF, ASC and MF4, into a folder of its own, or as one
//! tar archive with the session's raw log beside the exports, so it leaves the car in one step
//! (`ssh` to stdout, docs/test-day.md).
//!
//! An export that would select nothing is an error that says what has data; an export into a
//! folder that holds another export refuses, or with `--replace` removes that one first, so
//! two exports never mix.

use super::Located;
use crate::export::frames::{self, source::FrameSource};
use crate::export::{self, Format, load::Selection};
use crate::store::session::{self, Session};
use crate::store::utc;
use anyhow::{Context, Result, bail};
use std::io::Write;
use std::path::{Path, PathBuf};

/// What an export was asked for.
#[derive(Debug, Clone, Default)]
pub struct Wanted {
    /// A session id, or `latest`.
    pub session: Option<String>,
    pub from_us: Option<i64>,
    pub to_us: Option<i64>,
    /// A candump log or raw log segment instead of the store.
    pub log: Option<PathBuf>,
    pub formats: Vec<Format>,
    /// The folder to write.
    pub out: Option<PathBuf>,
    /// A tar archive to write instead (`-`: standard output).
    pub archive: Option<PathBuf>,
    /// Remove an earlier export in `out` first.
    pub replace: bool,
}

/// What an export folder holds of the decoded rows' formats; with the bus-logging formats'
/// files ([`frames::file_name`]), anything of these is an earlier export.
const LAYOUT: [&str; 8] = [
    "session.mcap",
    "parquet",
    "csv",
    "foxglove-layout.json",
    "plotjuggler-layout.xml",
    "report.html",
    "report.txt",
    "derived.csv",
];
/// Runs the export.
pub fn run(
    located: &Located,
    wanted: &Wanted,
    out: &mut dyn Write,
    notes: &mut dyn Write,
) -> Result<()> {
    let (db, extra, session) = match &wanted.log {
        Some(log) => {
            let (db, counters) = export::load::from_log(log, &located.config.car_id)?;
            let bad = counters
                .bad_lines
                .load(std::sync::atomic::Ordering::Relaxed);
            if bad > 0 {
                writeln!(
                    notes,
                    "{bad} lines or blocks of {} do not parse: skipped",
                    log.display()
                )?;
            }
            let m = &located.config.session;
            let extra = vec![
                ("log".to_owned(), log.display().to_string()),
                ("driver".to_owned(), m.driver.clone()),
                ("track".to_owned(), m.track.clone()),
                (
                    "run".to_owned(),
                    m.run.map(|r| r.to_string()).unwrap_or_default(),
                ),
                ("notes".to_owned(), m.notes.clone()),
                ("skipped_lines".to_owned(), bad.to_string()),
            ];
            (db, extra, None)
        }
        None => {
            let store = located.read(notes)?;
            let session = match wanted.session.as_deref() {
                None => None,
                Some(which) => Some(choose(&store.db, which, "exporting", notes)?),
            };
            if !store.still_consistent() {
                bail!("the service started while the store was being read: export again");
            }
            (store.db, Vec::new(), session)
        }
    };
    let selection = Selection {
        session: session.as_ref().map(|s| s.id),
        from_us: wanted.from_us,
        to_us: wanted.to_us,
    };
    let formats = if wanted.formats.is_empty() {
        Format::all()
    } else {
        wanted.formats.clone()
    };
    let frames = Some(frame_source(located, wanted, session.as_ref()));
    let (folder, scratch) = match (&wanted.out, &wanted.archive) {
        (Some(dir), None) => {
            prepare(dir, wanted.replace, notes)?;
            (dir.clone(), None)
        }
        (None, Some(_)) => {
            let scratch = scratch_dir()?;
            (scratch.clone(), Some(scratch))
        }
        _ => bail!("give --out DIR or --archive FILE (or `-`), one of them"),
    };
    let request = export::Request {
        selection,
        formats,
        out_dir: folder.clone(),
        topic_root: located.config.topic_prefix(),
        extra,
        frames,
        frames_required: !wanted.formats.is_empty(),
    };
    let written = export::export(&db, &request).map(|report| {
        let rows: usize = report.rows.iter().map(|(_, n)| n).sum();
        let frames = report.frames.as_ref().map_or(0, |s| s.frames);
        (rows > 0 || frames > 0).then_some((report, rows))
    });
    let outcome = match written {
        Err(error) => Err(anyhow::Error::new(error)),
        Ok(None) => Err(anyhow::anyhow!(
            "nothing to export: {} selects no rows (`aer-raspi session list` shows the sessions with data)",
            describe_selection(&selection)
        )),
        Ok(Some((report, rows))) => {
            writeln!(
                notes,
                "{rows} rows from {} tables, read in {:.1} ms",
                report.rows.len(),
                report.load.as_secs_f64() * 1e3
            )?;
            if report.calibration_entries > 0 {
                writeln!(
                    notes,
                    "calibration record: {} entries (`calibration` in Parquet and CSV, metadata in MCAP)",
                    report.calibration_entries
                )?;
            }
            frames_note(&report, &request, notes)?;
            if let Some(session) = &session {
                // The run report beside the data: what a data lead opens first.
                match crate::report::gather(&db, session.id, None)
                    .and_then(|run| crate::report::write(&folder, &run, None))
                {
                    Ok(_) => writeln!(
                        notes,
                        "report.html, report.txt, derived.csv: the run report"
                    )?,
                    Err(error) => writeln!(notes, "no run report: {error}")?,
                }
            }
            // A bus-logging format without frames was said above.
            for format in report
                .formats
                .iter()
                .filter(|f| !(f.format.holds_frames() && f.files.is_empty()))
            {
                let bytes: u64 = format.files.iter().map(|f| f.bytes).sum();
                writeln!(
                    notes,
                    "{:?}: {} file(s), {bytes} bytes, {:.1} ms",
                    format.format,
                    format.files.len(),
                    format.elapsed.as_secs_f64() * 1e3
                )?;
            }
            match &wanted.archive {
                Some(archive) => {
                    let raw = match &session {
                        Some(session) => session_segments(&located.config.raw_log.dir, session),
                        None => Vec::new(),
                    };
                    let name = match &session {
                        Some(session) => format!("session-{}", session.id),
                        None => "export".to_owned(),
                    };
                    write_archive(archive, &folder, &raw, &name, out, notes)
                }
                None => {
                    writeln!(out, "exported to {}", folder.display())?;
                    Ok(())
                }
            }
        }
    };
    if let Some(scratch) = scratch {
        let _ = std::fs::remove_dir_all(scratch);
    }
    outcome
}

/// Where the bus-logging formats take their frames: the recorded log itself, or the raw log's
/// segments over the session (or the time range).
fn frame_source(located: &Located, wanted: &Wanted, session: Option<&Session>) -> FrameSource {
    let micros = |us: Option<i64>| us.and_then(|us| u64::try_from(us).ok());
    let (mut from_us, mut to_us) = (micros(wanted.from_us), micros(wanted.to_us));
    if let Some(session) = session {
        let (started, last) = session.window();
        from_us = from_us.max(Some(started));
        to_us = match (to_us, last) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        };
    }
    let files = match &wanted.log {
        Some(log) => vec![log.clone()],
        None => frames::segments_between(
            &located.config.raw_log.dir,
            from_us.unwrap_or(0),
            to_us.unwrap_or(u64::MAX),
        ),
    };
    FrameSource {
        files,
        from_us,
        to_us,
    }
}

/// Says how many frames the bus-logging formats hold, or that a selection has none.
fn frames_note(
    report: &export::Report,
    request: &export::Request,
    notes: &mut dyn Write,
) -> Result<()> {
    let asked: Vec<String> = request
        .formats
        .iter()
        .filter(|f| f.holds_frames())
        .map(|f| format!("{f:?}"))
        .collect();
    if asked.is_empty() {
        return Ok(());
    }
    match &report.frames {
        Some(summary) if summary.frames > 0 => {
            writeln!(
                notes,
                "{} frames on channels {} for {}",
                summary.frames,
                summary.channels.describe(),
                asked.join(", ")
            )?;
            if summary.skipped > 0 {
                writeln!(
                    notes,
                    "{} lines or blocks of the frames' files do not parse: skipped",
                    summary.skipped
                )?;
            }
            Ok(())
        }
        // Asked for by name, no frames is the export's error, before anything was written.
        _ => {
            writeln!(
                notes,
                "no raw log frames for this selection: {} not written",
                asked.join(", ")
            )?;
            Ok(())
        }
    }
}

/// The session `which` names (`latest`, or an id), if it has rows; otherwise an error naming
/// the sessions that have. Says on `notes` which it took, as what the command is `doing`.
pub(super) fn choose(
    db: &rusqlite::Connection,
    which: &str,
    doing: &str,
    notes: &mut dyn Write,
) -> Result<Session> {
    let sessions = session::list_with_rows(db)?;
    let with_data: Vec<&(Session, u64)> = sessions.iter().filter(|(_, rows)| *rows > 0).collect();
    let listing = || {
        let named: Vec<String> = with_data
            .iter()
            .rev()
            .take(5)
            .map(|(s, rows)| format!("{} ({rows} rows, from {})", s.id, utc(s.started_us)))
            .collect();
        if named.is_empty() {
            "no session has any yet".to_owned()
        } else {
            format!("sessions with data, newest first: {}", named.join(", "))
        }
    };
    if which == "latest" {
        // The newest session with data: after an LV power cycle the newest session is the
        // one just opened, with nothing in it yet; the run just driven is the one before.
        let Some((chosen, rows)) = with_data.last() else {
            bail!(
                "no session has data yet ({} sessions, none with rows)",
                sessions.len()
            );
        };
        if let Some((newest, _)) = sessions.last().filter(|(s, _)| s.id != chosen.id) {
            writeln!(
                notes,
                "session {} (opened {}) has no rows yet: {doing} session {}, the newest with data ({rows} rows)",
                newest.id,
                utc(newest.started_us),
                chosen.id
            )?;
        } else {
            writeln!(notes, "{doing} session {} ({rows} rows)", chosen.id)?;
        }
        return Ok(chosen.clone());
    }
    let id: i64 = which.parse().ok().with_context(|| {
        format!("--session {which}: a session number (`aer-raspi session list`) or `latest`")
    })?;
    match sessions.iter().find(|(s, _)| s.id == id) {
        None => bail!("no session {id} in the store; {}", listing()),
        Some((_, 0)) => bail!("session {id} has no rows; {}", listing()),
        Some((s, rows)) => {
            writeln!(notes, "{doing} session {id} ({rows} rows)")?;
            Ok(s.clone())
        }
    }
}

fn describe_selection(selection: &Selection) -> String {
    let mut parts = Vec::new();
    if let Some(id) = selection.session {
        parts.push(format!("session {id}"));
    }
    if let Some(from) = selection.from_us {
        parts.push(format!("from {}", utc(from)));
    }
    if let Some(to) = selection.to_us {
        parts.push(format!("to {}", utc(to)));
    }
    if parts.is_empty() {
        "the whole store".to_owned()
    } else {
        parts.join(", ")
    }
}

/// Makes sure `dir` holds no earlier export: refuses, or with `replace` removes it whole.
fn prepare(dir: &Path, replace: bool, notes: &mut dyn Write) -> Result<()> {
    let frame_files = Format::all().into_iter().filter_map(frames::file_name);
    let earlier: Vec<PathBuf> = LAYOUT
        .into_iter()
        .chain(frame_files)
        .map(|name| dir.join(name))
        .filter(|path| path.exists())
        .collect();
    if earlier.is_empty() {
        return Ok(());
    }
    let names: Vec<String> = earlier.iter().map(|p| p.display().to_string()).collect();
    if !replace {
        bail!(
            "{} holds an earlier export ({}): choose another folder, or add --replace to remove it first",
            dir.display(),
            names.join(", ")
        );
    }
    for path in &earlier {
        let removed = if path.is_dir() {
            std::fs::remove_dir_all(path)
        } else {
            std::fs::remove_file(path)
        };
        removed.with_context(|| format!("removing the earlier export's {}", path.display()))?;
    }
    writeln!(notes, "removed the earlier export: {}", names.join(", "))?;
    Ok(())
}

/// A fresh folder for an archive's files.
fn scratch_dir() -> Result<PathBuf> {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos());
    let dir = std::env::temp_dir().join(format!("aer-export-{}-{nanos}", std::process::id()));
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    Ok(dir)
}

/// The raw log segments that hold frames of `session`.
fn session_segments(dir: &Path, session: &Session) -> Vec<PathBuf> {
    let (started, last) = session.window();
    frames::segments_between(dir, started, last.unwrap_or(u64::MAX))
}

/// Writes `folder` and the `raw` segments as one tar archive under `name/` (to `out` for
/// `-`).
fn write_archive(
    archive: &Path,
    folder: &Path,
    raw: &[PathBuf],
    name: &str,
    out: &mut dyn Write,
    notes: &mut dyn Write,
) -> Result<()> {
    let fill = |builder: &mut tar::Builder<&mut dyn Write>| -> Result<()> {
        builder
            .append_dir_all(name, folder)
            .context("adding the export to the archive")?;
        for segment in raw {
            let file = segment
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            builder
                .append_path_with_name(segment, format!("{name}/raw/{file}"))
                .with_context(|| format!("adding {} to the archive", segment.display()))?;
        }
        builder.finish().context("finishing the archive")?;
        Ok(())
    };
    if archive == Path::new("-") {
        let mut builder = tar::Builder::new(out);
        fill(&mut builder)?;
    } else {
        let mut file = std::io::BufWriter::new(
            std::fs::File::create(archive)
                .with_context(|| format!("creating {}", archive.display()))?,
        );
        {
            let mut builder = tar::Builder::new(&mut file as &mut dyn Write);
            fill(&mut builder)?;
        }
        file.flush()
            .with_context(|| format!("writing {}", archive.display()))?;
        writeln!(out, "archived to {}", archive.display())?;
    }
    writeln!(
        notes,
        "archive: {name}/ (the export) and {name}/raw/ ({} raw log segment(s))",
        raw.len()
    )?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{Config, Origin};

    fn session(started_us: i64, ended_us: Option<i64>) -> Session {
        Session {
            id: 1,
            started_us,
            ended_us,
            source: "live".into(),
            metadata: Default::default(),
            clock: String::new(),
        }
    }

    #[test]
    fn a_sessions_frames_are_those_of_its_time_within_the_range_asked_for() {
        let located = Located {
            config: Config::default(),
            origin: Origin::Defaults,
        };
        let window = |from_us, to_us, s: Option<&Session>| {
            let wanted = Wanted {
                from_us,
                to_us,
                ..Wanted::default()
            };
            let frames = frame_source(&located, &wanted, s);
            Some((frames.from_us, frames.to_us))
        };
        // Up to just before its end, where the next session's frames begin.
        let closed = session(1_000, Some(5_000));
        assert_eq!(
            window(None, None, Some(&closed)),
            Some((Some(1_000), Some(4_999)))
        );
        // The narrower of the two, at each end.
        assert_eq!(
            window(Some(2_000), Some(9_000), Some(&closed)),
            Some((Some(2_000), Some(4_999)))
        );
        assert_eq!(
            window(Some(500), Some(3_000), Some(&closed)),
            Some((Some(1_000), Some(3_000)))
        );
        // An open session runs to now; no session: the range alone.
        let open = session(1_000, None);
        assert_eq!(window(None, None, Some(&open)), Some((Some(1_000), None)));
        assert_eq!(window(Some(7), None, None), Some((Some(7), None)));
    }
}
