//! `mogen retrieve`: RG-DNO's constraint-based retrieval for a program, on its own.

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use motion_core::constraints::CompiledProgram;
use motion_core::rgdno::retrieval::{retrieve, RetrievalConfig, RetrievalCorpus, RetrievalQuery};

use super::load::load_program;
use super::run::database_source;

#[derive(Debug, Args)]
pub struct RetrieveArgs {
    /// Constraint program with a relational parse (JSON).
    program: PathBuf,
    /// Motion database file (`mogen data build`); default: the shipped catalog's clips, built in
    /// memory.
    #[arg(long, value_name = "FILE")]
    database: Option<PathBuf>,
    /// Retrieved motions printed, best first.
    #[arg(long, default_value_t = 10)]
    top: usize,
    /// Weight of C_R's constraints other than the most difficult one.
    #[arg(long, default_value_t = RetrievalConfig::default().related_weight, value_parser = super::flags::weight)]
    related_weight: f64,
    /// Also score every candidate exactly and print the best crop of each label (slower).
    #[arg(long)]
    per_label: bool,
}

pub fn run(args: RetrieveArgs) -> anyhow::Result<()> {
    let program = load_program(&args.program)?;
    let groups = program
        .constraint_groups()
        .with_context(|| format!("{} has no relational parse: nothing to retrieve for", args.program.display()))?;
    let most_difficult = program.relational_parse.as_ref().map(|p| p.most_difficult.clone()).unwrap_or_default();
    let device = candle_core::Device::Cpu;
    let compiled = CompiledProgram::compile(&program, &device)?.subset(&groups.retrieval);
    let source = database_source(args.database.as_deref());
    let (db, _) = source.open().with_context(|| format!("opening the database ({source})"))?;
    let config = RetrievalConfig { related_weight: args.related_weight, top_k: args.top, ..RetrievalConfig::default() };
    let clock = std::time::Instant::now();
    let corpus = RetrievalCorpus::build(&db, compiled.frames(), &config, &device)?;
    let built = clock.elapsed().as_secs_f64();
    let query = RetrievalQuery {
        program: &compiled,
        most_difficult: &most_difficult,
        prompt: &program.text,
        counting: !compiled.count_targets().is_empty(),
    };
    let clock = std::time::Instant::now();
    let found = retrieve(&corpus, &query, &config)?;
    println!(
        "C_R = {:?} (c_D = {most_difficult}, others weighted {}); {} candidates; corpus {built:.1} s, scoring \
         {:.2} s",
        groups.retrieval,
        config.related_weight,
        corpus.len(),
        clock.elapsed().as_secs_f64()
    );
    let line = |r: &motion_core::rgdno::retrieval::Retrieved| {
        let errors: Vec<String> = r.per_constraint.iter().map(|(id, e)| format!("{id} {e:.4}")).collect();
        format!("{:.4}  {}  {}", r.score, r.source, errors.join(", "))
    };
    println!("best {}:", found.len());
    for r in &found {
        println!("  {}", line(r));
    }
    if args.per_label {
        let every = RetrievalConfig { top_k: usize::MAX, ..config };
        let mut per_label = BTreeMap::new();
        for r in retrieve(&corpus, &query, &every)? {
            per_label.entry(r.source.label.clone()).or_insert(r);
        }
        println!("best of each label:");
        let mut best: Vec<_> = per_label.into_values().collect();
        best.sort_by(|a, b| a.score.total_cmp(&b.score));
        for r in &best {
            println!("  {}", line(r));
        }
    }
    Ok(())
}
