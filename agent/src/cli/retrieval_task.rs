//! A program's retrieval group opened for RG-DNO's constraint-based retrieval on its own.

use std::path::Path;

use anyhow::Context;
use candle_core::Device;
use motion_core::constraints::CompiledProgram;
use motion_core::generation::rgdno::candidates::{RetrievalDatabase, RetrievalSource};
use motion_core::generation::rgdno::retrieval::RetrievalQuery;
use motion_core::program::TaskProgram;
use motion_core::text::{ConditionEncoder, MINILM_NAME};

use super::generation_args::retrieval_source;
use super::load::load_program;

/// What a retrieval command works on: the program, its retrieval group C_R compiled, its most
/// difficult constraint c_D, and the retrieval database opened (with the seconds that took).
pub struct RetrievalTask {
    /// The program.
    pub program: TaskProgram,
    /// C_R's constraint ids.
    pub retrieval: Vec<String>,
    /// C_R compiled.
    pub compiled: CompiledProgram,
    /// c_D's id.
    pub most_difficult: String,
    /// Where the database came from.
    pub source: RetrievalSource,
    /// The database.
    pub database: RetrievalDatabase,
    /// Seconds opening the database took.
    pub open_s: f64,
    /// The shipped sentence encoder (the prior's), for retrieval's caption similarity.
    pub encoder: ConditionEncoder,
}

impl RetrievalTask {
    /// Reads the program at `program` (it needs a relational parse) and opens `database` (the
    /// shipped corpus's train split when `None`).
    pub fn open(program: &Path, database: Option<&Path>, device: &Device) -> anyhow::Result<Self> {
        let checked = load_program(program, device)?;
        let task = checked.program().clone();
        let groups = task
            .constraint_groups()
            .with_context(|| format!("{} has no relational parse: nothing to retrieve for", program.display()))?;
        let most_difficult = task.relational_parse.as_ref().map(|p| p.most_difficult.clone()).unwrap_or_default();
        let compiled = checked.compiled().subset(&groups.retrieval);
        let source = retrieval_source(database);
        let clock = std::time::Instant::now();
        let (database, _) = source.open().with_context(|| format!("opening {source}"))?;
        let open_s = clock.elapsed().as_secs_f64();
        let text_models = agent::paths::text_models();
        let encoder = ConditionEncoder::sentence(MINILM_NAME, &text_models, device)
            .with_context(|| format!("loading the sentence encoder from {}", text_models.display()))?;
        Ok(Self {
            program: task,
            retrieval: groups.retrieval,
            compiled,
            most_difficult,
            source,
            database,
            open_s,
            encoder,
        })
    }

    /// The retrieval query of the task.
    pub fn query(&self) -> RetrievalQuery<'_> {
        RetrievalQuery {
            program: &self.compiled,
            most_difficult: &self.most_difficult,
            prompt: &self.program.text,
            counting: !self.compiled.count_targets().is_empty(),
            encoder: Some(&self.encoder),
        }
    }
}
