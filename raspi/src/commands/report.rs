//! `aer-raspi report`: a session's run report (`report.txt`, printed, and `report.html`), with
//! another session beside it on `--compare`.

use super::Located;
use super::export::choose;
use crate::report;
use anyhow::{Context, Result};
use std::io::Write;
use std::path::PathBuf;

/// What to report on.
#[derive(Debug, Clone, Default)]
pub struct Wanted {
    /// A session id or `latest`.
    pub session: String,
    /// A session to compare with (an id or `latest`).
    pub compare: Option<String>,
    /// Laps every so many metres (an endurance lap), besides the runs and the marks.
    pub lap_length_m: Option<f64>,
    /// The folder to write into; `report-session-<id>` without.
    pub out: Option<PathBuf>,
    /// Also write the run on a 100 Hz grid, with these CAN signals (`table.column`).
    pub resample: bool,
    pub signals: Vec<String>,
}

/// Runs the report.
pub fn run(
    located: &Located,
    wanted: &Wanted,
    out: &mut dyn Write,
    notes: &mut dyn Write,
) -> Result<()> {
    let store = located.read(notes)?;
    let session = choose(&store.db, &wanted.session, "reporting on", notes)?;
    let ours = report::gather(&store.db, session.id, wanted.lap_length_m)?;
    let comparison = match &wanted.compare {
        Some(which) => {
            let other = choose(&store.db, which, "comparing with", notes)?;
            let theirs = report::gather(&store.db, other.id, wanted.lap_length_m)?;
            Some(report::compare(&ours, theirs))
        }
        None => None,
    };
    let dir = wanted
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from(format!("report-session-{}", session.id)));
    let written = report::write(&dir, &ours, comparison.as_ref())?;
    if wanted.resample || !wanted.signals.is_empty() {
        let signals = report::resample::signals(&store.db, session.id, &wanted.signals)?;
        let path = dir.join("resampled_100hz.csv");
        std::fs::write(&path, report::resample::csv(&ours.run, &signals))
            .with_context(|| format!("writing {}", path.display()))?;
        writeln!(notes, "the run at 100 Hz: {}", path.display())?;
    }
    out.write_all(report::text::render(&ours, comparison.as_ref()).as_bytes())?;
    writeln!(
        notes,
        "report written: {} (open it in a browser) and {}",
        written.html.display(),
        written.text.display()
    )?;
    Ok(())
}
