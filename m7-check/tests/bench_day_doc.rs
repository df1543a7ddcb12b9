//! docs/bench-day.md quotes what a good board prints; every quote is a transcript the images'
//! own code produces (`aer_m7_check::bench_day`), so the document cannot drift from the
//! firmware. A quote sits in a ```text block right after a `<!-- bench-day: NAME -->` line;
//! `cargo xtask docs` rewrites them all.

use aer_m7_check::bench_day::EXAMPLES;

const DOC: &str = include_str!("../../docs/bench-day.md");
const MARKER: &str = "<!-- bench-day: ";

/// Each marker's name and the text block after it.
fn quotes() -> Vec<(String, String)> {
    let mut quotes = Vec::new();
    let mut lines = DOC.lines().enumerate().peekable();
    while let Some((number, line)) = lines.next() {
        let Some(rest) = line.trim().strip_prefix(MARKER) else {
            continue;
        };
        let name = rest.trim_end_matches("-->").trim().to_string();
        let fence = lines.next().map(|(_, line)| line.trim());
        assert_eq!(
            fence,
            Some("```text"),
            "docs/bench-day.md:{}: `{name}` must be followed by a ```text block",
            number + 1
        );
        let mut block = String::new();
        for (_, line) in lines.by_ref() {
            if line.trim() == "```" {
                break;
            }
            block.push_str(line);
            block.push('\n');
        }
        quotes.push((name, block));
    }
    quotes
}

#[test]
fn every_quote_in_the_bench_day_procedure_is_what_the_code_prints() {
    let quotes = quotes();
    let mut differ = Vec::new();
    for (name, block) in &quotes {
        let (_, example) = EXAMPLES
            .iter()
            .find(|(known, _)| known == name)
            .unwrap_or_else(|| {
                panic!("docs/bench-day.md quotes `{name}`, which no example prints")
            });
        let mut printed = String::new();
        example(&mut printed).expect("the example runs");
        if block != &printed {
            differ.push(format!("`{name}`, which the code prints as:\n{printed}"));
        }
    }
    assert!(
        differ.is_empty(),
        "docs/bench-day.md's quotes differ from what the code prints (run `cargo xtask docs` to rewrite them all):\n{}",
        differ.join("\n")
    );
    for (name, _) in EXAMPLES {
        assert!(
            quotes.iter().any(|(quoted, _)| quoted == name),
            "`{name}` is never quoted in docs/bench-day.md: add its marker where it belongs, then `cargo xtask docs`"
        );
    }
}
