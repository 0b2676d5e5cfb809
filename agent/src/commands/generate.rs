//! The motion generator behind a planned task: the one place the command line hands a validated
//! program to the optimiser.

use std::path::PathBuf;

use agent::plan::PlannedTask;
use motion_core::export::OutputFolder;
use motion_core::pipeline::TaskSettings;

use super::run::{print_summary, run_program};

/// What to generate.
#[derive(Debug, Clone)]
pub struct RunOptions {
    /// Method, samples, seed, optimiser settings, RG-DNO's stages and database.
    pub settings: TaskSettings,
    /// The trained prior.
    pub prior: PathBuf,
    /// Choices about the exported files.
    pub formats: super::export::ExportFormats,
}

/// Generates the motions of `planned` into `out` with the configured method (RG-DNO, through
/// the plan's relational parse and Algorithm 1's groups, falls back to DNO and says why without
/// them) and prints the report's headline figures.
pub fn run(planned: &PlannedTask, options: &RunOptions, out: OutputFolder) -> anyhow::Result<()> {
    let device = candle_core::Device::Cpu;
    let prior = super::load::load_prior(&options.prior, &device)?;
    let report = run_program(&prior, &planned.program, &options.settings, out, options.formats)?;
    print_summary(&report);
    Ok(())
}
