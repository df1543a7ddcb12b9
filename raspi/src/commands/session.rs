//! `aer-raspi session ...`: list the sessions (times in UTC, rows, how far the clock was
//! trusted), change one's metadata, start the next, count one's CAN messages, or show its
//! calibration record.

use super::Located;
use crate::store::calibration::{self as record, Kind, number};
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

/// `session new`: closes the open session at `now_us` and starts the next with `metadata`,
/// from the same source.
pub fn new(
    located: &Located,
    metadata: &Metadata,
    create_store: bool,
    now: i64,
    out: &mut dyn Write,
    notes: &mut dyn Write,
) -> Result<()> {
    let db = located.change(create_store, notes)?;
    let lock = crate::store::lock::store_lock_path(located.store());
    if crate::store::lock::holder(&lock).is_none() {
        writeln!(
            notes,
            "no service records into this store now: the new session stays empty until one starts"
        )?;
    }
    let closed = session::current(&db)?;
    let id = session::hand_over(&db, metadata, now)?;
    writeln!(out, "session {id} open since {}", utc_seconds(now))?;
    if let Some(closed) = closed {
        let carried = record::carry_over(&db, closed, id, now)?;
        if carried > 0 {
            writeln!(
                notes,
                "it begins with the {carried} calibration values session {closed} ended with"
            )?;
        }
    }
    Ok(())
}

/// Session `id`, or the open one.
/// Session `id` (which must exist), or the open one, or, with none open (the service or the
/// demo stopped), the newest; says on `notes` which it took when none was given.
fn given_or_open(db: &rusqlite::Connection, id: Option<i64>, notes: &mut dyn Write) -> Result<i64> {
    if let Some(id) = id {
        if session::get(db, id)?.is_none() {
            bail!("no session {id} in the store (`aer-raspi session list` shows them)");
        }
        return Ok(id);
    }
    if let Some(open) = session::current(db)? {
        return Ok(open);
    }
    let newest = session::list(db)?
        .last()
        .map(|s| s.id)
        .context("the store has no sessions yet")?;
    writeln!(
        notes,
        "no session is open: session {newest}, the newest (give --id for another)"
    )?;
    Ok(newest)
}

/// `session messages`: each CAN message of the open session (or `id`) per bus.
pub fn messages(
    located: &Located,
    id: Option<i64>,
    out: &mut dyn Write,
    notes: &mut dyn Write,
) -> Result<()> {
    let store = located.read(notes)?;
    let id = given_or_open(&store.db, id, notes)?;
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

/// `session mark`: ends the lap in progress at `at_us`, in the open session.
pub fn mark(
    located: &Located,
    by: &str,
    at_us: i64,
    out: &mut dyn Write,
    notes: &mut dyn Write,
) -> Result<()> {
    let db = located.change(false, notes)?;
    let id = session::current(&db)?.context("no session is open (is the service running?)")?;
    let mark = aer_host::link::marks::Mark {
        ts: at_us as f64 / 1e6,
        by: by.to_owned(),
    };
    crate::store::events::insert(&db, id, &[crate::marks::event(&mark)])?;
    writeln!(out, "lap mark at {} in session {id}", utc(at_us))?;
    Ok(())
}

/// `session events`: what happened during the open session (or `id`), with when.
pub fn events(
    located: &Located,
    id: Option<i64>,
    out: &mut dyn Write,
    notes: &mut dyn Write,
) -> Result<()> {
    let store = located.read(notes)?;
    let id = given_or_open(&store.db, id, notes)?;
    let events = crate::store::events::list(&store.db, id)?;
    if events.is_empty() {
        bail!("session {id} recorded no events: no mark, no problem, no drop, no loop point");
    }
    writeln!(out, "time (UTC)\tkind\tname\ttext")?;
    for e in events {
        writeln!(
            out,
            "{}\t{}\t{}\t{}",
            utc(e.at_us),
            e.kind.name(),
            e.name,
            e.text
        )?;
    }
    Ok(())
}

/// `session calibration`: the open session's (or `id`'s) calibration changes and the values
/// it ended with; with `compare`, the values that differ from those session `compare` ended
/// with (or that one of the two does not know).
pub fn calibration(
    located: &Located,
    id: Option<i64>,
    compare: Option<i64>,
    out: &mut dyn Write,
    notes: &mut dyn Write,
) -> Result<()> {
    let store = located.read(notes)?;
    let id = given_or_open(&store.db, id, notes)?;
    if let Some(other) = compare
        && session::get(&store.db, other)?.is_none()
    {
        bail!(
            "--compare {other}: no session {other} in the store (`aer-raspi session list` shows them)"
        );
    }
    let entries = record::list(&store.db, Some(id), None, None)?;
    let value = |v: Option<f64>| v.map_or_else(|| "?".to_owned(), number);
    let unit = |name: &str| {
        aer::calibration::PARAMETERS
            .iter()
            .find(|p| p.name == name)
            .map_or("", |p| p.unit)
    };
    if let Some(other) = compare {
        let theirs = record::values_at_end(&record::list(&store.db, Some(other), None, None)?);
        let ours = record::values_at_end(&entries);
        let mut names: Vec<(String, Option<u32>)> = ours
            .iter()
            .chain(&theirs)
            .map(|(p, e, _)| (p.clone(), *e))
            .collect();
        names.sort();
        names.dedup();
        let find = |values: &[(String, Option<u32>, f64)], key: &(String, Option<u32>)| {
            values
                .iter()
                .find(|(p, e, _)| (p, e) == (&key.0, &key.1))
                .map(|(_, _, v)| *v)
        };
        if names.is_empty() {
            bail!(
                "neither session has a calibration record (no master connected through the gateway)"
            );
        }
        writeln!(out, "parameter\tunit\tsession {id}\tsession {other}")?;
        let mut same = 0;
        for key in &names {
            let (a, b) = (find(&ours, key), find(&theirs, key));
            if a.is_some() && a == b {
                same += 1;
                continue;
            }
            let target = key
                .1
                .map_or_else(|| key.0.clone(), |i| format!("{}[{i}]", key.0));
            writeln!(
                out,
                "{target}\t{}\t{}\t{}",
                unit(&key.0),
                value(a),
                value(b)
            )?;
        }
        writeln!(out, "({same} other values the same)")?;
        return Ok(());
    }
    if entries.is_empty() {
        bail!("session {id} has no calibration record (no master connected through the gateway)");
    }
    writeln!(
        out,
        "time (UTC)\tmaster\tkind\tparameter\tunit\told\tnew\tresult\tchecksum"
    )?;
    for e in entries.iter().filter(|e| e.kind != Kind::Found) {
        writeln!(
            out,
            "{}\t{}\t{}\t{}\t{}\t{}\t{}\t{}\t{}",
            utc(e.at_us),
            e.master,
            e.kind.name(),
            e.target(),
            unit(&e.parameter),
            value(e.old),
            value(e.new),
            if e.accepted {
                "accepted".to_owned()
            } else {
                format!("refused: {}", e.reason)
            },
            e.checksum.map(|c| format!("0x{c:08x}")).unwrap_or_default()
        )?;
    }
    writeln!(out, "\nat the end of session {id}:\nparameter\tunit\tvalue")?;
    for (parameter, element, v) in record::values_at_end(&entries) {
        let target = element.map_or_else(|| parameter.clone(), |i| format!("{parameter}[{i}]"));
        writeln!(out, "{target}\t{}\t{}", unit(&parameter), number(v))?;
    }
    Ok(())
}
