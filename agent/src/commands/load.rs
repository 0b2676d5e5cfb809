//! The files every command reads: a constraint program and the trained prior, each error
//! naming the file.

use std::path::Path;

use anyhow::Context;
use candle_core::Device;
use motion_core::prior::Prior;
use motion_core::program::TaskProgram;

/// Reads a program file (bounded in size) and runs every check of a planned task on it; the
/// error lists every problem with its JSON path.
pub fn load_program(path: &Path) -> anyhow::Result<TaskProgram> {
    Ok(agent::plan::plan_from_file(path)?.program)
}

/// Loads the trained prior at `path` onto `device`, its sentence encoder (if it has one) from the
/// shipped text models.
pub fn load_prior(path: &Path, device: &Device) -> anyhow::Result<Prior> {
    Prior::load(path, &crate::paths::text_models(), device)
        .with_context(|| format!("loading the prior {}", path.display()))
}
