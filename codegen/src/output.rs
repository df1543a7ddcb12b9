//! Writing generated files: formatted with rustfmt, written only when the content changed and
//! atomically (temp file + rename), so a build never leaves a half-written source behind and an
//! unchanged schema leaves file times alone (no needless rebuilds).

use std::io::Write;
use std::path::Path;
use std::process::{Command, Stdio};

/// Formats Rust source with the toolchain's rustfmt. Without rustfmt the text is returned as
/// rendered and `formatted` is false.
pub(crate) fn rustfmt(source: &str) -> (String, bool) {
    let child = Command::new(std::env::var("RUSTFMT").unwrap_or_else(|_| "rustfmt".into()))
        .args(["--edition", "2024", "--emit", "stdout", "--quiet"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn();
    let Ok(mut child) = child else {
        return (source.to_owned(), false);
    };
    if let Some(mut stdin) = child.stdin.take() {
        if stdin.write_all(source.as_bytes()).is_err() {
            return (source.to_owned(), false);
        }
    }
    match child.wait_with_output() {
        Ok(out) if out.status.success() => match String::from_utf8(out.stdout) {
            Ok(s) => (s, true),
            Err(_) => (source.to_owned(), false),
        },
        _ => (source.to_owned(), false),
    }
}

/// Writes `content` to `path` unless it already holds exactly that. Returns whether it wrote.
pub(crate) fn write_if_changed(path: &Path, content: &str) -> std::io::Result<bool> {
    if std::fs::read(path).is_ok_and(|old| old == content.as_bytes()) {
        return Ok(false);
    }
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir)?;
    }
    let file_name = path
        .file_name()
        .and_then(|n| n.to_str())
        .unwrap_or("generated");
    let tmp = path.with_file_name(format!(".{file_name}.tmp{}", std::process::id()));
    std::fs::write(&tmp, content)?;
    std::fs::rename(&tmp, path).inspect_err(|_| {
        let _ = std::fs::remove_file(&tmp);
    })?;
    Ok(true)
}
