//! Lays out one package's tree (files, modes, DEBIAN/) and turns it into a .deb.

use super::control::{self, Release};
use super::{Arch, Package, Source, binary_dir, stdout_of};
use anyhow::{Context, Result, bail};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::io::Write as _;
use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

/// A staged package, ready for `dpkg-deb`.
pub struct Staged {
    dir: PathBuf,
    file_name: String,
    installed_kib: u64,
}

/// A written package.
pub struct Deb {
    pub file_name: String,
    pub bytes: u64,
    pub installed_kib: u64,
}

/// Gzipped manual pages by binary name.
pub type Manuals = BTreeMap<&'static str, Vec<u8>>;

/// Lays out `package` (for `arch`, or `Architecture: all`) under `out/stage/`.
pub fn stage(
    root: &Path,
    out: &Path,
    package: &Package,
    arch: Option<Arch>,
    release: &Release,
    manuals: &Manuals,
) -> Result<Staged> {
    let arch_name = arch.map_or("all", Arch::debian);
    let dir = out
        .join("stage")
        .join(format!("{}_{arch_name}", package.name));
    if dir.exists() {
        std::fs::remove_dir_all(&dir).with_context(|| format!("clearing {}", dir.display()))?;
    }
    let mut libraries = Vec::new();
    for entry in package.files {
        let bytes = match entry.source {
            Source::Binary(name) => {
                let Some(arch) = arch else {
                    bail!("{}: an `all` package cannot carry binaries", package.name);
                };
                let path = binary_dir(root, arch).join(name);
                libraries.extend(control::libraries(&path)?);
                read(&path)?
            }
            Source::File(path) => read(&root.join(path))?,
            Source::PiConfig => pi_config(&String::from_utf8_lossy(&read(
                &root.join("raspi/config/aer-raspi.toml"),
            )?))?
            .into_bytes(),
            Source::Readme => read(&root.join("docs/pi-package.md"))?,
        };
        put(&dir, entry.path, &bytes, entry.executable)?;
    }
    let doc = format!("usr/share/doc/{}", package.name);
    let copyright = control::copyright(root, package, arch, release)?;
    put(
        &dir,
        &format!("{doc}/copyright"),
        copyright.as_bytes(),
        false,
    )?;
    let changelog = gzip(control::changelog(package, release).as_bytes())?;
    put(
        &dir,
        &format!("{doc}/changelog.Debian.gz"),
        &changelog,
        false,
    )?;
    for (binary, _) in package.manuals {
        let page = manuals
            .get(binary)
            .with_context(|| format!("no manual page for {binary}"))?;
        put(
            &dir,
            &format!("usr/share/man/man1/{binary}.1.gz"),
            page,
            false,
        )?;
    }

    let tree = walk(&dir)?;
    let files: Vec<String> = tree.files.iter().map(|(path, _)| path.clone()).collect();
    let installed_kib = tree
        .files
        .iter()
        .map(|(_, bytes)| bytes.div_ceil(1024))
        .sum::<u64>()
        + tree.dirs.len() as u64;
    libraries.dedup();

    let debian = dir.join("DEBIAN");
    let control_text = control::control(package, arch, release, &libraries, installed_kib);
    put(&dir, "DEBIAN/control", control_text.as_bytes(), false)?;
    put(&dir, "DEBIAN/md5sums", &md5sums(&dir, &files)?, false)?;
    let conffiles: String = files
        .iter()
        .filter(|path| path.starts_with("etc/"))
        .map(|path| format!("/{path}\n"))
        .collect();
    if !conffiles.is_empty() {
        put(&dir, "DEBIAN/conffiles", conffiles.as_bytes(), false)?;
    }
    for script in ["postinst", "prerm", "postrm"] {
        let source = root.join(format!("packaging/pi/{}.{script}", package.name));
        if source.exists() {
            put(&dir, &format!("DEBIAN/{script}"), &read(&source)?, true)?;
        }
    }
    // Directories 0755, whatever the umask.
    for folder in tree.dirs.iter().chain([&dir, &debian]) {
        std::fs::set_permissions(folder, std::fs::Permissions::from_mode(0o755))
            .with_context(|| format!("setting the mode of {}", folder.display()))?;
    }
    Ok(Staged {
        dir,
        file_name: format!("{}_{}_{arch_name}.deb", package.name, release.version),
        installed_kib,
    })
}

