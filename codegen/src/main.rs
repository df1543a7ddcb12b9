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
    /// Checks DBC files and prints compiler-style diagnostics; exits non-zero on any error.
    Check {
        /// DBC files to check.
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
