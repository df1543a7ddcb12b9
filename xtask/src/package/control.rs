//! The packages' metadata: version, maintainer, the control file, the changelog, the
//! copyright file, and the shared libraries a binary needs.

use super::{Arch, Package, stdout_of};
use anyhow::{Context, Result, bail};
use std::fmt::Write as _;
use std::path::Path;
use std::process::Command;

/// Who answers for the packages (the control file's Maintainer and the changelog's author).
pub const MAINTAINER: &str =
    "Anteater Electric Racing <Anteater-Electric-Racing@users.noreply.github.com>";
const HOMEPAGE: &str = "https://github.com/Anteater-Electric-Racing/aer";

/// What one build of the packages is.
pub struct Release {
    /// Debian version: the workspace's version, revision 1.
    pub version: String,
    /// The commit the packages are built from, for the changelog.
    pub commit: String,
    /// The commit's time (RFC 2822), the changelog's date.
    pub date: String,
    /// The commit's day (YYYY-MM-DD), the manual pages' date.
    pub day: String,
    /// The years the repository's history spans (`2024-2026`), for the copyright notice.
    pub years: String,
    /// The commit's time (Unix seconds): SOURCE_DATE_EPOCH, so that a rebuild of the same
    /// commit gives the same archive.
    pub epoch: String,
}

impl Release {
    pub fn from_repository(root: &Path) -> Result<Self> {
        let git = |args: &[&str]| stdout_of(Command::new("git").current_dir(root).args(args));
        let head = git(&["log", "-1", "--format=%h%n%aD%n%as%n%ct"])?;
        let mut fields = head.lines().map(str::to_owned);
        let mut field = || {
            fields
                .next()
                .context("git log gave fewer fields than asked")
        };
        let (commit, date, day, epoch) = (field()?, field()?, field()?, field()?);
        // Newest first: the last line is the first commit's year.
        let years = git(&["log", "--format=%ad", "--date=format:%Y"])?;
        Ok(Self {
            version: format!("{}-1", env!("CARGO_PKG_VERSION")),
            commit,
            date,
            day,
            epoch,
            years: span(&years)?,
        })
    }
}

/// `first-last` (or one year) from commit years listed newest first.
fn span(years: &str) -> Result<String> {
    let years: Vec<u32> = years
        .lines()
        .filter_map(|y| y.trim().parse().ok())
        .collect();
    let last = *years.first().context("git log gave no commit year")?;
    let first = years.last().copied().unwrap_or(last);
    Ok(if first == last {
        last.to_string()
    } else {
        format!("{first}-{last}")
    })
}

/// DEBIAN/control of `package`.
pub fn control(
    package: &Package,
    arch: Option<Arch>,
    release: &Release,
    libraries: &[String],
    installed_kib: u64,
) -> String {
    let mut depends: Vec<String> = libraries.to_vec();
    depends.extend(
        package
            .depends
            .split(',')
            .map(str::trim)
            .filter(|d| !d.is_empty())
            .map(|d| d.replace("${version}", &release.version)),
    );
    let mut text = String::new();
    let _ = writeln!(text, "Package: {}", package.name);
    let _ = writeln!(text, "Version: {}", release.version);
    let _ = writeln!(text, "Architecture: {}", arch.map_or("all", Arch::debian));
    let _ = writeln!(text, "Maintainer: {MAINTAINER}");
    let _ = writeln!(text, "Installed-Size: {installed_kib}");
    if !depends.is_empty() {
        let _ = writeln!(text, "Depends: {}", depends.join(", "));
    }
    if !package.recommends.is_empty() {
        let _ = writeln!(text, "Recommends: {}", package.recommends);
    }
    let _ = writeln!(text, "Section: {}", package.section);
    let _ = writeln!(text, "Priority: optional");
    let _ = writeln!(text, "Homepage: {HOMEPAGE}");
    let _ = writeln!(text, "Description: {}", package.summary);
    for paragraph in package.description.split("\n\n") {
        for line in wrap(paragraph, 79) {
            let _ = writeln!(text, " {line}");
        }
        let _ = writeln!(text, " .");
    }
    // The last paragraph needs no separator after it.
    match text.strip_suffix(" .\n") {
        Some(trimmed) => trimmed.to_owned(),
        None => text,
    }
}

