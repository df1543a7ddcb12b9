//! `cargo xtask pi-package`: the Debian packages that put the Pi service and the dashboard on
//! the car's Raspberry Pi 5 (arm64, cross-compiled with Debian's aarch64 toolchain) and on a
//! pit laptop (amd64).
//!
//! - `aer-tools` (per architecture): the `aer-raspi` program alone, for a pit laptop that
//!   exports, lists or replays sessions without running the service.
//! - `aer-raspi` (all architectures, with `aer-tools`): the ingest service, its systemd unit
//!   (user `aer`, hardened), the CAN links at 500 kbit/s through systemd-networkd, the CAN
//!   modules loaded at boot, its configuration in `/etc/aer/` and its data in `/var/lib/aer/`.
//! - `aer-dashboard`: the driver and pit views, a systemd user unit for the car's display and a
//!   menu entry for the pit view.
//! - `aer-car-display` (all architectures): starts the driver display full-screen when the Pi's
//!   desktop session starts. The car installs it; a pit laptop does not.
//!
//! The packages are built with `dpkg-deb` from a staged tree, so nothing beyond Debian's own
//! tools is needed; the files they carry live in `packaging/pi/`.

mod control;
mod stage;

use crate::{cargo, workspace_root};
use anyhow::{Context, Result, bail};
use std::path::{Path, PathBuf};
use std::process::Command;

/// A Debian architecture and the Rust target that builds for it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Arch {
    /// The car's Raspberry Pi 5.
    Arm64,
    /// A pit laptop (and the build machine).
    Amd64,
}

impl Arch {
    pub fn debian(self) -> &'static str {
        match self {
            Arch::Arm64 => "arm64",
            Arch::Amd64 => "amd64",
        }
    }

    pub fn rust_target(self) -> &'static str {
        match self {
            Arch::Arm64 => "aarch64-unknown-linux-gnu",
            Arch::Amd64 => "x86_64-unknown-linux-gnu",
        }
    }
}

/// The cargo profile the packaged binaries are built with (release, stripped).
const PROFILE: &str = "pi-package";

