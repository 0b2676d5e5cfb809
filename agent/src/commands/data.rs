//! `mogen data ...`: build and inspect the motion corpus and the motion database.

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Subcommand;
use motion_core::corpus::screen::ScreenConfig;
use motion_core::corpus::stats::CorpusStats;
use motion_core::corpus::{cmu, file as corpus_file, Corpus, RawTake, Source};
use motion_core::database::catalog::Catalog;
use motion_core::database::{DatabaseConfig, MotionDatabase};
use motion_core::import::resample;

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
    /// Build the motion corpus from the shared capture: the CMU database in its 22-joint form
    /// (`smpl22_20fps_f16.npz` and `index.tsv`), HDM05's ASF/AMC clips and the shipped clips of
    /// a catalog. Every take is screened (glitches, frozen frames, T-poses, uneven floors are
    /// dropped and reported), re-targeted to the rest skeleton, floored, cut into captioned
    /// windows and split by subject; the result is one compressed file (the shipped
    /// `fixtures/corpus/corpus.safetensors.gz` is made this way).
    Corpus {
        /// The shared CMU folder.
        #[arg(long, default_value = "../shared/data/cmu")]
        cmu: PathBuf,
        /// The shared HDM05 folder (ASF/AMC).
        #[arg(long, default_value = "../shared/data/hdm05")]
        hdm05: PathBuf,
        /// The catalog of shipped clips added to the training split.
        #[arg(long, default_value_os_t = paths::default_catalog())]
        catalog: PathBuf,
        /// Output corpus file.
        #[arg(long, short, default_value = "fixtures/corpus/corpus.safetensors.gz")]
        out: PathBuf,
    },
    /// Print what a corpus (hours per source, skill and split, what was dropped) or a database
    /// (seconds per label) holds; by default the shipped corpus.
    Stats {
        /// A corpus file (`.safetensors.gz`) or a database file (`.safetensors`).
        #[arg(default_value_os_t = paths::default_corpus())]
        file: PathBuf,
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
        DataCommand::Corpus { cmu, hdm05, catalog, out } => {
            let mut takes: Vec<RawTake> = Vec::new();
            eprintln!("reading {}", cmu.display());
            takes.extend(cmu::read_cmu_folder(&cmu).context("reading the CMU capture")?.into_iter().map(RawTake::from));
            eprintln!("reading {}", hdm05.display());
            takes.extend(motion_core::corpus::hdm05::read_hdm05_folder(&hdm05).context("reading the HDM05 capture")?);
            takes.extend(shipped_takes(&catalog)?);
            eprintln!("screening, re-targeting and captioning {} takes", takes.len());
            let corpus = Corpus::build(takes, &ScreenConfig::default());
            corpus_file::save(&corpus, &out).with_context(|| format!("writing {}", out.display()))?;
            println!("{}", CorpusStats::of(&corpus));
            println!("wrote {}", out.display());
            Ok(())
        }
        DataCommand::Stats { file } => {
            if file.extension().is_some_and(|e| e == "gz") {
                let corpus = corpus_file::load(&file).with_context(|| format!("reading {}", file.display()))?;
                println!("{}", CorpusStats::of(&corpus));
            } else {
                let db = MotionDatabase::load(&file).with_context(|| format!("reading {}", file.display()))?;
                print_stats(&db);
            }
            Ok(())
        }
    }
}

/// The clips of a catalog as corpus takes of the shipped source: one play-through each, cyclic
/// clips looped as the database loops them; already on the rest skeleton, so not screened.
fn shipped_takes(catalog: &Path) -> anyhow::Result<Vec<RawTake>> {
    let (clips, _) = Catalog::read(catalog).and_then(|c| c.load()).context("reading the shipped clips")?;
    let loop_seconds = DatabaseConfig::default().loop_seconds;
    Ok(clips
        .into_iter()
        .map(|c| RawTake {
            source: Source::Shipped,
            subject: "shipped".into(),
            description: c.label,
            poses: resample(c.clip.as_ref(), 1.0, c.clip.is_cyclic().then_some(loop_seconds)),
            take: c.name,
            screen: false,
            hold_frames: 0,
        })
        .collect())
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
