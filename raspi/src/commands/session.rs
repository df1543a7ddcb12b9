//! `aer-raspi session ...`: list the sessions (times in UTC, rows, how far the clock was
//! trusted), change one's metadata, start the next, or count one's CAN messages.

use super::Located;
use crate::store::session::{self, Changes, Metadata};
use crate::store::{clock, session_messages, utc};
use anyhow::{Context, Result, bail};
use std::io::Write;

/// `session list`.
pub fn list(located: &Located, out: &mut dyn Write, notes: &mut dyn Write) -> Result<()> {
    let store = located.read(notes)?;
    let sessions = session::list_with_rows(&store.db)?;
    writeln!(
        out,
        "id\tstarted (UTC)\tended (UTC)\tsource\trows\tdriver\ttrack\trun\tnotes\tclock"
    )?;
    for (s, rows) in &sessions {
        let steps = session::clock_steps(&store.db, s.id)?;
        let clock = if steps.is_empty() {
            s.clock.clone()
        } else {
            let steps: Vec<String> = steps
                .iter()
                .map(|&(at, step)| clock::describe_step(at, step))
                .collect();
            format!("{}; stepped {}", s.clock, steps.join(", "))
        };
        writeln!(
            out,
            "{}\t{}\t{}\t{}\t{}\t{}\t{}\t{}\t{}\t{}",
            s.id,
            utc_seconds(s.started_us),
            s.ended_us.map_or_else(|| "open".to_owned(), utc_seconds),
            s.source,
            rows,
            s.metadata.driver,
            s.metadata.track,
            s.metadata.run.map(|r| r.to_string()).unwrap_or_default(),
            s.metadata.notes.replace(['\n', '\t'], " "),
            clock
        )?;
    }
    if sessions.is_empty() {
        bail!("the store has no sessions yet");
    }
    Ok(())
}

/// A time to the second, for a table a person reads.
fn utc_seconds(us: i64) -> String {
    let text = utc(us);
    match text.split_once('.') {
        Some((seconds, _)) => format!("{seconds}Z"),
        None => text,
    }
}

/// `session set`: changes the open session's metadata, or session `id`'s.
pub fn set(
    located: &Located,
    id: Option<i64>,
    changes: &Changes,
    out: &mut dyn Write,
    notes: &mut dyn Write,
) -> Result<()> {
    let db = located.change(false, notes)?;
    let id = match id {
        Some(id) => id,
        None => session::current(&db)?.context("no session is open; give --id")?,
    };
    if !session::change(&db, id, changes)? {
        bail!("no session {id} (`aer-raspi session list` shows them)");
    }
    writeln!(out, "session {id} updated")?;
    Ok(())
}

/// `session new`: closes the open session at `now_us` and starts the next with `metadata`.
pub fn new(
    located: &Located,
    metadata: &Metadata,
    create_store: bool,
    now: i64,
    out: &mut dyn Write,
    notes: &mut dyn Write,
) -> Result<()> {
    let db = located.change(create_store, notes)?;
    let id = session::begin(&db, metadata, "live", now)?;
    writeln!(out, "session {id} open since {}", utc_seconds(now))?;
    Ok(())
}

/// `session messages`: each CAN message of the open session (or `id`) per bus.
pub fn messages(
    located: &Located,
    id: Option<i64>,
    out: &mut dyn Write,
    notes: &mut dyn Write,
) -> Result<()> {
    let store = located.read(notes)?;
    let id = match id {
        Some(id) => id,
        None => session::current(&store.db)?.context("no session is open; give --id")?,
    };
    let hz = |rate: Option<f64>| rate.map_or_else(|| "-".to_owned(), |r| format!("{r:.2}"));
    let messages = session_messages::list(&store.db, id)?;
    if messages.is_empty() {
        bail!(
            "session {id} has no CAN messages (`aer-raspi session list` shows the sessions and their rows)"
        );
    }
    writeln!(
        out,
        "bus\tmessage\tframes\tmeasured_hz\tdeclared_hz\tchecksum_failures\tcounter_repeats\tcounter_jumps\tlate_frames"
    )?;
    for m in messages {
        writeln!(
            out,
            "{}\t{}\t{}\t{}\t{}\t{}\t{}\t{}\t{}",
            m.bus,
            m.message,
            m.frames,
            hz(m.measured_hz()),
            hz(m.declared_hz()),
            m.checksum_failures,
            m.counter_repeats,
            m.counter_jumps,
            m.late_frames
        )?;
    }
    Ok(())
}
