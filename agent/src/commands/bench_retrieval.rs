//! `mogen bench retrieval`: RG-DNO's constraint-based retrieval over the whole retrieval
//! database for one task: seconds per query and bytes held.

use std::path::PathBuf;
use std::time::Instant;

use clap::Args;
use motion_core::generation::rgdno::candidates::Crop;
use motion_core::generation::rgdno::config::RetrievalConfig;
use motion_core::generation::rgdno::retrieval::retrieve;
use serde::Serialize;

use crate::cli::load;
use crate::cli::measure::{median, peak_rss_mib};
use crate::cli::retrieval_task::RetrievalTask;
use agent::paths;

#[derive(Debug, Args)]
pub struct BenchRetrievalArgs {
    /// Constraint program with a relational parse: its retrieval set C_R is scored (default:
    /// RG-DNO's Task 2, the low barrier, 100 frames).
    #[arg(default_value_os_t = paths::fixtures_dir().join("tasks").join("rgdno_task2_low_barrier.json"))]
    program: PathBuf,
    /// What to retrieve from, as `mogen run --database` (default: the shipped corpus's train
    /// split, with mirrored copies).
    #[arg(long, value_name = "FILE")]
    database: Option<PathBuf>,
    /// Timed queries (after one warm-up); the median is printed.
    #[arg(long, default_value_t = 5)]
    reps: usize,
    /// Print one JSON object instead of the text.
    #[arg(long)]
    json: bool,
}

/// The figures of one benchmark run.
#[derive(Debug, Serialize)]
struct Figures {
    database: String,
    clips: usize,
    hours: f64,
    open_s: f64,
    /// The joints and the clips' index with their captions.
    bytes_held: usize,
    frames: usize,
    candidates: usize,
    /// Bytes of the crops' index, made per query.
    candidate_bytes: usize,
    consistent: usize,
    threads: usize,
    /// Median seconds of a whole query: semantic check, every candidate ranked on joint
    /// centres, the shortlist scored exactly, features of the retrieved.
    query_s: f64,
    query_min_s: f64,
    query_max_s: f64,
    peak_rss_mib: f64,
    best: String,
}

pub fn run(args: BenchRetrievalArgs) -> anyhow::Result<()> {
    let device = load::device()?;
    let task = RetrievalTask::open(&args.program, args.database.as_deref(), &device)?;
    let RetrievalTask { database, source, compiled, open_s, .. } = &task;
    let config = RetrievalConfig::default();
    let query = task.query();
    let first = retrieve(database, &query, &config, &device)?;
    let mut times = Vec::with_capacity(args.reps);
    for _ in 0..args.reps {
        let clock = Instant::now();
        retrieve(database, &query, &config, &device)?;
        times.push(clock.elapsed().as_secs_f64());
    }
    let figures = Figures {
        database: source.to_string(),
        clips: database.clips(),
        hours: database.seconds() / 3600.0,
        open_s: *open_s,
        bytes_held: database.bytes(),
        frames: compiled.frames(),
        candidates: first.candidates,
        candidate_bytes: first.candidates * size_of::<Crop>(),
        consistent: first.consistent,
        threads: rayon::current_num_threads(),
        query_min_s: times.iter().copied().fold(f64::INFINITY, f64::min),
        query_max_s: times.iter().copied().fold(0.0, f64::max),
        query_s: median(times),
        peak_rss_mib: peak_rss_mib(),
        best: first.retrieved.first().map_or_else(|| "nothing".to_owned(), |r| format!("{:.4} {}", r.score, r.source)),
    };
    if args.json {
        println!("{}", serde_json::to_string(&figures)?);
        return Ok(());
    }
    let mb = |bytes: usize| bytes as f64 / 1e6;
    println!(
        "retrieval database: {}: {} clips, {:.2} h; opened in {:.1} s; {:.1} MB held (joints as f32, clips, captions)",
        figures.database,
        figures.clips,
        figures.hours,
        figures.open_s,
        mb(figures.bytes_held)
    );
    println!(
        "{} ({} frames, C_R = {:?}): {} candidate crops ({:.1} MB of index per query), {} after the semantic check",
        args.program.display(),
        figures.frames,
        task.retrieval,
        figures.candidates,
        mb(figures.candidate_bytes),
        figures.consistent
    );
    println!(
        "retrieval (semantic check, every candidate ranked on joint centres, {} scored exactly, features of the \
         best {}): {:.3} s median of {} (min {:.3}, max {:.3}) on {} threads; peak RSS {:.0} MiB",
        config.exact_shortlist,
        config.top_k,
        figures.query_s,
        args.reps,
        figures.query_min_s,
        figures.query_max_s,
        figures.threads,
        figures.peak_rss_mib
    );
    println!("best: {}", figures.best);
    Ok(())
}
