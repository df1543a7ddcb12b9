//! `cargo xtask docs`: rewrites the quoted transcripts in docs/bench-day.md from the code that
//! prints them (`cargo run -p aer-m7-check --example bench_day`), all at once; the doc test
//! (`cargo test -p aer-m7-check --test bench_day_doc`) then passes. A marker
//! `<!-- bench-day: NAME -->` is followed by a ```text block that holds NAME's transcript.

use crate::cargo;
use anyhow::{Context, Result, bail};
use std::collections::BTreeMap;
use std::path::Path;

/// The page and where its quotes come from.
const PAGE: &str = "docs/bench-day.md";
const MARKER: &str = "<!-- bench-day: ";

pub fn run(root: &Path) -> Result<()> {
    let output = cargo()
        .current_dir(root)
        .args([
            "run",
            "--quiet",
            "-p",
            "aer-m7-check",
            "--example",
            "bench_day",
        ])
        .output()
        .context("running the bench day's transcripts")?;
    if !output.status.success() {
        bail!(
            "the bench day's transcripts failed:\n{}",
            String::from_utf8_lossy(&output.stderr)
        );
    }
    let transcripts = parse(&String::from_utf8_lossy(&output.stdout));
    let path = root.join(PAGE);
    let page = std::fs::read_to_string(&path).with_context(|| format!("reading {PAGE}"))?;
    let (rewritten, changed) = rewrite(&page, &transcripts)?;
    if rewritten != page {
        std::fs::write(&path, rewritten).with_context(|| format!("writing {PAGE}"))?;
    }
    println!(
        "{PAGE}: {} quotes, {} rewritten",
        transcripts.len(),
        changed.len()
    );
    for name in changed {
        println!("  {name}");
    }
    Ok(())
}

/// `--- bench-day NAME` sections.
fn parse(text: &str) -> BTreeMap<String, String> {
    let mut transcripts = BTreeMap::new();
    let mut current: Option<(String, String)> = None;
    for line in text.lines() {
        if let Some(name) = line.strip_prefix("--- bench-day ") {
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
fn rewrite(page: &str, transcripts: &BTreeMap<String, String>) -> Result<(String, Vec<String>)> {
    let mut out = String::new();
    let mut changed = Vec::new();
    let mut lines = page.lines().peekable();
    let mut quoted = Vec::new();
    while let Some(line) = lines.next() {
        out.push_str(line);
        out.push('\n');
        let Some(rest) = line.trim().strip_prefix(MARKER) else {
            continue;
        };
        let name = rest.trim_end_matches("-->").trim().to_owned();
        let Some(text) = transcripts.get(&name) else {
            bail!("{PAGE} quotes `{name}`, which no transcript prints");
        };
        if lines.next().map(str::trim) != Some("```text") {
            bail!("{PAGE}: `{name}` must be followed by a ```text block");
        }
        let mut old = String::new();
        for line in lines.by_ref() {
            if line.trim() == "```" {
                break;
            }
            old.push_str(line);
            old.push('\n');
        }
        if &old != text {
            changed.push(name.clone());
        }
        out.push_str("```text\n");
        out.push_str(text);
        out.push_str("```\n");
        quoted.push(name);
    }
    if let Some(missing) = transcripts.keys().find(|name| !quoted.contains(name)) {
        bail!("`{missing}` is never quoted in {PAGE}: add its marker where it belongs");
    }
    Ok((out, changed))
}
