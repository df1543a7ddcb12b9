//! `aer-codegen`: check schemas and generate code from them.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

use aer_codegen::diagnostic::{Code, render_all};

/// A diagnostic code that `--allow` can let through.
fn allowable(text: &str) -> Result<Code, String> {
    let code = Code::parse(text).ok_or_else(|| format!("`{text}` is not a diagnostic code"))?;
    match code.when_allowed() {
        Some(_) => Ok(code),
        None => Err(format!(
            "{code} cannot be allowed: the generator cannot handle it safely (E0107 and E0101 can)"
        )),
    }
}

#[derive(Parser)]
#[command(
    name = "aer-codegen",
    version,
    about = "Checks CAN schemas and generates no_std codecs from them"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Checks DBC files and prints compiler-style diagnostics; exits non-zero on any error. A
    /// schema directory (`schema`), or a DBC with a `telemetry.yaml` beside it, is checked as
    /// `cargo build` checks the car's schema: the DBC, the telemetry packet (its bus load
    /// included) and the calibration, warnings denied.
    Check {
        /// DBC files or schema directories to check.
        #[arg(required = true)]
        files: Vec<PathBuf>,
        /// Treat warnings as errors (the car's own schema is built this way).
        #[arg(long)]
        deny_warnings: bool,
        /// Let an error through as a warning where the generator can handle it safely, for a
        /// vendor's file with known defects (repeatable): E0107 (overlapping signals, decoded
        /// as written), E0101 (a standard id above 0x7FF, taken as a 29-bit extended id).
        #[arg(long = "allow", value_name = "CODE", value_parser = allowable)]
        allow: Vec<Code>,
    },
    /// Writes a standalone Cargo crate for any DBC: the codec plus `decode`/`encode` examples.
    Crate {
        /// The DBC file.
        #[arg(long)]
        dbc: PathBuf,
        /// Directory to write the crate into (created if missing).
        #[arg(long)]
        out: PathBuf,
        /// Crate name (default: the file stem plus `_can`).
        #[arg(long)]
        name: Option<String>,
        /// Leave out the `[workspace]` table (for crates built as workspace members).
        #[arg(long)]
        workspace_member: bool,
        /// As for `check`: generate despite these errors, each reported and handled safely.
        #[arg(long = "allow", value_name = "CODE", value_parser = allowable)]
        allow: Vec<Code>,
    },
    /// Regenerates the contract crate sources from a schema directory (what build.rs does).
    Generate {
        #[arg(long, default_value = "schema")]
        schema: PathBuf,
        #[arg(long, default_value = "generated")]
        out: PathBuf,
    },
}

fn main() -> ExitCode {
    match Cli::parse().command {
        Command::Check {
            files,
            deny_warnings,
            allow,
        } => {
            let mut failed = false;
            for file in &files {
                if let Some(schema) = car_schema_dir(file) {
                    failed |= !check_car_schema(&schema);
                    continue;
                }
                match aer_codegen::load_dbc_allowing(file, &allow) {
                    Ok((db, warnings)) => {
                        if !warnings.is_empty() {
                            eprintln!("{}", render_all(&warnings));
                            failed |= deny_warnings;
                        }
                        let signals: usize = db.messages.iter().map(|m| m.signals.len()).sum();
                        println!(
                            "{}: {} messages, {} signals, fingerprint 0x{:08X}",
                            file.display(),
                            db.messages.len(),
                            signals,
                            aer_codegen::database_fingerprint(&db)
                        );
                    }
                    Err(diags) => {
                        eprintln!("{diags}");
                        failed = true;
                    }
                }
            }
            if failed {
                ExitCode::FAILURE
            } else {
                ExitCode::SUCCESS
            }
        }
        Command::Crate {
            dbc,
            out,
            name,
            workspace_member,
            allow,
        } => {
            let options = aer_codegen::CrateOptions {
                name,
                workspace_member,
                allow,
            };
            report(aer_codegen::generate_crate(&dbc, &out, &options), &out)
        }
        Command::Generate { schema, out } => {
            report(aer_codegen::generate_contract(&schema, &out), &out)
        }
    }
}

/// The schema directory `path` names: itself, or the folder of a DBC that has a
/// `telemetry.yaml` beside it (the car's schema, which the build checks as a whole).
fn car_schema_dir(path: &std::path::Path) -> Option<PathBuf> {
    if path.is_dir() {
        return Some(path.to_path_buf());
    }
    let dir = path.parent()?;
    let dir = if dir.as_os_str().is_empty() {
        std::path::Path::new(".")
    } else {
        dir
    };
    dir.join("telemetry.yaml")
        .is_file()
        .then(|| dir.to_path_buf())
}

/// Checks the car's schema in `dir` as build.rs does; true when it is clean.
fn check_car_schema(dir: &std::path::Path) -> bool {
    match aer_codegen::CarSchema::load(dir) {
        Ok(schema) => {
            let signals: usize = schema.db.messages.iter().map(|m| m.signals.len()).sum();
            println!(
                "{}: the car's schema as `cargo build` checks it (aer.dbc, telemetry.yaml, \
                 calibration.yaml; warnings denied): {} messages, {} signals, a {}-byte \
                 telemetry packet, {} calibration parameters",
                dir.display(),
                schema.db.messages.len(),
                signals,
                schema.telemetry.len,
                schema.calibration.parameters.len()
            );
            true
        }
        Err(error) => {
            eprintln!("{error}");
            false
        }
    }
}

fn report(
    result: Result<aer_codegen::Report, aer_codegen::Error>,
    out: &std::path::Path,
) -> ExitCode {
    match result {
        Ok(r) => {
            if !r.warnings.is_empty() {
                eprintln!("{}", render_all(&r.warnings));
            }
            if !r.formatted {
                eprintln!("warning: rustfmt was not found; the files are unformatted");
            }
            println!(
                "{}: {} file(s) updated, fingerprint 0x{:08X}",
                out.display(),
                r.written.len(),
                r.fingerprint
            );
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("{e}");
            ExitCode::FAILURE
        }
    }
}