/// The Debian changelog of one build (gzip it before installing).
pub fn changelog(package: &Package, release: &Release) -> String {
    format!(
        "{name} ({version}) unstable; urgency=medium\n\n  * Built from the car's repository at commit {commit}.\n\n -- {MAINTAINER}  {date}\n",
        name = package.name,
        version = release.version,
        commit = release.commit,
        date = release.date,
    )
}

/// The machine-readable copyright file: the project's licence, then every Rust crate the
/// package's binaries contain, with its own licence (from `cargo tree`).
pub fn copyright(
    root: &Path,
    package: &Package,
    arch: Option<Arch>,
    release: &Release,
) -> Result<String> {
    let mut text = format!(
        "Format: https://www.debian.org/doc/packaging-manuals/copyright-format/1.0/\n\
Upstream-Name: aer\n\
Upstream-Contact: {MAINTAINER}\n\
Source: {HOMEPAGE}\n\
\n\
Files: *\n\
Copyright: {years} Anteater Electric Racing\n\
License: MIT\n",
        years = release.years
    );
    // The crates compiled into the package's binaries (each binary is its own cargo
    // package's: `aer-raspi`, `aer-dashboard`).
    let mut crates = Vec::new();
    if let Some(arch) = arch {
        for entry in package.files {
            if let super::Source::Binary(binary) = entry.source {
                crates.extend(linked_crates(root, binary, arch)?);
            }
        }
    }
    crates.sort();
    crates.dedup();
    if !crates.is_empty() {
        text.push_str(
            "Comment: The binary also contains these Rust crates, each under its own licence\n \
(crate version: licence, as the crate declares it):\n .\n",
        );
        for line in crates {
            let _ = writeln!(text, " {line}");
        }
    }
    text.push_str(MIT);
    Ok(text)
}

