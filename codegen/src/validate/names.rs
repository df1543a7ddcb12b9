//! Names and lines in the YAML schemas: where a value is, and whether a name can become a
//! generated Rust item (the calibration's parameters and internals, the XCP events).

use std::collections::HashSet;

use serde_saphyr::Spanned;

use crate::diagnostic::{Code, Reporter};
use crate::naming::is_keyword;

/// The line of a value in its YAML file (0 when the parser gave none).
pub(crate) fn line_of<T>(s: &Spanned<T>) -> usize {
    usize::try_from(s.referenced.line()).unwrap_or(0)
}

/// Whether `text` can name a generated item: snake_case, starting with a letter.
pub(crate) fn is_snake_identifier(text: &str) -> bool {
    text.starts_with(|c: char| c.is_ascii_lowercase())
        && text
            .chars()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_')
}

/// A name for a generated item, reported under `code` when it is not snake_case, a keyword
/// or already taken; `what` says what it names.
pub(crate) fn check_item_name(
    r: &mut Reporter<'_>,
    code: Code,
    what: &str,
    name: &Spanned<String>,
    seen: &mut HashSet<String>,
) -> bool {
    let (text, line) = (name.value.as_str(), line_of(name));
    let problem = if !is_snake_identifier(text) {
        Some((
            format!("{what} name `{text}` is not a snake_case identifier"),
            "start with a lower-case letter; use lower-case letters, digits and underscores",
        ))
    } else if is_keyword(text) {
        Some((
            format!("{what} name `{text}` is a Rust keyword"),
            "choose another name (it becomes a generated Rust name)",
        ))
    } else if !seen.insert(text.to_owned()) {
        Some((
            format!("{what} `{text}` is declared twice"),
            "give each its own name",
        ))
    } else {
        None
    };
    match problem {
        Some((message, help)) => {
            r.report(code, line, message, help);
            false
        }
        None => true,
    }
}
