//! `mogen retrieve`: RG-DNO's constraint-based retrieval for a program, on its own.

use std::path::PathBuf;

use clap::Args;
use motion_core::generation::rgdno::config::RetrievalConfig;
use motion_core::generation::rgdno::retrieval::{retrieve, Retrieved};
use motion_core::generation::rgdno::semantic::{missing_actions_note, named_actions};

use crate::cli::retrieval_task::RetrievalTask;
use crate::cli::{flags, load};

#[derive(Debug, Args)]
pub struct RetrieveArgs {
    /// Constraint program with a relational parse (JSON).
    program: PathBuf,
    /// What to retrieve from: a motion corpus (`.safetensors.gz`: its train split, with mirrored
    /// copies), a database file of `mogen data build` (`.safetensors`) or a catalog of clips
    /// (`.json`, built in memory); default: the train split of the shipped corpus.
    #[arg(long, value_name = "FILE")]
    database: Option<PathBuf>,
    /// Retrieved motions printed, best first, one per take (its best crop; a mirror image is
    /// the same take).
    #[arg(long, default_value_t = 10)]
    top: usize,
    /// Weight of C_R's constraints other than the most difficult one.
    #[arg(long, default_value_t = RetrievalConfig::default().related_weight, value_parser = flags::weight)]
    related_weight: f64,
    /// Weight λ of the caption similarity in the shortlist's ranking (C_R score + λ·(1 − cosine of
    /// the prompt and the window's caption with its take's description); 0, the default: C_R
    /// alone, as the paper; 0.05 makes "carries a box" retrieve a box carry).
    #[arg(long, default_value_t = RetrievalConfig::default().caption_weight, value_parser = flags::weight)]
    caption_weight: f64,
    /// The same λ when the prompt asks for a skill other than walking (a crawl, a sit, a jump,
    /// ...) and only the crops that do it are scored.
    #[arg(long, default_value_t = RetrievalConfig::default().skill_caption_weight, value_parser = flags::weight)]
    skill_caption_weight: f64,
}

pub fn run(args: RetrieveArgs) -> anyhow::Result<()> {
    let device = load::device()?;
    let task = RetrievalTask::open(&args.program, args.database.as_deref(), &device)?;
    let RetrievalTask { database, source, most_difficult, open_s: opened, .. } = &task;
    let config = RetrievalConfig {
        related_weight: args.related_weight,
        caption_weight: args.caption_weight,
        skill_caption_weight: args.skill_caption_weight,
        top_k: args.top,
        ..RetrievalConfig::default()
    };
    let query = task.query();
    let clock = std::time::Instant::now();
    let found = retrieve(database, &query, &config, &device)?;
    println!(
        "C_R = {:?} (c_D = {most_difficult}, others weighted {}); {source}: {} clips, {} candidates, {} after the \
         semantic check; opened in {opened:.1} s, scored in {:.2} s",
        task.retrieval,
        config.related_weight,
        database.clips(),
        found.candidates,
        found.consistent,
        clock.elapsed().as_secs_f64()
    );
    let asked: Vec<&str> = named_actions(query.prompt).iter().map(|a| a.verb()).collect();
    if !asked.is_empty() {
        println!("the prompt \"{}\" names: {}", query.prompt, asked.join(", "));
    }
    if let Some(note) = missing_actions_note(found.missing_actions.iter().map(|a| a.verb())) {
        println!("{note}");
    }
    if let Some(skills) = &found.skills {
        println!("{skills}");
    }
    let line = |r: &Retrieved| {
        let errors: Vec<String> = r.per_constraint.iter().map(|(id, e)| format!("{id} {e:.4}")).collect();
        let similarity = r.caption_similarity.map_or(String::new(), |c| format!("  caption similarity {c:.2}"));
        format!("{:.4}  {}  {}{similarity}", r.score, r.source, errors.join(", "))
    };
    println!("best {}:", found.retrieved.len());
    for r in &found.retrieved {
        println!("  {}", line(r));
    }
    Ok(())
}
