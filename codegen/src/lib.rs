//! The AER schema generator: `schema/aer.dbc` (and the telemetry YAML) in, the code every tier
//! of the car shares out.
//!
//! The pipeline follows the data: `load` reads files, `validate` checks them and builds the
//! [`model`], `render` turns the model into source through askama templates beside the runtime
//! every generated crate carries (Rust this crate compiles and tests, copied verbatim), and
//! `output` writes it. Every emitter reads only the model.
//!
//! The public face is what the build scripts, the CLI and the tests need: generate the car's
//! contract crate ([`generate_contract`]) or a standalone crate for any DBC file
//! ([`generate_crate`]), load and check a schema ([`load_dbc`], [`parse_dbc`],
//! [`CarSchema`]), the [`model`] it builds, the [`diagnostic`]s it reports and the schema
//! fingerprints.

// The face stays small: an item public inside a private module is an error.
#![deny(unreachable_pub)]

pub mod diagnostic;
pub mod model;

mod bus_load;
mod fingerprint;
mod load;
mod naming;
mod output;
mod render;
mod runtime;
mod validate;

pub use fingerprint::{
    calibration as calibration_fingerprint, database as database_fingerprint,
    telemetry as telemetry_fingerprint,
};
pub use load::dbc::decode_text as decode_dbc_text;

use std::path::{Path, PathBuf};

use askama::Template;

use diagnostic::{Diagnostic, Diagnostics};
use model::Database;

/// Why generation failed.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("{0}")]
    Schema(#[from] Diagnostics),
    #[error("warnings are denied for this schema:\n{}", diagnostic::render_all(.0))]
    DeniedWarnings(Vec<Diagnostic>),
    #[error("rendering failed: {0}")]
    Render(#[from] askama::Error),
    #[error("cannot write {path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
}

/// A file the generator produces, relative to the output directory.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GeneratedFile {
    pub path: PathBuf,
    pub content: String,
}

/// What a generation run did.
#[derive(Debug, Default)]
pub struct Report {
    pub warnings: Vec<Diagnostic>,
    /// Files whose content changed and were rewritten.
    pub written: Vec<PathBuf>,
    /// False when rustfmt was unavailable and files were written unformatted.
    pub formatted: bool,
    pub fingerprint: u32,
}

/// Loads and validates a DBC file: the model plus any warnings, or every error found.
pub fn load_dbc(path: &Path) -> Result<(Database, Vec<Diagnostic>), Diagnostics> {
    load_dbc_allowing(path, &[])
}

/// [`load_dbc`], letting the errors in `allow` through as warnings where the generator can
/// handle them safely ([`diagnostic::Code::when_allowed`] says how): for a vendor's file with
/// known defects that the team cannot fix.
pub fn load_dbc_allowing(
    path: &Path,
    allow: &[diagnostic::Code],
) -> Result<(Database, Vec<Diagnostic>), Diagnostics> {
    let loaded = load::dbc::load(path)?;
    validate::dbc::validate(path, &loaded, allow)
}

/// [`load_dbc_allowing`] for DBC text already in memory; `path` names it in diagnostics.
pub fn parse_dbc(
    path: &Path,
    text: String,
    allow: &[diagnostic::Code],
) -> Result<(Database, Vec<Diagnostic>), Diagnostics> {
    let loaded = load::dbc::parse(path, text)?;
    validate::dbc::validate(path, &loaded, allow)
}

/// Parses and checks telemetry YAML against the database it references; `path` names it in
/// diagnostics. The packet plus any warnings, or every error found.
pub fn parse_telemetry(
    path: &Path,
    text: String,
    db: &Database,
) -> Result<(model::Telemetry, Vec<Diagnostic>), Diagnostics> {
    let loaded = load::telemetry::parse(path, text)?;
    validate::telemetry::validate(path, &loaded, db)
}

