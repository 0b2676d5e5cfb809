//! What every command loads: the device, a constraint program, the trained prior and RG-DNO's
//! retrieval database, each error naming the file.

use std::path::Path;

use anyhow::Context;
use candle_core::Device;
use motion_core::constraints::checked::CheckedProgram;
use motion_core::pipeline::{retrieves, OpenedDatabase, TaskSettings};
use motion_core::prior::Prior;

/// The one device every command computes on: the first CUDA GPU in a build with the `cuda`
/// feature, the CPU otherwise.
pub fn device() -> anyhow::Result<Device> {
    #[cfg(feature = "cuda")]
    return Device::new_cuda(0).context("opening CUDA device 0");
    #[cfg(not(feature = "cuda"))]
    Ok(Device::Cpu)
}

/// Reads a program file (bounded in size), runs every check of a planned task on it and compiles
/// it on `device`; the error lists every problem with its JSON path.
pub fn load_program(path: &Path, device: &Device) -> anyhow::Result<CheckedProgram> {
    Ok(agent::plan::plan_from_file(path, device)?.program)
}

/// Loads the trained prior at `path` onto `device`, its sentence encoder (if it has one) from the
/// shipped text models.
pub fn load_prior(path: &Path, device: &Device) -> anyhow::Result<Prior> {
    Prior::load(path, &agent::paths::text_models(), device)
        .with_context(|| format!("loading the prior {}", path.display()))
}

/// The trained prior at `path` (as [`load_prior`]) and, when a run of `program` with `settings`
/// [`retrieves`], RG-DNO's retrieval database, opened on a thread of its own while the prior and
/// its text models load: each takes about a second on two cores.
pub fn load_prior_and_database(
    path: &Path,
    program: &CheckedProgram,
    settings: &TaskSettings,
    device: &Device,
) -> anyhow::Result<(Prior, Option<OpenedDatabase>)> {
    std::thread::scope(|scope| {
        let opening = retrieves(program.program(), settings).then(|| scope.spawn(|| OpenedDatabase::open(settings)));
        let prior = load_prior(path, device)?;
        let database = match opening.map(|thread| thread.join()) {
            None => None,
            Some(Ok(opened)) => Some(opened.with_context(|| format!("opening {}", settings.database))?),
            Some(Err(_)) => anyhow::bail!("opening {} stopped with a panic", settings.database),
        };
        Ok((prior, database))
    })
}
