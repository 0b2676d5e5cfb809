//! One planned task end to end, the way every command runs it: compile the program, generate
//! its motions with the configured method, evaluate them in natural units, and write every
//! output file.
//!
//! RG-DNO ([`crate::rgdno`]) takes the whole plan: the program with its relational parse (the
//! most difficult constraint and its relations, from which Algorithm 1's groups `C_R`, `C1`,
//! `C2` are derived), and the retrieval database, opened only when RG-DNO runs (a saved file, or
//! the catalog's clips built in memory). When the program has no relational parse, or no
//! database motion passes the semantic check and the threshold, the run falls back to DNO; the
//! reason goes to the report's `fallback` and to the caller as an [`Event::Note`].
//!
//! With [`TaskSettings::retry_unmet`], the samples that miss a constraint at its tolerance are
//! generated again from fresh noise, each keeping its best attempt (the report's `attempt`).

use std::time::Instant;

use candle_core::Device;

use crate::constraints::{CompiledProgram, ConstraintError};
use crate::database::DatabaseSource;
use crate::evaluation::{self, TaskReport};
use crate::export::bvh::BvhUnit;
use crate::export::{position_targets, write_outputs, ExportError, ExportInput, ExportManifest, OutputFolder};
use crate::generation::{generate, Generated, GenerationConfig, GenerationError, Method};
use crate::prior::Prior;
use crate::program::TaskProgram;
use crate::quality::tensor_to_poses;
use crate::render::{motion_gif, motion_strip, GifOptions, RenderError, StripRow};
use crate::rgdno::retrieval::RetrievalCorpus;
use crate::rgdno::{generate_rg_dno, RgDnoConfig, RgDnoError, RgDnoReport, RgDnoTask};
use crate::skeleton::{Pose, FPS};

/// How a task is run: the method and its settings, RG-DNO's stages and where it retrieves from.
#[derive(Debug, Clone)]
pub struct TaskSettings {
    /// Method, samples, seed, guidance, DNO's optimiser (its `restarts` are RG-DNO's `N_S`
    /// too), the refinement and the clean-up.
    pub generation: GenerationConfig,
    /// RG-DNO's stages.
    pub rg_dno: RgDnoConfig,
    /// RG-DNO's retrieval database.
    pub database: DatabaseSource,
    /// Further attempts for the samples that miss a constraint at its tolerance: each such
    /// sample is generated again from fresh start noise (attempt k + 1 from seed + k·N_S) and
    /// keeps its best attempt (most constraints met, then the lowest constraint error), up to
    /// this many times (DNO's noise search, spent only where it is needed). 0: off.
    pub retry_unmet: usize,
}

/// What a running task reports.
#[derive(Debug, Clone)]
pub enum Event<'a> {
    /// An optimisation step of a stage (`round` is the restart).
    Step {
        /// The method or RG-DNO stage.
        stage: &'a str,
        /// The restart.
        round: usize,
        /// Steps done.
        step: usize,
        /// Steps of the stage.
        steps: usize,
        /// Mean loss over the samples.
        loss: f64,
    },
    /// Something the user should read: the retrieval corpus built, a fallback and its reason.
    Note(String),
}

/// A finished run: the motions and their report.
#[derive(Debug, Clone)]
pub struct TaskRun {
    /// The motions (the cleaned joints, the network's beside them).
    pub generated: Generated,
    /// Every figure in natural units; RG-DNO's stages or the fallback's reason.
    pub report: TaskReport,
}