/// Renders the codec modules and crate root for `db`. `source` names the schema in headers.
pub fn codec_files(
    db: &Database,
    source: &str,
    title: &str,
    krate: &str,
) -> Result<Vec<GeneratedFile>, Error> {
    let fingerprint = fingerprint::database(db);
    let file = |path: &str, content: String| GeneratedFile {
        path: PathBuf::from(path),
        content,
    };
    Ok(vec![
        file(
            "lib.rs",
            render::standalone::LibTemplate {
                title,
                source,
                telemetry: false,
                calibration: false,
            }
            .render()?,
        ),
        file("runtime.rs", runtime::render(source, None)),
        file(
            "can.rs",
            render::codec::render_can(db, source, fingerprint)?,
        ),
        file(
            "examples/decode.rs",
            render::standalone::DecodeExample { krate }.render()?,
        ),
        file(
            "examples/encode.rs",
            render::standalone::EncodeExample { krate }.render()?,
        ),
    ])
}

/// Formats the Rust files and writes those that changed under `out_dir`.
fn write_files(out_dir: &Path, files: &[GeneratedFile], report: &mut Report) -> Result<(), Error> {
    report.formatted = true;
    for f in files {
        let path = out_dir.join(&f.path);
        let content = if f.path.extension().is_some_and(|e| e == "rs") {
            let (text, formatted) = output::rustfmt(&f.content);
            report.formatted &= formatted;
            text
        } else {
            f.content.clone()
        };
        let wrote = output::write_if_changed(&path, &content).map_err(|source| Error::Io {
            path: path.clone(),
            source,
        })?;
        if wrote {
            report.written.push(path);
        }
    }
    Ok(())
}

/// Parses and checks calibration YAML against the database its XCP messages are in; `path`
/// names it in diagnostics. The calibration plus any warnings, or every error found.
pub fn parse_calibration(
    path: &Path,
    text: String,
    db: &Database,
) -> Result<(model::Calibration, Vec<Diagnostic>), Diagnostics> {
    let loaded = load::calibration::parse(path, text)?;
    validate::calibration::validate(path, &loaded, db)
}

/// The car's schema: the CAN database, the telemetry packet that references it and the
/// CCM's calibration.
pub struct CarSchema {
    pub db: Database,
    pub telemetry: model::Telemetry,
    pub calibration: model::Calibration,
}

impl CarSchema {
    /// Loads `aer.dbc`, `telemetry.yaml` and `calibration.yaml` from `schema_dir`. Warnings are
    /// denied: the car's own schema must be clean.
    pub fn load(schema_dir: &Path) -> Result<Self, Error> {
        let (db, warnings) = load_dbc(&schema_dir.join("aer.dbc"))?;
        if !warnings.is_empty() {
            return Err(Error::DeniedWarnings(warnings));
        }
        let yaml = schema_dir.join("telemetry.yaml");
        let loaded = load::telemetry::load(&yaml)?;
        let (telemetry, warnings) = validate::telemetry::validate(&yaml, &loaded, &db)?;
        if !warnings.is_empty() {
            return Err(Error::DeniedWarnings(warnings));
        }
        let yaml = schema_dir.join("calibration.yaml");
        let loaded = load::calibration::load(&yaml)?;
        let (calibration, warnings) = validate::calibration::validate(&yaml, &loaded, &db)?;
        if !warnings.is_empty() {
            return Err(Error::DeniedWarnings(warnings));
        }
        Ok(Self {
            db,
            telemetry,
            calibration,
        })
    }

