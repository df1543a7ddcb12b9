//! `cargo xtask m7-check`: the same transcript from the host and from QEMU's Cortex-M7.

use anyhow::{Context, Result, bail};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The host's transcript, from the check's example (a build of its own: the firmware tasks
/// never compile the car model the check drives).
fn host_transcript(root: &Path) -> Result<String> {
    let output = crate::example(root, "host_transcript")?
        .stderr(Stdio::inherit())
        .output()
        .context("running the host transcript")?;
    if !output.status.success() {
        bail!("the host run failed");
    }
    String::from_utf8(output.stdout).context("the host transcript is not UTF-8")
}

/// Builds the check for the Cortex-M7, runs it under QEMU and compares with the host run.
pub fn run(root: &Path, target: &str, timeout_s: u64) -> Result<()> {
    let status = crate::cargo()
        .current_dir(root)
        .args([
            "build",
            "--release",
            "--target",
            target,
            "--package",
            "aer-m7-check",
        ])
        .status()
        .context("running cargo build")?;
    if !status.success() {
        bail!("building the Cortex-M7 check failed");
    }
    let elf = crate::target_dir(root)
        .join(target)
        .join("release/m7-check");
    let started = Instant::now();
    let emulated = qemu(&elf, Duration::from_secs(timeout_s))?;
    let elapsed = started.elapsed();

    let host = host_transcript(root)?;
    // Cost lines exist only in the emulated run.
    let (costs, transcript): (Vec<&str>, Vec<&str>) =
        emulated.lines().partition(|line| line.starts_with("cost "));
    let emulated_transcript = transcript.join("\n");
    // Both transcripts stay beside the build, for reading (the bench day's console lines are
    // in them, under `--- bench-day <name>`).
    let kept = crate::target_dir(root).join("m7-check");
    std::fs::create_dir_all(&kept).with_context(|| format!("creating {}", kept.display()))?;
    for (name, text) in [
        ("host.txt", host.as_str()),
        ("cortex-m7.txt", emulated_transcript.as_str()),
    ] {
        let path = kept.join(name);
        std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))?;
    }
    let differences = compare(&host, &emulated_transcript);
    if !differences.is_empty() {
        for line in &differences {
            eprintln!("{line}");
        }
        bail!(
            "the Cortex-M7 transcript differs from the host's ({} lines)",
            differences.len()
        );
    }
    println!(
        "Cortex-M7 (QEMU mps2-an500) and host agree on all {} transcript lines ({:.1} s emulated run); both in {}",
        host.lines().count(),
        elapsed.as_secs_f64(),
        kept.display()
    );
    for line in costs {
        println!("  {line}");
    }
    Ok(())
}

/// Runs `elf` under QEMU with semihosting and returns what it printed.
fn qemu(elf: &Path, timeout: Duration) -> Result<String> {
    let mut child = Command::new("qemu-system-arm")
        .args(["-cpu", "cortex-m7", "-machine", "mps2-an500", "-nographic"])
        // One instruction per nanosecond of virtual time: SysTick counts instructions.
        .args(["-icount", "shift=0"])
        .args(["-semihosting-config", "enable=on,target=native", "-kernel"])
        .arg(elf)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .context("starting qemu-system-arm (Debian package qemu-system-arm)")?;
    let deadline = Instant::now() + timeout;
    // Poll rather than block so a hung guest cannot hang CI.
    let status = loop {
        if let Some(status) = child.try_wait().context("waiting for QEMU")? {
            break status;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            bail!("QEMU did not finish within {} s", timeout.as_secs());
        }
        std::thread::park_timeout(Duration::from_millis(20));
    };
    let output = child.wait_with_output().context("reading QEMU's output")?;
    let stdout = String::from_utf8_lossy(&output.stdout).into_owned();
    if !status.success() {
        bail!(
            "the Cortex-M7 check failed ({status}):\n{}{}",
            stdout,
            String::from_utf8_lossy(&output.stderr)
        );
    }
    Ok(stdout)
}

/// Line-by-line differences, as `-host` / `+m7` pairs.
fn compare(host: &str, emulated: &str) -> Vec<String> {
    let host_lines: Vec<&str> = host.lines().collect();
    let emulated_lines: Vec<&str> = emulated.lines().collect();
    let mut differences = Vec::new();
    for index in 0..host_lines.len().max(emulated_lines.len()) {
        let (a, b) = (host_lines.get(index), emulated_lines.get(index));
        if a != b {
            differences.push(format!(
                "line {}:\n  -host {}\n  +m7   {}",
                index + 1,
                a.unwrap_or(&"<none>"),
                b.unwrap_or(&"<none>")
            ));
        }
    }
    differences
}

#[cfg(test)]
mod tests {
    use super::compare;

    #[test]
    fn equal_transcripts_have_no_differences() {
        assert!(compare("a\nb\n", "a\nb\n").is_empty());
    }

    #[test]
    fn changed_missing_and_extra_lines_are_reported() {
        assert_eq!(compare("a\nb\n", "a\nc\n").len(), 1);
        assert_eq!(compare("a\nb\n", "a\n").len(), 1);
        assert_eq!(compare("a\n", "a\nb\nc\n").len(), 2);
    }
}