/// Errors of a task run.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    /// The program does not compile.
    #[error(transparent)]
    Program(#[from] ConstraintError),
    /// Generation failed or a setting is unusable.
    #[error(transparent)]
    Generation(#[from] GenerationError),
    /// RG-DNO failed (a reason to fall back never reaches the caller).
    #[error(transparent)]
    RgDno(#[from] RgDnoError),
    /// A tensor operation failed.
    #[error(transparent)]
    Tensor(#[from] candle_core::Error),
    /// A figure of the report is NaN or infinite; nothing is written.
    #[error("the report's {0} is not finite; nothing was written")]
    NonFinite(String),
    /// Writing a file failed.
    #[error(transparent)]
    Export(#[from] ExportError),
    /// Drawing a picture failed.
    #[error(transparent)]
    Render(#[from] RenderError),
    /// The report could not be serialised.
    #[error("writing the report: {0}")]
    Json(#[from] serde_json::Error),
}

/// Runs `program` with `settings`: compile, generate (RG-DNO with its fallback to DNO), and
/// evaluate; then, with [`TaskSettings::retry_unmet`], generate the samples that miss a
/// constraint again and keep each one's best attempt. `on` gets every optimisation step and
/// the notes a user should read.
pub fn run_task(
    prior: &Prior,
    program: &TaskProgram,
    settings: &TaskSettings,
    device: &Device,
    mut on: impl FnMut(Event<'_>),
) -> Result<TaskRun, PipelineError> {
    let compiled = CompiledProgram::compile(program, device)?;
    let mut config = settings.generation.clone();
    let mut fallback = None;
    let mut corpus = None;
    if config.method == Method::RgDno {
        match rg_dno_corpus(program, &compiled, settings, device, &mut on) {
            Ok(built) => corpus = Some(built),
            Err(e) => fallback = Some(fall_back(e, &mut config, &mut on)?),
        }
    }
    let attempt = Attempt { prior, program, compiled: &compiled, corpus: corpus.as_ref(), settings, device };
    let (mut generated, mut rg_report) = match attempt.run(&config, &mut on) {
        Err(PipelineError::RgDno(e @ RgDnoError::NothingRetrieved)) => {
            fallback = Some(fall_back(e, &mut config, &mut on)?);
            attempt.run(&config, &mut on)?
        }
        done => done?,
    };
    let mut report = evaluation::report(program, &compiled, &generated, &config)?;
    let mut kept = vec![0; config.samples];
    for k in 1..=settings.retry_unmet {
        let unmet = report.unmet_samples();
        if unmet.is_empty() {
            break;
        }
        let seed = retry_seed(&config, k);
        let list = unmet.iter().map(usize::to_string).collect::<Vec<_>>().join(", ");
        on(Event::Note(format!(
            "attempt {} of {}: sample(s) {list} miss a constraint; generating them again from seed {seed}",
            k + 1,
            settings.retry_unmet + 1
        )));
        let retry_config = GenerationConfig { samples: unmet.len(), seed, ..config.clone() };
        let (retry, retry_rg) = attempt.run(&retry_config, &mut on)?;
        let retry_report = evaluation::report(program, &compiled, &retry, &retry_config)?;
        let mut rows = vec![None; config.samples];
        for (i, &b) in unmet.iter().enumerate() {
            if report.beaten_by(b, &retry_report, i) {
                rows[b] = Some(i);
                kept[b] = k;
            }
        }
        generated = generated.with_rows_from(retry, &rows)?;
        rg_report = match (rg_report, retry_rg) {
            (Some(own), Some(other)) => Some(own.with_rows_from(other, &rows)),
            (own, _) => own,
        };
        report = evaluation::report(program, &compiled, &generated, &config)?;
    }
    report.rg_dno = rg_report;
    report.fallback = fallback;
    report.attempt = (settings.retry_unmet > 0).then_some(kept);
    if let Some(figure) = report.non_finite_figure() {
        return Err(PipelineError::NonFinite(figure));
    }
    Ok(TaskRun { generated, report })
}

/// The start seed of retry `k` (≥ 1): `seed + k·N_S`, so that no retry repeats a start noise of
/// an earlier attempt's restarts (restart r of an attempt from seed s starts from s + r).
fn retry_seed(config: &GenerationConfig, k: usize) -> u64 {
    config.seed.wrapping_add((k * config.dno.restarts.max(1)) as u64)
}

/// Switches `config` to DNO when `error` is a reason to fall back (no relational parse, nothing
/// retrieved), telling `on` why; any other error is returned.
fn fall_back(
    error: RgDnoError,
    config: &mut GenerationConfig,
    on: &mut impl FnMut(Event<'_>),
) -> Result<String, PipelineError> {
    match error {
        RgDnoError::NoParse | RgDnoError::NothingRetrieved => {
            let why = error.to_string();
            on(Event::Note(format!("RG-DNO falls back to DNO: {why}")));
            config.method = Method::Dno;
            Ok(why)
        }
        error => Err(error.into()),
    }
}

/// RG-DNO's retrieval corpus for `program`: opens the database and crops its windows to the
/// program's frame count (built once for every attempt).
fn rg_dno_corpus(
    program: &TaskProgram,
    compiled: &CompiledProgram,
    settings: &TaskSettings,
    device: &Device,
    on: &mut impl FnMut(Event<'_>),
) -> Result<RetrievalCorpus, RgDnoError> {
    if program.relational_parse.is_none() {
        return Err(RgDnoError::NoParse);
    }
    let clock = Instant::now();
    let source = &settings.database;
    let (database, warnings) = source
        .open()
        .map_err(|error| RgDnoError::Database { source_name: source.to_string(), error: Box::new(error) })?;
    let corpus = RetrievalCorpus::build(&database, compiled.frames(), &settings.rg_dno.retrieval, device)?;
    // Import warnings (quaternions normalised on read) are `mogen data build`'s to list.
    let warned = if warnings.is_empty() { String::new() } else { format!(", {} import warnings", warnings.len()) };
    on(Event::Note(format!(
        "retrieval corpus: {} candidate crops of {source} ({:.1} s{warned})",
        corpus.len(),
        clock.elapsed().as_secs_f64()
    )));
    Ok(corpus)
}

/// One attempt at a compiled task: everything but the generation settings, which change from
/// attempt to attempt (the samples, the seed, the method after a fallback).
struct Attempt<'a> {
    prior: &'a Prior,
    program: &'a TaskProgram,
    compiled: &'a CompiledProgram,
    /// RG-DNO's corpus; `None` when the method is not RG-DNO.
    corpus: Option<&'a RetrievalCorpus>,
    settings: &'a TaskSettings,
    device: &'a Device,
}

impl Attempt<'_> {
    /// Generates with `config` (RG-DNO on the corpus when the method is RG-DNO).
    fn run(
        &self,
        config: &GenerationConfig,
        on: &mut impl FnMut(Event<'_>),
    ) -> Result<(Generated, Option<RgDnoReport>), PipelineError> {
        let Attempt { prior, program, compiled, corpus, settings, device } = *self;
        match (config.method, corpus) {
            (Method::RgDno, Some(corpus)) => {
                let task = RgDnoTask { program, compiled, corpus };
                let (generated, report) = generate_rg_dno(prior, task, config, &settings.rg_dno, device, |p| {
                    on(Event::Step {
                        stage: p.stage.name(),
                        round: p.round,
                        step: p.step,
                        steps: p.steps,
                        loss: p.loss,
                    })
                })?;
                Ok((generated, Some(report)))
            }
            _ => {
                let stage = config.method.to_string();
                let generated = generate(prior, program, compiled, config, device, |p| {
                    on(Event::Step { stage: &stage, round: p.round, step: p.step + 1, steps: p.steps, loss: p.loss })
                })?;
                Ok((generated, None))
            }
        }
    }
}

/// Choices about the exported files (default: no GIF, BVH in metres).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ExportOptions {
    /// Also write `motion.gif` (side and top views, animated).
    pub gif: bool,
    /// Length unit of the BVH files.
    pub bvh_unit: BvhUnit,
}

/// Writes a run into `folder` (committed by the caller): `features.npy` (de-normalised
/// features of the network's motion), `joints.npy` (the output), `report.json`, `strip.png`,
/// `program.json`, and the exports of [`write_exports`].
pub fn write_task(
    folder: &OutputFolder,
    prior: &Prior,
    program: &TaskProgram,
    run: &TaskRun,
    options: ExportOptions,
) -> Result<ExportManifest, PipelineError> {
    let (generated, report) = (&run.generated, &run.report);
    let config = &report.config;
    folder.write_npy("features.npy", &prior.to_features(&generated.features)?)?;
    folder.write_npy("joints.npy", &generated.joints)?;
    folder.write("report.json", serde_json::to_string_pretty(report)?.as_bytes())?;
    let poses = tensor_to_poses(&generated.joints)?;
    // A retried sample is labelled with the seed of the attempt it kept.
    let seed = |i: usize| match report.attempt.as_ref().and_then(|a| a.get(i)) {
        Some(&k) if k > 0 => retry_seed(config, k),
        _ => config.seed,
    };
    let labels: Vec<String> =
        (0..poses.len()).map(|i| format!("{} sample {i} (seed {})", config.method, seed(i))).collect();
    let rows: Vec<StripRow<'_>> =
        poses.iter().zip(&labels).map(|(p, label)| StripRow { label: label.clone(), poses: p }).collect();
    let (scene, carried) = (program.scene_primitives(), program.carried_objects());
    motion_strip(&rows, 8, &scene, &carried, &program.text, &folder.path().join("strip.png"))?;
    folder.write("program.json", (serde_json::to_string_pretty(program)? + "\n").as_bytes())?;
    let report_json = Some(serde_json::to_value(report)?);
    write_exports(folder, &program.text, FPS, &poses, labels, Some(program), report_json, options)
}

/// Writes the BVH and GLB of every motion, the viewer page, `export.json` and, when asked,
/// `motion.gif` into `folder` (committed by the caller). `labels` name the motions; `program`'s
/// scene, position targets and carried objects are drawn; `report` is shown by the viewer.
#[allow(clippy::too_many_arguments)]
pub fn write_exports(
    folder: &OutputFolder,
    title: &str,
    fps: f64,
    motions: &[Vec<Pose>],
    labels: Vec<String>,
    program: Option<&TaskProgram>,
    report: Option<serde_json::Value>,
    options: ExportOptions,
) -> Result<ExportManifest, PipelineError> {
    let input = ExportInput {
        title: title.to_owned(),
        fps,
        samples: labels.into_iter().zip(motions).map(|(label, p)| (label, p.as_slice())).collect(),
        scene: program.map(TaskProgram::scene_primitives).unwrap_or_default(),
        targets: program.map(position_targets).unwrap_or_default(),
        carried: program.map(TaskProgram::carried_objects).unwrap_or_default(),
        report,
        bvh_unit: options.bvh_unit,
    };
    let manifest = write_outputs(folder.path(), &input)?;
    if options.gif {
        let rows: Vec<StripRow<'_>> =
            input.samples.iter().map(|(label, poses)| StripRow { label: label.clone(), poses }).collect();
        motion_gif(&rows, &input.scene, title, &GifOptions::default(), &folder.path().join("motion.gif"))?;
    }
    Ok(manifest)
}
