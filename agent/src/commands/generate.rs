//! The motion generator behind a planned task: the one place the command line hands a validated
//! program to the optimiser.

use std::path::PathBuf;

use agent::plan::PlannedTask;

/// What to generate.
#[derive(Debug, Clone)]
pub struct RunOptions {
    /// Motions to generate.
    pub samples: usize,
    /// Seed of the start noise.
    pub seed: u64,
    /// Output folder (already holds `program.json`).
    pub out: PathBuf,
}

/// Generates the motions of `planned` into `options.out`.
///
/// The constraint compiler and the DNO / RG-DNO runner are not connected yet: for now this says
/// so and leaves the planned program as the output.
pub fn run(planned: &PlannedTask, options: &RunOptions) -> anyhow::Result<()> {
    eprintln!(
        "motion generation is not connected yet: {} sample(s) with seed {} of the {}-constraint program would go to {}",
        options.samples,
        options.seed,
        planned.program.constraints.len(),
        options.out.display()
    );
    Ok(())
}
