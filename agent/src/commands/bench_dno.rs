//! `mogen bench dno`: the wall time of a full DNO run at several batch sizes.

use std::path::PathBuf;
use std::time::Instant;

use clap::Args;
use motion_core::generation::generate;
use motion_core::generation::method::{GenerationConfig, Method, Task};

use crate::cli::flags;
use crate::cli::load::{device, load_prior, load_program};
use agent::paths;

#[derive(Debug, Args)]
pub struct BenchDnoArgs {
    /// Task program to optimise (its frame count sets the motion length).
    #[arg(long, default_value_os_t = paths::fixtures_dir().join("tasks").join("rgdno_task1_narrow_gap.json"))]
    task: PathBuf,
    /// Batch sizes to time.
    #[arg(long, value_delimiter = ',', default_values_t = [1usize, 8])]
    batches: Vec<usize>,
    /// DNO steps.
    #[arg(long, default_value_t = 500)]
    steps: usize,
    /// Classifier-free guidance scale (1: one denoiser call per DDIM step; 2.5 doubles it).
    #[arg(long, default_value_t = 1.0, value_parser = flags::guidance)]
    guidance: f64,
    /// Trained prior file.
    #[arg(long, default_value_os_t = paths::default_prior())]
    prior: PathBuf,
}

pub fn run(args: BenchDnoArgs) -> anyhow::Result<()> {
    let device = device()?;
    let prior = load_prior(&args.prior, &device)?;
    let checked = load_program(&args.task, &device)?;
    let (program, compiled) = (checked.program(), checked.compiled());
    println!(
        "DNO {} steps on {} ({} frames), guidance {}; {} threads; the time includes the refinement and the foot clean-up",
        args.steps,
        args.task.display(),
        program.frames,
        args.guidance,
        rayon::current_num_threads()
    );
    println!("| batch | total (s) | per step (s) | constraint error before → after |\n|---|---|---|---|");
    for &batch in &args.batches {
        let mut config = GenerationConfig::new(Method::Dno);
        config.samples = batch;
        config.guidance = args.guidance;
        config.dno.steps = args.steps;
        let start = Instant::now();
        let generated = generate(&prior, Task { program, compiled }, None, &config, &device, |_| {})?.generated;
        let total = start.elapsed().as_secs_f64();
        let first: f64 = generated.loss_history.iter().filter_map(|h| h.first()).sum::<f64>() / batch as f64;
        let last: f64 = generated.loss_history.iter().filter_map(|h| h.last()).sum::<f64>() / batch as f64;
        println!("| {batch} | {total:.1} | {:.4} | {first:.5} → {last:.5} |", total / args.steps as f64);
    }
    Ok(())
}
