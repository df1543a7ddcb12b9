//! The bench day's printable go/no-go sheet (docs/bench-day-sheet.md) and the page's table of
//! what is still assumed, both made from the sources the page itself is: `cargo xtask docs`
//! rewrites them, and this module's tests fail while either is stale.
//!
//! - Every go/no-go check is a list item of docs/bench-day.md written `- **☐ ID** text`
//!   (continued on indented lines); the sheet lists them by phase, each with its box and a
//!   link to the step it sits in. A check's ID starts with its step's number.
//! - Every stop condition is a list item `- **STOP** text` of the page's "Stop" section; the
//!   sheet boxes them all in one place, first.
//! - The table under `<!-- bench-day-table: assumed -->` is `aer_boards::assumed::ASSUMED`,
//!   the list the race images print at start-up.
//!
//! What the sheet adds of its own: the day's header, the ESO's signature before high voltage,
//! and the weld check before every re-closure of the shutdown circuit.

use aer_boards::assumed::{ASSUMED, Board};
use anyhow::{Result, bail};
use std::fmt::Write;

/// The page's marker before the table of what is still assumed.
pub const ASSUMED_MARKER: &str = "<!-- bench-day-table: assumed -->";

/// The phases of the day, by the steps they hold, each one printed page.
const PHASES: [(&str, &[&str]); 3] = [
    (
        "Phase 1: the boards at low voltage (steps 0-5)",
        &["0", "1", "2", "3", "4", "5"],
    ),
    (
        "Phase 2: the PCC and the DTI at low voltage (steps 6-7)",
        &["6", "7"],
    ),
    ("Phase 3: high voltage and the first spin (step 8)", &["8"]),
];

/// One check of the page.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Check {
    id: String,
    text: String,
    /// The heading it sits under, and its anchor.
    section: (String, String),
}

/// The page's table of what is still assumed, as markdown.
pub fn assumed_table() -> String {
    let mut table = String::from(
        "| What | Assumed | Where it lives | Settled in | Printed by |\n|---|---|---|---|---|\n",
    );
    for item in &ASSUMED {
        let board = match item.board {
            Board::Ccm => "CCM",
            Board::Pcc => "PCC",
            Board::Both => "both",
        };
        let _ = writeln!(
            table,
            "| {} | {} | {} | {} | {board} |",
            item.what, item.assumed, item.lives, item.settled
        );
    }
    table
}

/// `page` with the table under [`ASSUMED_MARKER`] replaced by [`assumed_table`].
pub fn with_assumed_table(page: &str) -> Result<String> {
    let Some(at) = page.find(ASSUMED_MARKER) else {
        bail!(
            "docs/bench-day.md has no `{ASSUMED_MARKER}` line before its table of what is assumed"
        );
    };
    let after = at + ASSUMED_MARKER.len();
    let rest = page.get(after..).unwrap_or_default();
    let rest = rest.strip_prefix('\n').unwrap_or(rest);
    let table_len: usize = rest
        .lines()
        .take_while(|line| line.starts_with('|'))
        .map(|line| line.len() + 1)
        .sum();
    let tail = rest.get(table_len..).unwrap_or_default();
    Ok(format!(
        "{}\n{}{}",
        page.get(..after).unwrap_or_default(),
        assumed_table(),
        tail
    ))
}

/// A heading's anchor as GitHub and mdBook make it: lower case, punctuation dropped, spaces
/// to hyphens.
fn anchor(heading: &str) -> String {
    heading
        .chars()
        .filter_map(|c| match c {
            'A'..='Z' => Some(c.to_ascii_lowercase()),
            'a'..='z' | '0'..='9' | '-' | '_' => Some(c),
            ' ' => Some('-'),
            _ if c.is_alphanumeric() => Some(c),
            _ => None,
        })
        .collect()
}

/// Every check and every stop condition of the page, in order.
fn parse(page: &str) -> Result<(Vec<Check>, Vec<String>)> {
    let mut checks: Vec<Check> = Vec::new();
    let mut stops: Vec<String> = Vec::new();
    let mut section = (String::new(), String::new());
    // What the current list item's continuation lines extend.
    enum Open {
        None,
        Check,
        Stop,
    }
    let mut open = Open::None;
    for (number, line) in page.lines().enumerate() {
        if let Some(heading) = line.strip_prefix('#') {
            let heading = heading.trim_start_matches('#').trim();
            section = (heading.to_owned(), anchor(heading));
            open = Open::None;
            continue;
        }
        let trimmed = line.trim_start();
        if let Some(rest) = trimmed.strip_prefix("- **☐ ") {
            let Some((id, text)) = rest.split_once("** ") else {
                bail!(
                    "docs/bench-day.md:{}: a check is `- **☐ ID** text`",
                    number + 1
                );
            };
            let step: String = id.chars().take_while(char::is_ascii_digit).collect();
            if step.is_empty() {
                bail!(
                    "docs/bench-day.md:{}: check `{id}` must start with its step's number",
                    number + 1
                );
            }
            if checks.iter().any(|check| check.id == id) {
                bail!("docs/bench-day.md:{}: check `{id}` twice", number + 1);
            }
            checks.push(Check {
                id: id.to_owned(),
                text: text.trim().to_owned(),
                section: section.clone(),
            });
            open = Open::Check;
        } else if let Some(rest) = trimmed.strip_prefix("- **STOP** ") {
            stops.push(rest.trim().to_owned());
            open = Open::Stop;
        } else if line.starts_with("  ") && !trimmed.is_empty() && !trimmed.starts_with("- ") {
            let extend = match open {
                Open::Check => checks.last_mut().map(|check| &mut check.text),
                Open::Stop => stops.last_mut(),
                Open::None => None,
            };
            if let Some(text) = extend {
                text.push(' ');
                text.push_str(trimmed);
            }
        } else {
            open = Open::None;
        }
    }
    if checks.is_empty() || stops.is_empty() {
        bail!("docs/bench-day.md has no `- **☐ ID**` checks or no `- **STOP**` conditions");
    }
    Ok((checks, stops))
}

