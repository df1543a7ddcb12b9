//! Render: the model -> source files, through askama templates (one per output).

pub mod codec;
pub mod standalone;

/// Formats a float as a Rust literal that reads back to exactly the same value.
pub fn float_lit(v: f64) -> String {
    let s = format!("{v:?}");
    if s.contains(['.', 'e', 'E', 'N', 'i']) {
        s
    } else {
        format!("{s}.0")
    }
}

/// Splits a schema comment into doc-comment lines.
pub fn doc_lines(text: &str) -> Vec<String> {
    text.lines().map(|l| l.trim_end().to_owned()).collect()
}