/// Builds the .deb of `staged` in `out`.
pub fn build_deb(staged: &Staged, out: &Path, release: &Release) -> Result<Deb> {
    let target = out.join(&staged.file_name);
    let status = Command::new("dpkg-deb")
        .env("SOURCE_DATE_EPOCH", &release.epoch)
        .args(["--root-owner-group", "-Zxz", "--build"])
        .arg(&staged.dir)
        .arg(&target)
        .stdout(Stdio::null())
        .status()
        .context("running dpkg-deb")?;
    if !status.success() {
        bail!("dpkg-deb could not build {}", staged.file_name);
    }
    Ok(Deb {
        file_name: staged.file_name.clone(),
        bytes: std::fs::metadata(&target)?.len(),
        installed_kib: staged.installed_kib,
    })
}

/// The service's configuration as installed on the Pi: the shipped defaults with the store
/// and the raw log in /var/lib/aer and the broker's configuration in /etc/aer. Every key it
/// changes must be found exactly once, so a reworded default cannot slip through unchanged.
pub fn pi_config(defaults: &str) -> Result<String> {
    const CHANGES: [(&str, &str); 3] = [
        (
            "path = \"aer-local.sqlite\"",
            "path = \"/var/lib/aer/store.sqlite\"",
        ),
        ("dir = \"aer-raw\"", "dir = \"/var/lib/aer/raw\""),
        (
            "# config = \"/etc/aer/rumqttd.toml\"",
            "config = \"/etc/aer/rumqttd.toml\"",
        ),
    ];
    let mut text = String::from(
        "# Installed by the aer-raspi package (a conffile: your changes are kept on upgrade).\n\
# The service (systemctl status aer-raspi) reads it; the store and the raw log live in\n\
# /var/lib/aer. Apply a change: sudo systemctl restart aer-raspi\n#\n",
    );
    let mut found = [0; CHANGES.len()];
    for line in defaults.lines() {
        let change = CHANGES.iter().position(|(from, _)| line.trim() == *from);
        match change {
            Some(index) => {
                found[index] += 1;
                text.push_str(CHANGES[index].1);
            }
            None => text.push_str(line),
        }
        text.push('\n');
    }
    for ((from, _), found) in CHANGES.iter().zip(found) {
        if found != 1 {
            bail!("raspi/config/aer-raspi.toml: expected one line `{from}`, found {found}");
        }
    }
    Ok(text)
}

/// Manual pages (section 1) of every packaged binary, from the build machine's binaries:
/// the command's --help, then each subcommand's.
pub fn manuals(bin_dir: &Path, release: &Release, packages: &[Package]) -> Result<Manuals> {
    let mut pages = Manuals::new();
    for (binary, summary) in packages.iter().flat_map(|p| p.manuals) {
        let path = bin_dir.join(binary);
        let help = |args: &[&str]| stdout_of(Command::new(&path).args(args).arg("--help"));
        let top = help(&[])?;
        let mut page = String::new();
        let _ = writeln!(
            page,
            ".TH {} 1 \"{}\" \"{binary} {}\" \"AER car software\"",
            binary.to_uppercase(),
            release.day,
            release.version
        );
        let _ = writeln!(page, ".SH NAME\n{} \\- {}", binary, roff(summary));
        let _ = writeln!(page, ".SH DESCRIPTION");
        literal(&mut page, &top);
        let commands = subcommands(&top);
        if !commands.is_empty() {
            let _ = writeln!(page, ".SH COMMANDS");
            for command in commands {
                let _ = writeln!(page, ".SS \"{binary} {command}\"");
                literal(&mut page, &help(&[command.as_str()])?);
            }
        }
        let _ = writeln!(page, ".SH SEE ALSO\n/usr/share/doc/{binary}/README.md");
        pages.insert(binary, gzip(page.as_bytes())?);
    }
    Ok(pages)
}

/// The subcommands clap lists under `Commands:` (without `help`).
fn subcommands(help: &str) -> Vec<String> {
    help.lines()
        .skip_while(|line| line.trim() != "Commands:")
        .skip(1)
        .take_while(|line| line.starts_with("  "))
        .filter(|line| !line.starts_with("   "))
        .filter_map(|line| line.split_whitespace().next())
        .filter(|name| *name != "help")
        .map(str::to_owned)
        .collect()
}

/// `text` as preformatted roff.
fn literal(page: &mut String, text: &str) {
    page.push_str(".nf\n");
    for line in text.trim_end().lines() {
        let _ = writeln!(page, "{}", roff(line));
    }
    page.push_str(".fi\n");
}

