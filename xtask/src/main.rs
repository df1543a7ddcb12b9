//! Project tasks that need more than `cargo build`: `cargo xtask firmware` builds the
//! flashable images, `cargo xtask m7-check` runs the portable code on an emulated Cortex-M7,
//! `cargo xtask docs` rewrites the documentation's quoted transcripts, `cargo xtask
//! pi-package` builds the Debian packages for the car's Pi and a pit laptop.

mod docs;
mod ihex;
mod image;
mod m7_check;
mod package;
mod pins;
mod sheet;

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand};
use image::{FLASH_T40, FLASH_T41, FLEXRAM_BYTES, Image, RAM, Region};
use std::path::{Path, PathBuf};
use std::process::Command;

/// The firmware target of both Teensys.
const TARGET: &str = "thumbv7em-none-eabihf";

#[derive(Parser)]
#[command(about = "Project tasks: firmware images, Cortex-M7 checks, the Pi's Debian packages")]
struct Cli {
    #[command(subcommand)]
    task: Task,
}

#[derive(Subcommand)]
enum Task {
    /// Build the firmware (release): the race images (the CCM for the comp car's DTI), the
    /// bench bring-up images of both boards, the CCM for the HIMaC bench's IFL100 and both
    /// CCM images for the ADS1115 pedal board, written as target/firmware/{ccm,pcc,
    /// ccm-bringup,pcc-bringup,ccm-ifl100,ccm-ads1115,ccm-bringup-ads1115}.hex (and .elf) for
    /// teensy_loader_cli, printing flash and RAM use.
    Firmware,
    /// Print the default boards' pin maps (aer-boards), one line per signal:
    /// `<board> <pin> <signal> <mode>`.
    Pins {
        /// Print the Markdown table of docs/firmware.md instead, with each pin's source.
        #[arg(long)]
        markdown: bool,
    },
    /// Record a driving session of the CCM logic as a candump log (raspi/data/session.log, the
    /// Pi demo's input).
    SessionLog,
    /// Rewrite the console transcripts docs/bench-day.md quotes from the code that prints them
    /// (every quote at once; the doc test then passes).
    Docs,
    /// Run the portable code (codec, telemetry packer, PCC logic) on an emulated Cortex-M7
    /// (qemu-system-arm, mps2-an500) and require the same transcript as on the host.
    M7Check {
        /// Seconds QEMU may run before the check fails.
        #[arg(long, default_value_t = 300)]
        timeout: u64,
    },
    /// Build the Debian packages of the Pi service and the dashboard (aer-raspi,
    /// aer-dashboard, aer-car-display) for the car's Pi (arm64) and a pit laptop (amd64).
    PiPackage {
        /// The architectures (default: both).
        #[arg(long = "arch", value_enum)]
        arches: Vec<package::Arch>,
        /// Where the .deb files go.
        #[arg(long, default_value = "target/pi-package")]
        out: PathBuf,
    },
}

/// A firmware image to build.
struct Firmware {
    /// Image name.
    name: &'static str,
    /// Binary name.
    bin: &'static str,
    /// Cargo package.
    package: &'static str,
    /// Cargo features.
    features: &'static str,
    /// Board.
    board: &'static str,
    /// The board's flash.
    flash: Region,
}

const FIRMWARE: [Firmware; 7] = [
    Firmware {
        name: "ccm",
        bin: "ccm",
        package: "aer-ccm",
        features: "firmware",
        board: "Teensy 4.1, comp car (DTI HV-550)",
        flash: FLASH_T41,
    },
    Firmware {
        name: "pcc",
        bin: "pcc",
        package: "aer-pcc",
        features: "firmware",
        board: "Teensy 4.0",
        flash: FLASH_T40,
    },
    Firmware {
        name: "ccm-bringup",
        bin: "ccm-bringup",
        package: "aer-ccm",
        features: "firmware",
        board: "Teensy 4.1, bench bring-up",
        flash: FLASH_T41,
    },
    Firmware {
        name: "pcc-bringup",
        bin: "pcc-bringup",
        package: "aer-pcc",
        features: "firmware",
        board: "Teensy 4.0, bench bring-up",
        flash: FLASH_T40,
    },
    // Last: each feature change rebuilds only the CCM crate.
    Firmware {
        name: "ccm-ifl100",
        bin: "ccm",
        package: "aer-ccm",
        features: "firmware,inverter-ifl100",
        board: "Teensy 4.1, HIMaC bench (IFL100)",
        flash: FLASH_T41,
    },
    Firmware {
        name: "ccm-ads1115",
        bin: "ccm",
        package: "aer-ccm",
        features: "firmware,pedals-ads1115",
        board: "Teensy 4.1, comp car (DTI HV-550), pedals on an ADS1115",
        flash: FLASH_T41,
    },
    Firmware {
        name: "ccm-bringup-ads1115",
        bin: "ccm-bringup",
        package: "aer-ccm",
        features: "firmware,pedals-ads1115",
        board: "Teensy 4.1, bench bring-up, pedals on an ADS1115",
        flash: FLASH_T41,
    },
];