    /// Every file of the contract crate, relative to `generated/`.
    pub fn files(&self) -> Result<Vec<GeneratedFile>, Error> {
        let (db, t, c) = (&self.db, &self.telemetry, &self.calibration);
        let dbc = "schema/aer.dbc";
        let yaml = "schema/telemetry.yaml";
        let calibration = "schema/calibration.yaml";
        let file = |path: &str, content: String| GeneratedFile {
            path: PathBuf::from(path),
            content,
        };
        let epk = render::a2l::Epk::new(fingerprint::telemetry(db, t), fingerprint::calibration(c));
        let lib = render::standalone::LibTemplate {
            title: "The car's wire contract: CAN frames, the telemetry packet, its storage and topics.",
            source: "schema/",
            telemetry: true,
            calibration: true,
        };
        Ok(vec![
            file("lib.rs", lib.render()?),
            file("runtime.rs", runtime::render(dbc, Some(db))),
            file(
                "can.rs",
                render::codec::render_can(db, dbc, fingerprint::database(db))?,
            ),
            file(
                "telemetry.rs",
                render::telemetry::render(db, t, yaml, fingerprint::telemetry(db, t))?,
            ),
            file(
                "telemetry_deku.rs",
                render::telemetry::render_deku(db, t, yaml)?,
            ),
            file(
                "calibration.rs",
                render::calibration::render(c, calibration, &epk)?,
            ),
            file("tables.rs", render::tables::render_rust(db, t, "schema/")?),
            file(
                "sql/tdengine.sql",
                render::tables::render_tdengine_sql(db, t, "schema/")?,
            ),
            file(
                "sql/sqlite.sql",
                render::tables::render_sqlite_sql(db, t, "schema/")?,
            ),
            file("mqtt.rs", render::mqtt::render(db, t, "schema/")?),
            file(
                "docs/can.md",
                render::docs::render_can(
                    db,
                    &bus_load::loads(db, Some(t)),
                    bus_load::planned(db, t).map(|planned| (t, planned)),
                    dbc,
                    fingerprint::database(db),
                )?,
            ),
            file(
                "docs/telemetry.md",
                render::docs::render_telemetry(db, t, yaml, fingerprint::telemetry(db, t))?,
            ),
            file(
                "docs/calibration.md",
                render::calibration::render_docs(c, calibration, &epk, t.len)?,
            ),
            file(
                &format!("{}.a2l", render::a2l::A2L_NAME),
                render::a2l::render(db, t, c, &epk)?,
            ),
            file(
                "examples/decode.rs",
                render::standalone::DecodeExample { krate: "aer" }.render()?,
            ),
            file(
                "examples/encode.rs",
                render::standalone::EncodeExample { krate: "aer" }.render()?,
            ),
        ])
    }
}

/// Generates the car's contract crate sources (`generated/`) from `schema_dir`.
pub fn generate_contract(schema_dir: &Path, out_dir: &Path) -> Result<Report, Error> {
    let schema = CarSchema::load(schema_dir)?;
    let files = schema.files()?;
    let mut report = Report {
        fingerprint: fingerprint::telemetry(&schema.db, &schema.telemetry),
        ..Report::default()
    };
    write_files(out_dir, &files, &mut report)?;
    Ok(report)
}

/// Options for [`generate_crate`].
#[derive(Debug, Clone, Default)]
pub struct CrateOptions {
    /// Crate name; defaults to the DBC file's stem in snake case plus `_can`.
    pub name: Option<String>,
    /// Leave out the `[workspace]` table, for crates built as members of a workspace.
    pub workspace_member: bool,
    /// Errors let through as warnings (see [`load_dbc_allowing`]).
    pub allow: Vec<diagnostic::Code>,
}

/// Writes a standalone Cargo crate (codec plus decode/encode examples) for any DBC file.
pub fn generate_crate(dbc: &Path, out_dir: &Path, options: &CrateOptions) -> Result<Report, Error> {
    let (db, warnings) = load_dbc_allowing(dbc, &options.allow)?;
    let stem = dbc.file_stem().and_then(|s| s.to_str()).unwrap_or("dbc");
    let name = options
        .name
        .clone()
        .unwrap_or_else(|| format!("{}_can", naming::snake(stem).trim_end_matches('_')));
    let krate = name.replace('-', "_");
    let source = dbc
        .file_name()
        .and_then(|s| s.to_str())
        .unwrap_or(stem)
        .to_owned();
    let title = format!("CAN codec for `{source}`.");
    let mut files: Vec<GeneratedFile> = codec_files(&db, &source, &title, &krate)?
        .into_iter()
        .map(|mut f| {
            if !f.path.starts_with("examples") {
                f.path = Path::new("src").join(&f.path);
            }
            f
        })
        .collect();
    files.push(GeneratedFile {
        path: PathBuf::from("Cargo.toml"),
        content: render::standalone::CargoTemplate {
            name: &name,
            source: &source,
            standalone: !options.workspace_member,
        }
        .render()?,
    });
    let mut report = Report {
        warnings,
        fingerprint: fingerprint::database(&db),
        ..Report::default()
    };
    write_files(out_dir, &files, &mut report)?;
    Ok(report)
}