/// The sheet for `page`.
pub fn sheet(page: &str) -> Result<String> {
    let (checks, stops) = parse(page)?;
    let mut out = String::new();
    let _ = writeln!(
        out,
        "# Bench day: the go/no-go sheet\n\n\
         <!-- Written by `cargo xtask docs` from docs/bench-day.md: edit the page, not this file. -->\n\n\
         Print it, one page per phase; tick each box as its check passes, in order. Every line links to its step in\n\
         [docs/bench-day.md](bench-day.md), which says how and what to do when it does not pass. A box\n\
         not ticked is a no-go for everything after it.\n\n\
         Car ____________ Date ____________ CCM board serial ________________ PCC board serial ________________\n\n\
         People (and who is the ESO) ______________________________________________________________\n"
    );
    let _ = writeln!(
        out,
        "## Stop: any of these stops the day's work on the car\n\n\
         First open the shutdown circuit if it is closed (the e-stop); then hands off the car, and the ESO\n\
         decides what happens next and when work goes on ([the page's Stop section](bench-day.md#stop)).\n"
    );
    let _ = writeln!(out, "| Stop condition | Seen (time, what) |\n|---|---|");
    for stop in &stops {
        let _ = writeln!(out, "| ☐ {stop} | |");
    }
    for (index, (title, steps)) in PHASES.iter().enumerate() {
        let _ = writeln!(
            out,
            "\n<div style=\"page-break-before: always\"></div>\n\n## {title}\n"
        );
        if index == 2 {
            let _ = writeln!(
                out,
                "**Before the accumulator is connected**: every box of phases 1 and 2 ticked, no stop condition\n\
                 seen, the bench wiring undone ([8, set-up](bench-day.md#set-up)).\n\n\
                 ESO: name ________________ signature ________________ time ________\n"
            );
        }
        let _ = writeln!(out, "| | Check | Step |\n|---|---|---|");
        for check in checks.iter().filter(|check| {
            let step: String = check.id.chars().take_while(char::is_ascii_digit).collect();
            steps.contains(&step.as_str())
        }) {
            let step = check
                .section
                .0
                .split_once(' ')
                .map_or(check.section.0.as_str(), |(number, _)| number)
                .trim_end_matches('.');
            let _ = writeln!(
                out,
                "| ☐ | **{}** {} | [{step}](bench-day.md#{}) |",
                check.id, check.text, check.section.1
            );
        }
        if index == 2 {
            let _ = writeln!(
                out,
                "\n**Every closure of the shutdown circuit** (the day's first, and after any opening, planned or not): before\n\
                 closing, the TSMP meter reads below 5 V with the circuit open, and the ESO measures each AIR open: the\n\
                 maintenance plug out, LV off, the ohmmeter across each AIR's main contacts reads open (ears cannot tell:\n\
                 both coils drop at once; [8, set-up](bench-day.md#set-up)).\n\n\
                 | Closure | Time | TSMP below 5 V, circuit open | AIR+ open (ohmmeter) | AIR- open (ohmmeter) | ESO initials |\n\
                 |---|---|---|---|---|---|"
            );
            for closure in 1..=8 {
                let _ = writeln!(out, "| {closure} | | ☐ | ☐ | ☐ | |");
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    const PAGE: &str = include_str!("../../docs/bench-day.md");
    const SHEET: &str = include_str!("../../docs/bench-day-sheet.md");

    #[test]
    fn the_sheet_is_what_the_page_makes() {
        assert!(
            sheet(PAGE).expect("the page parses") == SHEET,
            "docs/bench-day-sheet.md is stale: run `cargo xtask docs`"
        );
    }

    #[test]
    fn the_pages_table_of_what_is_assumed_is_the_firmwares_list() {
        assert!(
            with_assumed_table(PAGE).expect("the marker is there") == PAGE,
            "docs/bench-day.md's table of what is assumed differs from aer_boards::assumed: run `cargo xtask docs`"
        );
    }

    #[test]
    fn checks_and_stops_are_read_with_their_steps() {
        let page = "## 6c. Pin 11\n\n- **☐ 6c.1** AIR+ opens\n  at once.\n- other\n\n## Stop\n\n- **STOP** a reading\n  of 60 V.\n";
        let (checks, stops) = parse(page).expect("parses");
        assert_eq!(
            checks,
            vec![Check {
                id: "6c.1".to_owned(),
                text: "AIR+ opens at once.".to_owned(),
                section: ("6c. Pin 11".to_owned(), "6c-pin-11".to_owned()),
            }]
        );
        assert_eq!(stops, vec!["a reading of 60 V.".to_owned()]);
        assert!(parse("- **☐ x** no step\n- **STOP** s\n").is_err());
    }

    #[test]
    fn each_phase_fits_a_printed_page() {
        let sheet = sheet(PAGE).expect("the page parses");
        for page in sheet.split("page-break-before") {
            let rows = page.lines().filter(|line| line.starts_with('|')).count();
            assert!(rows <= 42, "{rows} table rows on one page:\n{page}");
        }
    }
}
