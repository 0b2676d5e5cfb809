//! `mogen data ...`: build and inspect the motion database.

use std::path::PathBuf;

use anyhow::Context;
use clap::Subcommand;
use motion_core::database::catalog::Catalog;
use motion_core::database::{DatabaseConfig, MotionDatabase};

use crate::paths;

#[derive(Debug, Subcommand)]
pub enum DataCommand {
    /// Build the training/retrieval database from a catalog of mocap clips and print the
    /// seconds of motion per label.
    Build {
        /// Catalog JSON listing clip files, formats and labels.
        #[arg(long, default_value_os_t = paths::default_catalog())]
        catalog: PathBuf,
        /// Output database file (safetensors with the index in its header).
        #[arg(long, short, default_value_os_t = paths::default_database())]
        out: PathBuf,
        /// Seconds generated from each cyclic clip by looping it (positive, at most an hour).
        #[arg(long, default_value_t = DatabaseConfig::default().loop_seconds, value_parser = super::flags::loop_seconds)]
        loop_seconds: f64,
        /// Leave out the left/right mirrored copies.
        #[arg(long)]
        no_mirror: bool,
    },
    /// Print the contents of a database.
    Stats {
        /// Database file.
        #[arg(default_value_os_t = paths::default_database())]
        database: PathBuf,
    },
}

pub fn run(cmd: DataCommand) -> anyhow::Result<()> {
    match cmd {
        DataCommand::Build { catalog, out, loop_seconds, no_mirror } => {
            let catalog = Catalog::read(&catalog).context("reading the catalog")?;
            let (sources, warnings) = catalog.load().context("importing clips")?;
            for w in &warnings {
                tracing::warn!("{w}");
            }
            let config = DatabaseConfig { loop_seconds, mirror: !no_mirror, ..DatabaseConfig::default() };
            let db = MotionDatabase::build(&sources, &config).context("building the database")?;
            db.save(&out).with_context(|| format!("writing {}", out.display()))?;
            print_stats(&db);
            println!("wrote {}", out.display());
            Ok(())
        }
        DataCommand::Stats { database } => {
            let db = MotionDatabase::load(&database).with_context(|| format!("reading {}", database.display()))?;
            print_stats(&db);
            Ok(())
        }
    }
}

fn print_stats(db: &MotionDatabase) {
    println!("{:<52} {:>9}", "label", "seconds");
    for (label, seconds) in db.seconds_per_label() {
        println!("{label:<52} {seconds:>9.1}");
    }
    println!(
        "{} sequences, {} windows, {} frames ({:.1} s at 20 fps)",
        db.sequences().len(),
        db.windows().len(),
        db.total_frames(),
        db.total_frames() as f64 / motion_core::skeleton::FPS
    );
}
