//! `mogen run`: generate motions for a constraint program file with one method.

use std::path::PathBuf;

use clap::Args;
use motion_core::export::OutputFolder;

use crate::cli::generation_args::{GenerationArgs, MethodArg};
use crate::cli::load::{device, load_prior_and_database, load_program};
use crate::cli::progress::run_with_progress;

#[derive(Debug, Args)]
pub struct RunArgs {
    /// Constraint program (JSON; see fixtures/tasks/ and `mogen schema`).
    program: PathBuf,
    /// Generation method.
    #[arg(long, short, value_enum, default_value_t = MethodArg::Dno)]
    method: MethodArg,
    #[command(flatten)]
    generation: GenerationArgs,
    /// Output folder: features.npy [n, frames, 263] (de-normalised HumanML3D features of the
    /// network's motion, before the foot clean-up), joints.npy [n, frames, 22, 3] (m, y up, 20
    /// fps, bones at the rest lengths, after the clean-up: the output), report.json (every
    /// constraint in natural units with pass/fail, before and after the clean-up), strip.png
    /// (world coordinates, the scene drawn), program.json, `sample_<i>/motion.bvh` and
    /// `sample_<i>/motion.glb` (rotations on a rigid skeleton; the GLB has a skinned figure and the
    /// scene), viewer.html (3-D, offline) and export.json (the files and the rotation fit).
    #[arg(long, short, default_value = "out/run")]
    out: PathBuf,
}

pub fn run(args: RunArgs) -> anyhow::Result<()> {
    let device = device()?;
    let program = load_program(&args.program, &device)?;
    let folder = OutputFolder::create(&args.out)?;
    let settings = args.generation.settings(args.method.into())?;
    let (prior, database) = load_prior_and_database(&args.generation.prior, &program, &settings, &device)?;
    let report = run_with_progress(&prior, &program, &settings, database.as_ref(), folder, &device)?;
    print!("{}", report.summary());
    Ok(())
}
