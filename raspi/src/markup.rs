//! Text inside XML and HTML (the MF4 header's comment, the tools' layouts, the run report):
//! the five characters markup gives a meaning, escaped once, here.

/// `text` with `&`, `<`, `>`, `"` escaped, fit for an element or an attribute.
pub fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

#[cfg(test)]
mod tests {
    #[test]
    fn markup_characters_are_escaped_and_the_rest_kept() {
        assert_eq!(
            super::escape(r#"a <b> & "c" °C"#),
            "a &lt;b&gt; &amp; &quot;c&quot; °C"
        );
    }
}
