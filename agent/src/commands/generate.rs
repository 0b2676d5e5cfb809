//! The motion generator behind a planned task: the one place the command line hands a validated
//! program to the optimiser.

use std::path::PathBuf;

use agent::plan::PlannedTask;
use anyhow::Context;
use motion_core::export::OutputFolder;
use motion_core::generation::GenerationConfig;
use motion_core::prior::Prior;

use super::run::{print_summary, run_program};

/// What to generate.
#[derive(Debug, Clone)]
pub struct RunOptions {
    /// Method, samples, seed and optimiser settings.
    pub config: GenerationConfig,
    /// The trained prior.
    pub prior: PathBuf,
    /// Where RG-DNO retrieves from, and its settings.
    pub rg_source: super::run::RgDnoSource,
    /// Choices about the exported files.
    pub formats: super::export::ExportFormats,
}

/// Generates the motions of `planned` into `out` with the configured method (DNO by
/// default; RG-DNO's retrieval stages will use the plan's constraint groups when they land) and
/// prints the report's headline figures.
pub fn run(planned: &PlannedTask, options: &RunOptions, out: OutputFolder) -> anyhow::Result<()> {
    let device = candle_core::Device::Cpu;
    let prior = Prior::load(&options.prior, &device)
        .with_context(|| format!("loading the prior {}", options.prior.display()))?;
    let report = run_program(&prior, &planned.program, &options.config, &options.rg_source, out, options.formats)?;
    print_summary(&report);
    Ok(())
}
