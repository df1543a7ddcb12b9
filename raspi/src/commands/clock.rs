//! `aer-raspi clock`: the Pi's clock as the sessions record it, before a test day starts
//! (docs/test-day.md, "Before"): the time it reads in UTC, whether network time synchronized
//! it, and the steps the open session has seen.

use super::Located;
use crate::store::{clock, session, utc};

use anyhow::Result;
use std::io::Write;

/// Prints the clock as it reads at `now` with its `state` ([`clock::state`]); with a store,
/// the open session's recorded clock and steps.
pub fn show(
    located: &Located,
    now: i64,
    state: &str,
    out: &mut dyn Write,
    notes: &mut dyn Write,
) -> Result<()> {
    writeln!(out, "now (UTC)\t{}", utc(now))?;
    writeln!(out, "clock\t{state}")?;
    let Ok(store) = located.read(notes) else {
        writeln!(out, "session\tno store to read")?;
        return Ok(());
    };
    match session::current(&store.db)? {
        Some(id) => {
            let open = session::get(&store.db, id)?;
            writeln!(
                out,
                "session\t{id}, open since {}, clock then: {}",
                open.as_ref()
                    .map_or_else(String::new, |s| utc(s.started_us)),
                open.as_ref().map_or("", |s| s.clock.as_str())
            )?;
            for (at, step) in session::clock_steps(&store.db, id)? {
                writeln!(out, "step\t{}", clock::describe_step(at, step))?;
            }
        }
        None => writeln!(out, "session\tnone open")?,
    }
    Ok(())
}