const MIT: &str = "\nLicense: MIT
 Permission is hereby granted, free of charge, to any person obtaining a copy of
 this software and associated documentation files (the \"Software\"), to deal in
 the Software without restriction, including without limitation the rights to
 use, copy, modify, merge, publish, distribute, sublicense, and/or sell copies of
 the Software, and to permit persons to whom the Software is furnished to do so,
 subject to the following conditions:
 .
 The above copyright notice and this permission notice shall be included in all
 copies or substantial portions of the Software.
 .
 THE SOFTWARE IS PROVIDED \"AS IS\", WITHOUT WARRANTY OF ANY KIND, EXPRESS OR
 IMPLIED, INCLUDING BUT NOT LIMITED TO THE WARRANTIES OF MERCHANTABILITY, FITNESS
 FOR A PARTICULAR PURPOSE AND NONINFRINGEMENT. IN NO EVENT SHALL THE AUTHORS OR
 COPYRIGHT HOLDERS BE LIABLE FOR ANY CLAIM, DAMAGES OR OTHER LIABILITY, WHETHER
 IN AN ACTION OF CONTRACT, TORT OR OTHERWISE, ARISING FROM, OUT OF OR IN
 CONNECTION WITH THE SOFTWARE OR THE USE OR OTHER DEALINGS IN THE SOFTWARE.
";

/// `crate version: licence` of every crate linked into `package`'s binary for `arch`.
fn linked_crates(root: &Path, package: &str, arch: Arch) -> Result<Vec<String>> {
    let tree = stdout_of(
        crate::cargo()
            .current_dir(root)
            .args(["tree", "--package", package, "--edges", "normal"])
            .args(["--target", arch.rust_target(), "--prefix", "none"])
            .args(["--format", "{p}: {l}"]),
    )?;
    let mut lines: Vec<String> = tree
        .lines()
        // `(*)` marks a crate listed before; local crates show their path.
        .map(|line| line.trim_end_matches(" (*)").trim())
        .map(|line| match line.split_once(" (/") {
            Some((name, rest)) => {
                let licence = rest.rsplit_once(": ").map_or("", |(_, l)| l);
                format!("{name}: {licence}")
            }
            None => line.to_owned(),
        })
        .filter(|line| !line.is_empty())
        .collect();
    lines.sort();
    lines.dedup();
    Ok(lines)
}

/// The Depends entries for the shared libraries `binary` links: libc6 at the newest glibc
/// symbol version it uses, libgcc-s1 for the unwinder, zlib1g. Any other library is refused, so a
/// new dependency cannot reach the car without a line here.
pub fn libraries(binary: &Path) -> Result<Vec<String>> {
    let readelf = |flag: &str| {
        stdout_of(Command::new("readelf").args(["--wide", flag]).arg(binary))
            .with_context(|| format!("reading {} (binutils' readelf)", binary.display()))
    };
    let mut depends = Vec::new();
    let mut libc = false;
    for line in readelf("--dynamic")?.lines() {
        let Some(name) = line
            .split_once("Shared library: [")
            .and_then(|(_, rest)| rest.split_once(']'))
            .map(|(name, _)| name)
        else {
            continue;
        };
        match name {
            "libc.so.6"
            | "libm.so.6"
            | "libpthread.so.0"
            | "libdl.so.2"
            | "librt.so.1"
            | "ld-linux-aarch64.so.1"
            | "ld-linux-x86-64.so.2" => libc = true,
            "libgcc_s.so.1" => depends.push("libgcc-s1".to_owned()),
            // libz-sys links the system's zlib where its headers are installed (the build
            // machine), and builds its own copy otherwise (the arm64 cross build).
            "libz.so.1" => depends.push("zlib1g".to_owned()),
            other => bail!(
                "{} links {other}: add its Debian package to xtask/src/package/control.rs",
                binary.display()
            ),
        }
    }
    if libc {
        let newest = readelf("--version-info")?
            .split_whitespace()
            .filter_map(|word| word.strip_prefix("GLIBC_"))
            .filter_map(|v| {
                let mut parts = v.split('.').map(|p| p.parse::<u32>().ok());
                Some((parts.next()??, parts.next().flatten().unwrap_or(0)))
            })
            .max();
        depends.insert(
            0,
            match newest {
                Some((major, minor)) => format!("libc6 (>= {major}.{minor})"),
                None => "libc6".to_owned(),
            },
        );
    }
    depends.dedup();
    Ok(depends)
}

/// Words of `text` in lines of at most `width` characters (a longer word stands alone).
fn wrap(text: &str, width: usize) -> Vec<String> {
    let mut lines = Vec::new();
    let mut line = String::new();
    for word in text.split_whitespace() {
        if !line.is_empty() && line.len() + 1 + word.len() > width {
            lines.push(std::mem::take(&mut line));
        }
        if !line.is_empty() {
            line.push(' ');
        }
        line.push_str(word);
    }
    if !line.is_empty() {
        lines.push(line);
    }
    lines
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn descriptions_wrap_within_the_width_and_keep_every_word() {
        let text = "one two three four five six seven eight nine ten eleven twelve";
        let lines = wrap(text, 14);
        assert!(lines.iter().all(|l| l.len() <= 14), "{lines:?}");
        assert_eq!(lines.join(" "), text);
        assert_eq!(wrap("a-very-long-word x", 5), ["a-very-long-word", "x"]);
    }

    #[test]
    fn the_control_file_has_every_field_and_paragraphs_separated() {
        let release = Release {
            version: "0.1.0-1".into(),
            commit: "abc1234".into(),
            date: "Tue, 24 Nov 2026 08:00:00 +0000".into(),
            day: "2026-11-24".into(),
            years: "2025-2026".into(),
            epoch: "1795507200".into(),
        };
        let package = super::super::PACKAGES
            .iter()
            .find(|package| package.name == "aer-car-display")
            .expect("the car display's package");
        let text = control(package, None, &release, &[], 12);
        assert!(text.contains("Architecture: all\n"), "{text}");
        assert!(text.contains("aer-dashboard (>= 0.1.0-1)"), "{text}");
        assert!(text.contains("Installed-Size: 12\n"), "{text}");
        assert!(!text.contains("${"), "{text}");
        // Continuation lines start with a space, and the description ends without a " .".
        let description = text.split_once("Description: ").unwrap().1;
        assert!(description.lines().skip(1).all(|l| l.starts_with(' ')));
        assert!(!text.ends_with(" .\n"), "{text}");
        // The extended description fits an 80-column terminal (lintian's limit).
        assert!(description.lines().all(|l| l.len() <= 80), "{text}");
    }
}