/// One line of text, safe in roff: backslashes escaped, a leading `.` or `'` neutralised,
/// hyphens written as the minus sign command options are.
fn roff(line: &str) -> String {
    let escaped = line.replace('\\', "\\e").replace('-', "\\-");
    if escaped.starts_with('.') || escaped.starts_with('\'') {
        format!("\\&{escaped}")
    } else {
        escaped
    }
}

fn read(path: &Path) -> Result<Vec<u8>> {
    std::fs::read(path).with_context(|| format!("reading {}", path.display()))
}

/// Writes `bytes` to `dir/path`, 0755 if executable, 0644 otherwise.
fn put(dir: &Path, path: &str, bytes: &[u8], executable: bool) -> Result<()> {
    let target = dir.join(path);
    if let Some(parent) = target.parent() {
        std::fs::create_dir_all(parent)
            .with_context(|| format!("creating {}", parent.display()))?;
    }
    std::fs::write(&target, bytes).with_context(|| format!("writing {}", target.display()))?;
    let mode = if executable { 0o755 } else { 0o644 };
    std::fs::set_permissions(&target, std::fs::Permissions::from_mode(mode))
        .with_context(|| format!("setting the mode of {}", target.display()))
}

/// What a staged package holds (its DEBIAN folder aside).
struct Tree {
    /// Every file, relative to the package's root, sorted, with its size.
    files: Vec<(String, u64)>,
    /// Every folder below the root.
    dirs: Vec<PathBuf>,
}

fn walk(dir: &Path) -> Result<Tree> {
    let mut tree = Tree {
        files: Vec::new(),
        dirs: Vec::new(),
    };
    let mut pending = vec![dir.to_path_buf()];
    while let Some(current) = pending.pop() {
        for entry in std::fs::read_dir(&current)? {
            let entry = entry?;
            let path = entry.path();
            if entry.file_type()?.is_dir() {
                if path != dir.join("DEBIAN") {
                    tree.dirs.push(path.clone());
                    pending.push(path);
                }
            } else if let Ok(relative) = path.strip_prefix(dir) {
                let bytes = entry.metadata()?.len();
                tree.files
                    .push((relative.to_string_lossy().into_owned(), bytes));
            }
        }
    }
    tree.files.sort();
    Ok(tree)
}

fn md5sums(dir: &Path, files: &[String]) -> Result<Vec<u8>> {
    stdout_of(
        Command::new("md5sum")
            .current_dir(dir)
            .arg("--")
            .args(files),
    )
    .map(String::into_bytes)
}

/// gzip -9n: no name or time in the header, so the same input gives the same bytes.
fn gzip(bytes: &[u8]) -> Result<Vec<u8>> {
    let mut child = Command::new("gzip")
        .args(["-9n", "-c"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .context("running gzip")?;
    child
        .stdin
        .take()
        .context("gzip's input")?
        .write_all(bytes)?;
    let output = child.wait_with_output()?;
    if !output.status.success() {
        bail!("gzip failed");
    }
    Ok(output.stdout)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_pi_config_moves_the_data_to_var_lib_and_reads_the_broker_config_from_etc() {
        let defaults = std::fs::read_to_string(
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../raspi/config/aer-raspi.toml"),
        )
        .unwrap();
        let pi = pi_config(&defaults).unwrap();
        for line in [
            "path = \"/var/lib/aer/store.sqlite\"",
            "dir = \"/var/lib/aer/raw\"",
            "config = \"/etc/aer/rumqttd.toml\"",
        ] {
            assert_eq!(pi.lines().filter(|l| l.trim() == line).count(), 1, "{line}");
        }
        assert!(!pi.contains("aer-local.sqlite") && !pi.contains("\"aer-raw\""));
        // Everything else is the shipped defaults, line for line.
        assert_eq!(pi.lines().count(), defaults.lines().count() + 4);
        let error = pi_config("car_id = \"car1\"\n").unwrap_err();
        assert!(error.to_string().contains("aer-local.sqlite"), "{error}");
    }

    #[test]
    fn subcommands_are_read_from_clap_help() {
        let help = "Usage: x <COMMAND>\n\nCommands:\n  run       Live\n  replay    Replay a log\n            through the pipeline\n  help      Print this\n\nOptions:\n  -h\n";
        assert_eq!(subcommands(help), ["run", "replay"]);
    }

    #[test]
    fn roff_lines_cannot_become_requests() {
        assert_eq!(roff(".start"), "\\&.start");
        assert_eq!(roff("'quote"), "\\&'quote");
        assert_eq!(roff("a\\b --fast"), "a\\eb \\-\\-fast");
    }
}
