//! `cargo xtask docs`: rewrites every quoted transcript in the documentation from the code that
//! prints it, all at once, so the doc tests pass again after a change (a schema change moves
//! fingerprints, byte counts and parameter lists in several quotes).
//!
//! - docs/bench-day.md: `cargo run -p aer-m7-check --example bench_day` prints every transcript
//!   (checked by `cargo test -p aer-m7-check --test bench_day_doc`).
//! - docs/test-day.md: the test `cargo test -p aer-raspi --test test_day_doc` writes what each
//!   command prints to the file `AER_DOC_EXAMPLES` names.
//!
//! In both, a marker `<!-- NAME-OF-PAGE: QUOTE -->` is followed by a fenced block (```text,
//! ```python, ...) that holds the quote.
//!
//! Then the bench day's table of what is still assumed (from `aer_boards::assumed`) and its
//! printable sheet, docs/bench-day-sheet.md, made from the page ([`crate::sheet`]).

use crate::cargo;
use anyhow::{Context, Result, bail};
use std::collections::BTreeMap;
use std::path::Path;

/// One page and the command whose output its quotes are.
struct Page {
    /// The page, from the workspace root.
    path: &'static str,
    /// Its markers' and the output's sections' tag: `bench-day`, `test-day`.
    tag: &'static str,
}

const PAGES: [Page; 2] = [
    Page {
        path: "docs/bench-day.md",
        tag: "bench-day",
    },
    Page {
        path: "docs/test-day.md",
        tag: "test-day",
    },
];

pub fn run(root: &Path) -> Result<()> {
    for page in &PAGES {
        let output = match page.tag {
            "bench-day" => bench_day(root)?,
            _ => test_day(root)?,
        };
        let transcripts = parse(&output, page.tag);
        let path = root.join(page.path);
        let text =
            std::fs::read_to_string(&path).with_context(|| format!("reading {}", page.path))?;
        let (rewritten, changed) = rewrite(&text, page, &transcripts)?;
        if rewritten != text {
            std::fs::write(&path, rewritten).with_context(|| format!("writing {}", page.path))?;
        }
        println!(
            "{}: {} quotes, {} rewritten{}",
            page.path,
            transcripts.len(),
            changed.len(),
            if changed.is_empty() { "" } else { ":" }
        );
        for name in changed {
            println!("  {name}");
        }
    }
    let page_path = root.join("docs/bench-day.md");
    let page = std::fs::read_to_string(&page_path).context("reading docs/bench-day.md")?;
    let page_now = crate::sheet::with_assumed_table(&page)?;
    if page_now != page {
        std::fs::write(&page_path, &page_now).context("writing docs/bench-day.md")?;
        println!("docs/bench-day.md: the table of what is still assumed rewritten");
    }
    let sheet_path = root.join("docs/bench-day-sheet.md");
    let sheet = crate::sheet::sheet(&page_now)?;
    if std::fs::read_to_string(&sheet_path).ok().as_deref() != Some(sheet.as_str()) {
        std::fs::write(&sheet_path, sheet).context("writing docs/bench-day-sheet.md")?;
        println!("docs/bench-day-sheet.md: rewritten from docs/bench-day.md");
    }
    Ok(())
}

fn bench_day(root: &Path) -> Result<String> {
    let output = crate::example(root, "bench_day")?
        .output()
        .context("running the bench day's transcripts")?;
    if !output.status.success() {
        bail!(
            "the bench day's transcripts failed:\n{}",
            String::from_utf8_lossy(&output.stderr)
        );
    }
    Ok(String::from_utf8_lossy(&output.stdout).into_owned())
}

fn test_day(root: &Path) -> Result<String> {
    let file = crate::target_dir(root).join("test-day-examples.txt");
    let _absent = std::fs::remove_file(&file);
    // The test fails while the page differs; what it wrote before comparing is what counts.
    let status = cargo()
        .current_dir(root)
        .args([
            "test",
            "--quiet",
            "-p",
            "aer-raspi",
            "--test",
            "test_day_doc",
        ])
        .env("AER_DOC_EXAMPLES", &file)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .status()
        .context("running the test-day runbook's commands")?;
    let text = std::fs::read_to_string(&file).unwrap_or_default();
    if text.is_empty() {
        bail!(
            "the test-day runbook's commands printed nothing (the test exited {status}): run `cargo test -p aer-raspi --test test_day_doc` to see why"
        );
    }
    Ok(text)
}

/// `--- TAG NAME` sections.
fn parse(text: &str, tag: &str) -> BTreeMap<String, String> {
    let header = format!("--- {tag} ");
    let mut transcripts = BTreeMap::new();
    let mut current: Option<(String, String)> = None;
    for line in text.lines() {
        if let Some(name) = line.strip_prefix(&header) {
            if let Some((name, body)) = current.take() {
                transcripts.insert(name, body);
            }
            current = Some((name.trim().to_owned(), String::new()));
        } else if let Some((_, body)) = current.as_mut() {
            body.push_str(line);
            body.push('\n');
        }
    }
    if let Some((name, body)) = current {
        transcripts.insert(name, body);
    }
    transcripts
}

/// The page with every marked block replaced; the names whose block changed.
fn rewrite(
    text: &str,
    page: &Page,
    transcripts: &BTreeMap<String, String>,
) -> Result<(String, Vec<String>)> {
    let marker = format!("<!-- {}: ", page.tag);
    let mut out = String::new();
    let mut changed = Vec::new();
    let mut quoted = Vec::new();
    let mut lines = text.lines();
    while let Some(line) = lines.next() {
        out.push_str(line);
        out.push('\n');
        let Some(rest) = line.trim().strip_prefix(&marker) else {
            continue;
        };
        let name = rest.trim_end_matches("-->").trim().to_owned();
        let Some(quote) = transcripts.get(&name) else {
            bail!("{} quotes `{name}`, which nothing prints", page.path);
        };
        let fence = lines.next().map(str::trim).unwrap_or_default();
        if !fence.starts_with("```") {
            bail!("{}: `{name}` must be followed by a ``` block", page.path);
        }
        let mut old = String::new();
        for line in lines.by_ref() {
            if line.trim() == "```" {
                break;
            }
            old.push_str(line);
            old.push('\n');
        }
        if &old != quote {
            changed.push(name.clone());
        }
        out.push_str(fence);
        out.push('\n');
        out.push_str(quote);
        out.push_str("```\n");
        quoted.push(name);
    }
    if let Some(missing) = transcripts.keys().find(|name| !quoted.contains(name)) {
        bail!(
            "`{missing}` is never quoted in {}: add its marker where it belongs",
            page.path
        );
    }
    Ok((out, changed))
}