/// Where a packaged file comes from.
#[derive(Debug, Clone, Copy)]
enum Source {
    /// A binary of the workspace, built for the package's architecture.
    Binary(&'static str),
    /// A file of the repository, as it is.
    File(&'static str),
    /// The service's configuration with the Pi's paths (see [`pi_config`]).
    PiConfig,
    /// The package's documentation: docs/pi-package.md.
    Readme,
}

/// One file of a package.
#[derive(Debug, Clone, Copy)]
struct Entry {
    /// Path inside the package, without the leading `/`.
    path: &'static str,
    source: Source,
    executable: bool,
}

const fn file(path: &'static str, source: &'static str) -> Entry {
    Entry {
        path,
        source: Source::File(source),
        executable: false,
    }
}

/// One binary package.
struct Package {
    name: &'static str,
    /// Built per architecture (`false`: `Architecture: all`).
    binary: bool,
    depends: &'static str,
    recommends: &'static str,
    section: &'static str,
    summary: &'static str,
    description: &'static str,
    files: &'static [Entry],
    /// Binaries that get a manual page (section 1) from their `--help`.
    manuals: &'static [(&'static str, &'static str)],
}

const PACKAGES: [Package; 4] = [
    Package {
        name: "aer-tools",
        binary: true,
        depends: "",
        recommends: "",
        section: "utils",
        summary: "AER car data tools: sessions, exports and raw logs without the service",
        description: "The aer-raspi program alone: list the sessions of a store copied off the \
car, export them as MCAP, Parquet and CSV, decode a raw log or a candump log, replay one. \
It starts no service: a pit laptop installs it beside aer-dashboard.\n\
\n\
On the car, package aer-raspi runs the same program as the ingest service.",
        files: &[
            Entry {
                path: "usr/bin/aer-raspi",
                source: Source::Binary("aer-raspi"),
                executable: true,
            },
            Entry {
                path: "usr/share/doc/aer-tools/README.md",
                source: Source::Readme,
                executable: false,
            },
            file("usr/share/doc/aer-tools/test-day.md", "docs/test-day.md"),
            file(
                "usr/share/lintian/overrides/aer-tools",
                "packaging/pi/aer-tools.lintian-overrides",
            ),
        ],
        manuals: &[(
            "aer-raspi",
            "the car's data ingest service and its session, export and raw log tools",
        )],
    },
    Package {
        name: "aer-raspi",
        binary: false,
        depends: "adduser, aer-tools (= ${version})",
        recommends: "",
        section: "net",
        summary: "AER car data ingest: CAN/ISO-TP to MQTT, local store and raw log",
        description: "Reads the car's CAN buses (can0, can1) and the central computer's ISO-TP \
telemetry, decodes them with the code generated from the car's schema, publishes every packet \
and frame on an embedded MQTT broker, keeps them in a local SQLite store and a raw log of every \
frame, and forwards the store to TDengine when one is configured.\n\
\n\
The package runs it (the program from aer-tools) as the systemd service aer-raspi (user aer, \
data in /var/lib/aer, configuration in /etc/aer) and brings the CAN links up at 500 kbit/s \
through systemd-networkd.",
        files: &[
            file(
                "usr/lib/systemd/system/aer-raspi.service",
                "packaging/pi/aer-raspi.service",
            ),
            file(
                "usr/lib/systemd/network/80-aer-can.network",
                "packaging/pi/80-aer-can.network",
            ),
            file(
                "usr/lib/modules-load.d/aer-can.conf",
                "packaging/pi/aer-can.conf",
            ),
            file(
                "usr/lib/sysctl.d/60-aer-can.conf",
                "packaging/pi/60-aer-can.conf",
            ),
            Entry {
                path: "etc/aer/aer-raspi.toml",
                source: Source::PiConfig,
                executable: false,
            },
            file("etc/aer/rumqttd.toml", "raspi/config/rumqttd.toml"),
            Entry {
                path: "usr/share/doc/aer-raspi/README.md",
                source: Source::Readme,
                executable: false,
            },
            file(
                "usr/share/doc/aer-raspi/pi-service.md",
                "docs/pi-service.md",
            ),
            file(
                "usr/share/lintian/overrides/aer-raspi",
                "packaging/pi/aer-raspi.lintian-overrides",
            ),
        ],
        manuals: &[],
    },
    Package {
        name: "aer-dashboard",
        binary: true,
        // winit opens these at run time (dlopen): the keyboard always, then Wayland or X11.
        depends: "libxkbcommon0",
        recommends: "libwayland-client0, libwayland-cursor0, libx11-6, libx11-xcb1, libxcursor1, libxi6, libxrandr2, libxkbcommon-x11-0",
        section: "misc",
        summary: "AER driver display and pit view of the car's telemetry",
        description: "Shows the car's live telemetry from the Pi's MQTT broker: the driver's \
display (speed, state of charge, faults, laps) and the pit crew's view (every field, plots, \
the ingest service's health). Labels, units and limits come from the car's schema.\n\
\n\
The pit view is in the desktop menu; on the car, package aer-car-display starts the driver's \
display full-screen.",
        files: &[
            Entry {
                path: "usr/bin/aer-dashboard",
                source: Source::Binary("aer-dashboard"),
                executable: true,
            },
            file(
                "etc/aer/aer-dashboard.toml",
                "dashboard/config/aer-dashboard.toml",
            ),
            file(
                "usr/lib/systemd/user/aer-dashboard.service",
                "packaging/pi/aer-dashboard.service",
            ),
            file(
                "usr/share/applications/aer-dashboard.desktop",
                "packaging/pi/aer-dashboard.desktop",
            ),
            Entry {
                path: "usr/share/doc/aer-dashboard/README.md",
                source: Source::Readme,
                executable: false,
            },
            file(
                "usr/share/doc/aer-dashboard/dashboard.md",
                "docs/dashboard.md",
            ),
            file(
                "usr/share/lintian/overrides/aer-dashboard",
                "packaging/pi/aer-dashboard.lintian-overrides",
            ),
        ],
        manuals: &[(
            "aer-dashboard",
            "driver display and pit view of the car's telemetry",
        )],
    },
    Package {
        name: "aer-car-display",
        binary: false,
        depends: "aer-dashboard (>= ${version}), aer-raspi (>= ${version}), systemd",
        recommends: "",
        section: "misc",
        summary: "starts the AER driver display full-screen on the car's screen",
        description: "Starts the driver's display (aer-dashboard, full-screen, driver view) \
in the Pi's desktop session as the systemd user service aer-dashboard, which restarts it if \
it ever stops. Install it on the car, not on a pit laptop.",
        files: &[
            file(
                "etc/xdg/autostart/aer-car-display.desktop",
                "packaging/pi/aer-car-display.desktop",
            ),
            Entry {
                path: "usr/libexec/aer/aer-car-display",
                source: Source::File("packaging/pi/aer-car-display"),
                executable: true,
            },
            Entry {
                path: "usr/share/doc/aer-car-display/README.md",
                source: Source::Readme,
                executable: false,
            },
            file(
                "usr/share/lintian/overrides/aer-car-display",
                "packaging/pi/aer-car-display.lintian-overrides",
            ),
        ],
        manuals: &[],
    },
];

/// Builds the binaries for `arches` and writes every package into `out`.
pub fn run(arches: &[Arch], out: &Path) -> Result<()> {
    let root = workspace_root();
    let out = if out.is_absolute() {
        out.to_path_buf()
    } else {
        root.join(out)
    };
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let release = control::Release::from_repository(&root)?;
    // The manual pages are made from the build machine's binaries' --help (the same text on
    // every architecture), so amd64 is always built.
    let mut builds = vec![Arch::Amd64];
    builds.extend(arches.iter().copied().filter(|a| *a != Arch::Amd64));
    for arch in &builds {
        build_binaries(&root, *arch)?;
    }
    let manuals = stage::manuals(&binary_dir(&root, Arch::Amd64), &release, &PACKAGES)?;
    let mut written = Vec::new();
    for package in &PACKAGES {
        let targets: Vec<Option<Arch>> = if package.binary {
            arches.iter().copied().map(Some).collect()
        } else {
            vec![None]
        };
        for arch in targets {
            let staged = stage::stage(&root, &out, package, arch, &release, &manuals)?;
            written.push(stage::build_deb(&staged, &out, &release)?);
        }
    }
    println!(
        "{:<52} {:>12} {:>14}",
        "package", "size (B)", "installed (KiB)"
    );
    for deb in &written {
        println!(
            "{:<52} {:>12} {:>14}",
            deb.file_name, deb.bytes, deb.installed_kib
        );
    }
    Ok(())
}

/// Runs `command` and returns what it printed; fails with what it said on stderr.
fn stdout_of(command: &mut Command) -> Result<String> {
    let program = command.get_program().to_string_lossy().into_owned();
    let output = command
        .output()
        .with_context(|| format!("running {program}"))?;
    if !output.status.success() {
        bail!(
            "{program} failed: {}",
            String::from_utf8_lossy(&output.stderr).trim()
        );
    }
    Ok(String::from_utf8_lossy(&output.stdout).into_owned())
}

/// Where cargo leaves the packaged binaries for `arch`.
fn binary_dir(root: &Path, arch: Arch) -> PathBuf {
    crate::target_dir(root)
        .join(arch.rust_target())
        .join(PROFILE)
}

fn build_binaries(root: &Path, arch: Arch) -> Result<()> {
    let mut command = cargo();
    command
        .current_dir(root)
        .args([
            "build",
            "--profile",
            PROFILE,
            "--target",
            arch.rust_target(),
        ])
        .args(["--package", "aer-raspi", "--bin", "aer-raspi"])
        .args(["--package", "aer-dashboard", "--bin", "aer-dashboard"]);
    if arch == Arch::Arm64 {
        // Debian's cross toolchain (gcc-aarch64-linux-gnu) links the binaries and compiles
        // the C inside them (SQLite, ring, zstd).
        let gcc = "aarch64-linux-gnu-gcc";
        if Command::new(gcc).arg("--version").output().is_err() {
            bail!("{gcc} not found: apt-get install gcc-aarch64-linux-gnu libc6-dev-arm64-cross");
        }
        command
            .env("CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_LINKER", gcc)
            .env("CC_aarch64_unknown_linux_gnu", gcc)
            .env("AR_aarch64_unknown_linux_gnu", "aarch64-linux-gnu-ar");
    }
    let status = command.status().context("running cargo build")?;
    if !status.success() {
        bail!("building the {} binaries failed", arch.debian());
    }
    Ok(())
}
