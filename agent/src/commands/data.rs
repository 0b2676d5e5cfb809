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

use agent::paths;

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
        #[arg(long, default_value_t = DatabaseConfig::default().loop_seconds, value_parser = crate::cli::flags::loop_seconds)]
        loop_seconds: f64,
        /// Leave out the left/right mirrored copies.
        #[arg(long)]
        no_mirror: bool,
    },
    /// Build the motion corpus from the shared capture (CMU, HDM05), ACCAD's takes and the
    /// shipped clips.
    ///
    /// Reads the CMU database in its 22-joint form (`smpl22_20fps_f16.npz` and `index.tsv`),
    /// HDM05's ASF/AMC clips, ACCAD's BVH takes (fetched by `fixtures/corpus/accad/fetch.sh`,
    /// each checked against its SHA-256 in the manifest) and the shipped clips of a catalog. Every take is screened (glitches, frozen frames, T-poses, uneven floors are
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
        /// The folder of ACCAD's takes (`Female1_bvh/`, `Male2_bvh/`).
        #[arg(long, default_value = "fixtures/corpus/accad/takes")]
        accad: PathBuf,
        /// The SHA-256 list of ACCAD's takes (`sha256sum` format, paths relative to `--accad`).
        #[arg(long, default_value = "fixtures/corpus/accad/MANIFEST.sha256")]
        accad_manifest: PathBuf,
        /// The catalog of shipped clips added to the training split.
        #[arg(long, default_value_os_t = paths::default_catalog())]
        catalog: PathBuf,
        /// Output corpus file.
        #[arg(long, short, default_value = "fixtures/corpus/corpus.safetensors.gz")]
        out: PathBuf,
    },
    /// Draw corpus windows in world coordinates: one per skill family, and random ones.
    ///
    /// Writes `skills.png`, one window per skill
    /// family (walk, sideways walk, sneak/creep, crawl, one-leg balance, hop, carry, sit down),
    /// and `random_<k>.png`, randomly drawn windows ten to a picture, with `windows.md`, the
    /// table of their takes, descriptions, captions and tags.
    Show {
        /// A corpus file.
        #[arg(long, default_value_os_t = paths::default_corpus())]
        corpus: PathBuf,
        /// Output folder.
        #[arg(long, short, default_value = "out/corpus")]
        out: PathBuf,
        /// Random windows drawn.
        #[arg(long, default_value_t = 30)]
        random: usize,
        /// Seed of the random draw.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Draw only the windows of one source (cmu, hdm05, accad, shipped).
        #[arg(long, value_parser = source_name)]
        source: Option<Source>,
    },
    /// Print what a corpus or a database holds (by default the shipped corpus).
    ///
    /// For a corpus: hours per source, skill family and split, what was dropped and why, and
    /// soundness figures; for a database: seconds per label.
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
        DataCommand::Corpus { cmu, hdm05, accad, accad_manifest, catalog, out } => {
            let mut takes: Vec<RawTake> = Vec::new();
            eprintln!("reading {}", cmu.display());
            takes.extend(cmu::read_cmu_folder(&cmu).context("reading the CMU capture")?.into_iter().map(RawTake::from));
            eprintln!("reading {}", hdm05.display());
            takes.extend(motion_core::corpus::hdm05::read_hdm05_folder(&hdm05).context("reading the HDM05 capture")?);
            takes.extend(shipped_takes(&catalog)?);
            // Last, so that the clips and windows of the other sources keep their indices.
            eprintln!("reading {}", accad.display());
            takes.extend(
                motion_core::corpus::accad::read_accad_folder(&accad, &accad_manifest)
                    .context("reading ACCAD's takes (fixtures/corpus/accad/fetch.sh fetches them)")?,
            );
            eprintln!("screening, re-targeting and captioning {} takes", takes.len());
            let corpus = Corpus::build(takes, &ScreenConfig::default());
            corpus_file::save(&corpus, &out).with_context(|| format!("writing {}", out.display()))?;
            println!("{}", CorpusStats::of(&corpus));
            println!("wrote {}", out.display());
            Ok(())
        }
        DataCommand::Show { corpus, out, random, seed, source } => {
            let corpus = corpus_file::load(&corpus).with_context(|| format!("reading {}", corpus.display()))?;
            show(&corpus, &out, random, seed, source)
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

/// A source by its lower-case name.
fn source_name(name: &str) -> Result<Source, String> {
    Source::ALL.into_iter().find(|s| s.name() == name).ok_or_else(|| {
        let names: Vec<&str> = Source::ALL.iter().map(|s| s.name()).collect();
        format!("no source `{name}`; the sources are {}", names.join(", "))
    })
}

/// A window of each skill family among `eligible` (window indices in corpus order), chosen where
/// the take's description names the skill and the window's own tags show it; the first such one.
fn skill_windows(corpus: &Corpus, eligible: &[usize]) -> Vec<(&'static str, usize)> {
    use motion_core::corpus::caption::Action;
    use motion_core::corpus::skill::Skill;
    use motion_core::corpus::tags::{MotionTags, TravelDirection};
    type Family = (&'static str, Skill, fn(&MotionTags) -> bool);
    let families: [Family; 8] = [
        ("walk", Skill::Walk, |t| Action::of(t) == Action::Walk && t.direction == Some(TravelDirection::Forwards)),
        ("sideways walk", Skill::Sideways, |t| {
            matches!(t.direction, Some(TravelDirection::SidewaysLeft | TravelDirection::SidewaysRight))
                && t.travel_m > 1.5
        }),
        ("sneak/creep", Skill::CrouchSneak, |t| Action::of(t) == Action::Sneak),
        ("crawl", Skill::Crawl, |t| Action::of(t) == Action::Crawl),
        ("one-leg balance", Skill::Balance, |t| Action::of(t) == Action::Balance),
        ("hop", Skill::JumpHop, |t| t.airborne() && t.one_foot()),
        ("carry", Skill::Carry, |t| Action::of(t) == Action::Walk),
        ("sit down", Skill::Sit, |t| t.sitting),
    ];
    families
        .iter()
        .filter_map(|(name, skill, shows)| {
            eligible
                .iter()
                .copied()
                .find(|&i| {
                    let w = &corpus.windows[i];
                    skill.named_by(&corpus.clips[w.clip].description) && shows(&w.tags)
                })
                .map(|i| (*name, i))
        })
        .collect()
}

/// SplitMix64's finaliser: a well-mixed 64-bit hash of `x`.
fn splitmix64(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

fn show(corpus: &Corpus, out: &Path, random: usize, seed: u64, source: Option<Source>) -> anyhow::Result<()> {
    use motion_core::render::{motion_strip, StripRow};
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let row = |label: String, i: usize| StripRow { label, poses: corpus.window_joints(&corpus.windows[i]) };
    let eligible: Vec<usize> = (0..corpus.windows.len())
        .filter(|&i| source.is_none_or(|s| corpus.clips[corpus.windows[i].clip].source == s))
        .collect();
    let skills = skill_windows(corpus, &eligible);
    let rows: Vec<StripRow<'_>> = skills
        .iter()
        .map(|(name, i)| {
            let w = &corpus.windows[*i];
            row(
                format!(
                    "{name}: {} ({}, {})",
                    w.captions[0], corpus.clips[w.clip].take, corpus.clips[w.clip].description
                ),
                *i,
            )
        })
        .collect();
    motion_strip(&rows, 8, &[], &[], "one window per skill family", &out.join("skills.png"))?;
    // A seeded draw without replacement: the windows in the order of a hash of seed and index.
    let mut drawn = eligible;
    drawn.sort_by_key(|&i| splitmix64(seed ^ (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)));
    drawn.truncate(random);
    let mut table = String::from("| # | take (frames) | description | caption | tags |\n|---|---|---|---|---|\n");
    for (k, chunk) in drawn.chunks(10).enumerate() {
        let rows: Vec<StripRow<'_>> = chunk
            .iter()
            .enumerate()
            .map(|(j, &i)| row(format!("{}: {}", 10 * k + j, corpus.windows[i].captions[0]), i))
            .collect();
        motion_strip(&rows, 8, &[], &[], "random corpus windows", &out.join(format!("random_{k}.png")))?;
    }
    for (n, &i) in drawn.iter().enumerate() {
        let w = &corpus.windows[i];
        let clip = &corpus.clips[w.clip];
        let t = &w.tags;
        table.push_str(&format!(
            "| {n} | {} ({}..{}) | {} | {} | {:.2} m/s, {:.1} m, {:?}, turn {:.0}°{}{}{}{}{} |\n",
            clip.name,
            w.start,
            w.start + w.frames,
            clip.description,
            w.captions[0],
            t.speed_m_per_s,
            t.travel_m,
            t.direction,
            t.turn_deg,
            if t.crouched { ", crouched" } else { "" },
            if t.sitting { ", sitting" } else { "" },
            if t.on_floor { ", on the floor" } else { "" },
            if t.airborne() { ", airborne" } else { "" },
            if t.one_foot() { ", one foot up" } else { "" },
        ));
    }
    std::fs::write(out.join("windows.md"), &table).with_context(|| format!("writing {}", out.display()))?;
    for (name, i) in &skills {
        let w = &corpus.windows[*i];
        println!("{name}: {} ({}, frames {}..)", w.captions[0], corpus.clips[w.clip].name, w.start);
    }
    println!("wrote {}/{{skills.png,random_*.png,windows.md}}", out.display());
    Ok(())
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
