//! Regenerates `generated/` from `schema/` whenever the schema (or the generated files) change.
//! A broken schema fails the build with the same diagnostics `aer-codegen check` prints.

use std::path::Path;
use std::process::ExitCode;

fn main() -> ExitCode {
    println!("cargo::rerun-if-changed=schema");
    // Also rerun when generated/ is edited by hand, so the edit is overwritten (and CI's
    // freshness check sees it) instead of silently compiled.
    println!("cargo::rerun-if-changed=generated");
    match aer_codegen::generate_contract(Path::new("schema"), Path::new("generated")) {
        Ok(report) => {
            if !report.formatted {
                println!(
                    "cargo::warning=rustfmt was not found: generated/ was written unformatted"
                );
            }
            for path in &report.written {
                println!("cargo::warning=regenerated {}", path.display());
            }
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("{e}");
            ExitCode::FAILURE
        }
    }
}
