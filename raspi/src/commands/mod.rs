//! The store commands a person types on the car or a laptop (`session`, `export`, `report`,
//! `compact`, `clock`): they find the service's store, say which one they opened, never create one by
//! accident, and fail, with the reason and what to do, when they did nothing.
//!
//! Each writes its results to `out` (what a script reads: tables, the archive) and what it is
//! doing to `notes` (the store it opened, which session it chose), so `export --archive -`
//! can stream a tar file through SSH.

pub mod clock;
pub mod export;
pub mod report;
pub mod session;

use crate::config::{Config, Origin};
use crate::store::access::{self, ReadOnly};
use crate::store::{self, StoreError};
use anyhow::{Context, Result};
use rusqlite::Connection;
use std::io::Write;
use std::path::Path;

/// Where the store commands' store is, and why there.
pub struct Located {
    pub config: Config,
    pub origin: Origin,
}

impl Located {
    /// The configuration `origin` names, with the environment's overrides.
    pub fn load(origin: Origin, env: impl Fn(&str) -> Option<String>) -> Result<Self> {
        let mut config = Config::load(origin.path(), &env)?;
        if origin == Origin::Demo {
            config = config.in_demo_store(env);
        }
        Ok(Self { config, origin })
    }

    /// The store's path.
    pub fn store(&self) -> &Path {
        &self.config.store.path
    }

    /// Opens the store for reading, and says which it opened.
    pub fn read(&self, notes: &mut dyn Write) -> Result<ReadOnly> {
        let opened = access::open_read_only(self.store()).map_err(|e| self.explain(e))?;
        let how = match opened.mode {
            access::ReadMode::Shared => "",
            access::ReadMode::Immutable => ", read as a still file (no writer running)",
        };
        writeln!(
            notes,
            "store {} ({}{how})",
            self.store().display(),
            self.origin
        )?;
        Ok(opened)
    }

    /// Opens the store to change it (as the service's user, `sudo -u aer`), and says which;
    /// a missing store is created only with `create`.
    pub fn change(&self, create: bool, notes: &mut dyn Write) -> Result<Connection> {
        let db = access::open_for_change(self.store(), create).map_err(|e| self.explain(e))?;
        writeln!(notes, "store {} ({})", self.store().display(), self.origin)?;
        Ok(db)
    }

    /// A store error with what to do about it here.
    fn explain(&self, error: StoreError) -> anyhow::Error {
        let hint = match (&error, &self.origin) {
            (StoreError::Missing { .. }, Origin::Defaults) => {
                let demo = if Path::new(crate::config::DEMO_STORE).exists() {
                    format!(
                        "; the demo recorded into {}: add --demo",
                        crate::config::DEMO_STORE
                    )
                } else {
                    String::new()
                };
                format!(
                    "\n  (read with {}; the car's service keeps its store where /etc/aer/aer-raspi.toml says: give -c, or set AER_CONFIG{demo})",
                    self.origin
                )
            }
            (StoreError::Missing { .. }, Origin::Demo) => format!(
                "\n  (looked in {}: run the command in the folder the demo ran in, where it made aer-demo.sqlite and aer-demo-raw/)",
                std::env::current_dir()
                    .map_or_else(|_| ".".to_owned(), |d| d.display().to_string())
            ),
            (StoreError::Missing { .. }, _) => format!(
                "\n  (read with {}: has the service run with it? `aer-raspi session new --create-store` starts an empty store)",
                self.origin
            ),
            _ => format!("\n  (read with {})", self.origin),
        };
        anyhow::anyhow!("{error}{hint}")
    }
}

/// `compact`: compacts every closed session now and gives the pages back.
pub fn compact(located: &Located, out: &mut dyn Write, notes: &mut dyn Write) -> Result<()> {
    let mut db = located.change(false, notes)?;
    let mut compaction = store::Compaction::everything_closed();
    let mut rows = 0;
    loop {
        let step = compaction.step(&mut db)?;
        if step == 0 {
            break;
        }
        rows += step;
    }
    store::space::release_free_pages(&db)?;
    db.query_row("PRAGMA wal_checkpoint(TRUNCATE)", [], |_| Ok(()))
        .context("checkpointing the store")?;
    let bytes = std::fs::metadata(located.store()).map_or(0, |m| m.len());
    writeln!(
        out,
        "{rows} rows compacted; {} is {bytes} bytes",
        located.store().display()
    )?;
    Ok(())
}