fn main() -> Result<()> {
    match Cli::parse().task {
        Task::Firmware => firmware(),
        Task::Pins { markdown } => {
            print!(
                "{}",
                if markdown {
                    pins::markdown()
                } else {
                    pins::listing()
                }
            );
            Ok(())
        }
        Task::Docs => docs::run(&workspace_root()),
        Task::SessionLog => {
            // The car model runs as an example: the firmware tasks never compile it.
            let path = workspace_root().join("raspi/data/session.log");
            let status = example(&workspace_root(), "session_log")?
                .arg(&path)
                .status()
                .context("running the session log")?;
            if !status.success() {
                bail!("recording the session failed");
            }
            Ok(())
        }
        Task::M7Check { timeout } => {
            ensure_target()?;
            m7_check::run(&workspace_root(), TARGET, timeout)
        }
        Task::PiPackage { arches, out } => {
            let arches = if arches.is_empty() {
                vec![package::Arch::Arm64, package::Arch::Amd64]
            } else {
                arches
            };
            package::run(&arches, &out)
        }
    }
}

fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map_or_else(|| PathBuf::from("."), Path::to_path_buf)
}

/// Cargo's build directory: `CARGO_TARGET_DIR` when set (relative to the workspace, as cargo
/// reads it), else `<workspace>/target`.
pub(crate) fn target_dir(root: &Path) -> PathBuf {
    match std::env::var_os("CARGO_TARGET_DIR") {
        Some(dir) if !dir.is_empty() => root.join(dir),
        _ => root.join("target"),
    }
}

/// The workspace example `name`, built with the workspace's examples (the features `cargo
/// build --workspace --all-targets` and the tests resolve, so after either nothing builds
/// again), ready to run.
pub(crate) fn example(root: &Path, name: &str) -> Result<Command> {
    let status = cargo()
        .current_dir(root)
        .args(["build", "--quiet", "--workspace", "--examples"])
        .status()
        .context("running cargo build")?;
    if !status.success() {
        bail!("building the workspace's examples failed");
    }
    let mut command = Command::new(target_dir(root).join("debug/examples").join(name));
    command.current_dir(root);
    Ok(command)
}

pub(crate) fn cargo() -> Command {
    Command::new(std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into()))
}

/// Installs the firmware target with rustup when it is missing, saying so (a fresh machine
/// has only the host's).
pub(crate) fn ensure_target() -> Result<()> {
    let installed = Command::new("rustup")
        .args(["target", "list", "--installed"])
        .output();
    let Ok(installed) = installed else {
        bail!(
            "rustup not found: install Rust with rustup (https://rustup.rs), then `rustup target add {TARGET}`"
        );
    };
    if String::from_utf8_lossy(&installed.stdout)
        .lines()
        .any(|line| line.trim() == TARGET)
    {
        return Ok(());
    }
    eprintln!("installing the firmware target: rustup target add {TARGET}");
    let status = Command::new("rustup")
        .args(["target", "add", TARGET])
        .status()
        .context("running rustup target add")?;
    if !status.success() {
        bail!("`rustup target add {TARGET}` failed: run it by hand, then again");
    }
    Ok(())
}

fn firmware() -> Result<()> {
    ensure_target()?;
    let root = workspace_root();
    let out_dir = target_dir(&root).join("firmware");
    std::fs::create_dir_all(&out_dir).with_context(|| format!("creating {}", out_dir.display()))?;
    for firmware in &FIRMWARE {
        let status = cargo()
            .current_dir(&root)
            .args([
                "build",
                "--release",
                "--target",
                TARGET,
                "--features",
                firmware.features,
            ])
            .args(["--package", firmware.package, "--bin", firmware.bin])
            .status()
            .context("running cargo build")?;
        if !status.success() {
            bail!("building the {} firmware failed", firmware.name);
        }
        let elf_path = target_dir(&root)
            .join(TARGET)
            .join("release")
            .join(firmware.bin);
        let elf =
            std::fs::read(&elf_path).with_context(|| format!("reading {}", elf_path.display()))?;
        // Kept beside the HEX file: two images share the `ccm` binary's build path.
        let kept_elf = out_dir.join(format!("{}.elf", firmware.name));
        std::fs::write(&kept_elf, &elf)
            .with_context(|| format!("writing {}", kept_elf.display()))?;
        let image = Image::read(&elf).with_context(|| format!("reading {}", elf_path.display()))?;
        if image.outside(firmware.flash) > 0 {
            bail!(
                "{}: {} loadable bytes lie outside flash; check the linker script",
                firmware.name,
                image.outside(firmware.flash)
            );
        }
        let chunks: Vec<(u32, &[u8])> = image
            .load
            .iter()
            .map(|(address, bytes)| (*address, bytes.as_slice()))
            .collect();
        let hex_path = out_dir.join(format!("{}.hex", firmware.name));
        std::fs::write(&hex_path, ihex::write(&chunks))
            .with_context(|| format!("writing {}", hex_path.display()))?;
        report(firmware, &image, &hex_path);
    }
    Ok(())
}

fn report(firmware: &Firmware, image: &Image, hex_path: &Path) {
    let flash = image.flash_bytes(firmware.flash);
    println!(
        "{} ({}): {}",
        firmware.name,
        firmware.board,
        hex_path.display()
    );
    println!(
        "  flash {:>8} B of {:>8} B ({:.2} %)",
        flash,
        firmware.flash.size,
        percent(flash, firmware.flash.size)
    );
    for (used, region) in image.ram.iter().zip(RAM) {
        println!("  {:<22} {:>8} B", region.name, used);
    }
    let flexram = image.ram[0] + image.ram[1];
    println!(
        "  FlexRAM (ITCM + DTCM) {:>8} B of {:>8} B ({:.2} %)",
        flexram,
        FLEXRAM_BYTES,
        percent(flexram, FLEXRAM_BYTES)
    );
}

fn percent(part: u32, whole: u32) -> f64 {
    f64::from(part) * 100.0 / f64::from(whole)
}
