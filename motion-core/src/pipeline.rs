//! One checked task end to end, the way every command runs it ([`run_task`]): generate its
//! motions with the configured method, evaluate them in natural units, and write every output
//! file into a folder that appears whole or not at all.
//!
//! RG-DNO ([`crate::generation::rgdno`]) takes the whole plan: the program with its relational parse (the
//! most difficult constraint and its relations, from which Algorithm 1's groups `C_R`, `C1`,
//! `C2` are derived), and the retrieval database, opened only when RG-DNO runs (the corpus's
//! train split, a saved database file, or a catalog's clips built in memory). When the program
//! has no relational parse, or no database motion passes the semantic check and the threshold,
//! the run falls back to DNO; the
//! reason goes to the report's `fallback` and to the caller as an [`Event::Note`].
//!
//! With [`TaskSettings::retry_unmet`], the samples that miss a constraint at its tolerance, or
//! that do not do the skill the prompt asks for ([`crate::evaluation::SkillReport::asked`]),
//! are generated again from fresh noise, each keeping its best attempt (the report's
//! `attempt`).

use std::path::PathBuf;
use std::time::Instant;

use candle_core::Device;

use crate::constraints::checked::CheckedProgram;
use crate::evaluation::{self, TaskReport};
use crate::export::bvh::BvhUnit;
use crate::export::retarget::{RigJudge, TargetRig};
use crate::export::{position_targets, write_outputs, ExportError, ExportInput, ExportManifest, OutputFolder};
use crate::generation::method::{Generated, GenerationConfig, Method, Task};
use crate::generation::rgdno::candidates::{RetrievalDatabase, RetrievalSource};
use crate::generation::rgdno::config::RgDnoConfig;
use crate::generation::rgdno::error::RetrievalError;
use crate::generation::{generate, Event, GenerateError, Retrieval};
use crate::motion::tensor_to_poses;
use crate::prior::Prior;
use crate::program::TaskProgram;
use crate::render::{motion_gif, motion_strip, GifOptions, RenderError, StripRow};
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
    pub database: RetrievalSource,
    /// Further attempts for the samples that miss a constraint at its tolerance or do not do
    /// the skill the prompt asks for: each such sample is generated again from fresh start
    /// noise (attempt k + 1 from seed + k·N_S; with RG-DNO, from the next retrieved takes) and
    /// keeps its best attempt ([`TaskReport::beaten_by`]: most constraints met, then the skill
    /// done, then the lowest constraint error), up to this many times (DNO's noise search,
    /// spent only where it is needed). 0: off.
    pub retry_unmet: usize,
    /// Choices about the exported files.
    pub exports: ExportOptions,
}

/// A finished run: the motions and their report.
#[derive(Debug, Clone)]
struct TaskRun {
    /// The motions (the cleaned joints, the network's beside them).
    generated: Generated,
    /// Every figure in natural units; RG-DNO's stages or the fallback's reason.
    report: TaskReport,
}

/// A finished and written run: its report, the exported files and the folder they are in.
#[derive(Debug, Clone)]
pub struct TaskOutcome {
    /// Every figure in natural units; RG-DNO's stages or the fallback's reason.
    pub report: TaskReport,
    /// The BVH, GLB and viewer files with the rotation solve's fit.
    pub exports: ExportManifest,
    /// The output folder, written whole.
    pub folder: PathBuf,
}

/// Errors of a task run.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    /// Generation failed or a setting is unusable.
    #[error(transparent)]
    Generation(#[from] GenerateError),
    /// RG-DNO's retrieval database could not be opened.
    #[error(transparent)]
    Retrieval(#[from] RetrievalError),
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

/// RG-DNO's retrieval database opened from a run's [`TaskSettings::database`], with the note that
/// says what it holds and how long it took to open.
pub struct OpenedDatabase {
    database: RetrievalDatabase,
    note: String,
}

impl OpenedDatabase {
    /// Opens `settings.database` (its crops are made per query).
    pub fn open(settings: &TaskSettings) -> Result<Self, PipelineError> {
        let clock = Instant::now();
        let source = &settings.database;
        let (database, warnings) = source.open()?;
        // Import warnings (quaternions normalised on read) are `mogen data build`'s to list.
        let warned = if warnings.is_empty() { String::new() } else { format!(", {} import warnings", warnings.len()) };
        let note = format!(
            "retrieval database: {} clips ({:.2} h) of {source}, {:.0} MB held (opened in {:.1} s{warned})",
            database.clips(),
            database.seconds() / 3600.0,
            database.bytes() as f64 / 1e6,
            clock.elapsed().as_secs_f64()
        );
        Ok(OpenedDatabase { database, note })
    }
}

/// Whether a run of `program` with `settings` retrieves: RG-DNO with a relational parse. Only
/// such a run opens the database, and only for such a run may a caller open it beforehand.
pub fn retrieves(program: &TaskProgram, settings: &TaskSettings) -> bool {
    settings.generation.method == Method::RgDno && program.relational_parse.is_some()
}

/// Runs `program` with `settings` on `device` and writes every output into `folder`, which is
/// committed only when everything is made (a failure leaves the target as it was): the one
/// call behind every command that generates for a task. `database`, when given, is
/// `settings.database` already opened (a command opens it beside its own loading, or once for
/// many runs); otherwise the run opens it when it [`retrieves`]. `on` gets every optimisation
/// step and the notes a user should read.
pub fn run_task(
    prior: &Prior,
    program: &CheckedProgram,
    settings: &TaskSettings,
    database: Option<&OpenedDatabase>,
    folder: OutputFolder,
    device: &Device,
    on: impl FnMut(Event<'_>),
) -> Result<TaskOutcome, PipelineError> {
    let run = generate_task(prior, program, settings, database, device, on)?;
    let exports = write_task(&folder, prior, program, &run, &settings.exports)?;
    let folder = folder.commit()?;
    Ok(TaskOutcome { report: run.report, exports, folder })
}

/// Generates and evaluates `program` with `settings` (RG-DNO with its fallback to DNO); then,
/// with [`TaskSettings::retry_unmet`], generates the samples that miss a constraint or the skill
/// the prompt asks for again (from fresh noise and, with RG-DNO, from the next retrieved takes)
/// and keeps each one's best attempt.
fn generate_task(
    prior: &Prior,
    checked: &CheckedProgram,
    settings: &TaskSettings,
    database: Option<&OpenedDatabase>,
    device: &Device,
    mut on: impl FnMut(Event<'_>),
) -> Result<TaskRun, PipelineError> {
    let (program, compiled) = (checked.program(), checked.compiled());
    let task = Task { program, compiled };
    let mut config = settings.generation.clone();
    // The database is opened once for every attempt, and only when RG-DNO can use it.
    let opened;
    let database = match database {
        _ if !retrieves(program, settings) => None,
        Some(database) => Some(database),
        None => {
            opened = OpenedDatabase::open(settings)?;
            Some(&opened)
        }
    };
    if let Some(database) = database {
        on(Event::Note(database.note.clone()));
    }
    let retrieval = database.map(|opened| Retrieval { database: &opened.database, rg_dno: &settings.rg_dno });
    let first = generate(prior, task, retrieval, &config, device, &mut on)?;
    // After a fallback, the report and every retry are DNO's.
    config.method = first.method;
    let (mut generated, mut rg_report, fallback) = (first.generated, first.rg_dno, first.fallback);
    let mut report = evaluation::report(program, compiled, &generated, &config)?;
    let mut kept = vec![0; config.samples];
    for k in 1..=settings.retry_unmet {
        let (missed, unskilled) = (report.unmet_samples(), report.skill_missed_samples());
        if missed.is_empty() && unskilled.is_empty() {
            break;
        }
        let seed = retry_seed(&config, k);
        on(Event::Note(format!(
            "attempt {} of {}: {}; generating them again from seed {seed}",
            k + 1,
            settings.retry_unmet + 1,
            short_samples(&missed, &unskilled, &report)
        )));
        let mut unmet = [missed, unskilled].concat();
        unmet.sort_unstable();
        let retry_config = GenerationConfig { samples: unmet.len(), seed, ..config.clone() };
        let rg_dno = retry_rg_dno(&settings.rg_dno, k);
        let retrieval = retrieval.map(|r| Retrieval { rg_dno: &rg_dno, ..r });
        let retry = generate(prior, task, retrieval, &retry_config, device, &mut on)?;
        let retry_report = evaluation::report(program, compiled, &retry.generated, &retry_config)?;
        let mut rows = vec![None; config.samples];
        for (i, &b) in unmet.iter().enumerate() {
            if report.beaten_by(b, &retry_report, i) {
                rows[b] = Some(i);
                kept[b] = k;
            }
        }
        generated = generated.with_rows_from(retry.generated, &rows)?;
        rg_report = match (rg_report, retry.rg_dno) {
            (Some(own), Some(other)) => Some(own.with_rows_from(other, &rows)),
            (own, _) => own,
        };
        report = evaluation::report(program, compiled, &generated, &config)?;
    }
    report.prior = prior.identity.clone();
    report.rg_dno = rg_report;
    report.fallback = fallback;
    report.attempt = (settings.retry_unmet > 0).then_some(kept);
    if let Some(figure) = report.non_finite_figure() {
        return Err(PipelineError::NonFinite(figure));
    }
    Ok(TaskRun { generated, report })
}

/// Why samples are generated again: "sample(s) 0, 2 miss a constraint", "sample(s) 1 do not do
/// the skill the prompt asks for (hop on one foot: airborne ≥ 2 frames)", or both joined.
fn short_samples(missed: &[usize], unskilled: &[usize], report: &TaskReport) -> String {
    let list = |s: &[usize]| s.iter().map(usize::to_string).collect::<Vec<_>>().join(", ");
    let mut why = Vec::new();
    if !missed.is_empty() {
        why.push(format!("sample(s) {} miss a constraint", list(missed)));
    }
    if let (false, Some(skill)) = (unskilled.is_empty(), &report.skill) {
        why.push(format!(
            "sample(s) {} do not do the skill the prompt asks for ({}: {})",
            list(unskilled),
            skill.family,
            skill.detector
        ));
    }
    why.join("; ")
}

/// The start seed of retry `k` (≥ 1): `seed + k·N_S`, so that no retry repeats a start noise of
/// an earlier attempt's restarts (restart r of an attempt from seed s starts from s + r).
fn retry_seed(config: &GenerationConfig, k: usize) -> u64 {
    config.seed.wrapping_add((k * config.dno.restarts.max(1)) as u64)
}

/// RG-DNO's settings for retry `k` (≥ 1): it starts from the retrieved takes after those of the
/// earlier attempts, so that a sample a take did not serve is tried from another.
fn retry_rg_dno(rg: &RgDnoConfig, k: usize) -> RgDnoConfig {
    RgDnoConfig { skip_retrieved: rg.skip_retrieved + k * rg.retrieved_motions, ..rg.clone() }
}

/// Choices about the exported files (default: no GIF, BVH in metres, the motion's frame rate, no
/// rig of the user's).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ExportOptions {
    /// Also write `motion.gif` (side and top views, animated).
    pub gif: bool,
    /// Length unit of the BVH files.
    pub bvh_unit: BvhUnit,
    /// Frame rate of the BVH and GLB files, frames per second (rotations resampled by slerp:
    /// [`crate::export::RotationTrack::resampled`]); `None`: the motion's own.
    pub fps: Option<u32>,
    /// Leave the root's horizontal motion out of the BVH and GLB files
    /// ([`crate::export::RotationTrack::in_place`]).
    pub in_place: bool,
    /// A rig of the user's to write every motion onto as well
    /// ([`crate::export::retarget`]).
    pub rig: Option<TargetRig>,
}

/// Writes a run into `folder` (committed by the caller): `features.npy` (de-normalised
/// features of the network's motion), `joints.npy` (the output), `report.json`, `strip.png`,
/// `program.json`, and the exports of [`write_exports`].
fn write_task(
    folder: &OutputFolder,
    prior: &Prior,
    checked: &CheckedProgram,
    run: &TaskRun,
    options: &ExportOptions,
) -> Result<ExportManifest, PipelineError> {
    let program = checked.program();
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
    let initial = tensor_to_poses(&generated.initial_joints)?;
    let motions = Motions { title: &program.text, fps: FPS, poses: &poses, labels, initial: Some(&initial) };
    write_exports(folder, motions, Some(checked), report_json, options)
}

/// Motions to write: a title, their frame rate (fps), the poses and a label for each.
#[derive(Debug, Clone)]
pub struct Motions<'a> {
    /// The title of the viewer page and the GIF.
    pub title: &'a str,
    /// Frames per second.
    pub fps: f64,
    /// The motions.
    pub poses: &'a [Vec<Pose>],
    /// One label per motion.
    pub labels: Vec<String>,
    /// Per motion, the unoptimised motion its task's `stay_near_initial` constraints compare
    /// with, when known (the constraints are judged again on a `--rig`).
    pub initial: Option<&'a [Vec<Pose>]>,
}

/// Writes the BVH and GLB of every motion, the viewer page, `export.json` and, when asked,
/// `motion.gif` into `folder` (committed by the caller). `checked`'s scene, position targets
/// and carried objects are drawn, and its constraints judged again on a `--rig`; `report` is
/// shown by the viewer.
pub fn write_exports(
    folder: &OutputFolder,
    Motions { title, fps, poses, labels, initial }: Motions<'_>,
    checked: Option<&CheckedProgram>,
    report: Option<serde_json::Value>,
    options: &ExportOptions,
) -> Result<ExportManifest, PipelineError> {
    let program = checked.map(CheckedProgram::program);
    let input = ExportInput {
        title: title.to_owned(),
        fps,
        samples: labels.into_iter().zip(poses).map(|(label, p)| (label, p.as_slice())).collect(),
        scene: program.map(TaskProgram::scene_primitives).unwrap_or_default(),
        targets: program.map(position_targets).unwrap_or_default(),
        carried: program.map(TaskProgram::carried_objects).unwrap_or_default(),
        report,
        bvh_unit: options.bvh_unit,
        file_fps: options.fps,
        in_place: options.in_place,
        rig: options.rig.as_ref(),
        judge: checked.map(|c| RigJudge { compiled: c.compiled(), device: c.device(), initial }),
    };
    let manifest = write_outputs(folder.path(), &input)?;
    if let Some(rig) = &options.rig {
        // Each sample on our skeleton and, below it, on the rig (its nodes of our joints).
        let rows: Vec<StripRow<'_>> = input
            .samples
            .iter()
            .zip(&manifest.samples)
            .filter_map(|((label, poses), sample)| Some((label, poses, sample.rig.as_ref()?)))
            .flat_map(|(label, poses, on_rig)| {
                [
                    StripRow { label: format!("{label}: ours"), poses },
                    StripRow {
                        label: format!(
                            "{label}: on the rig `{}` (legs {:.2}x ours)",
                            rig.name(),
                            on_rig.report.leg_ratio
                        ),
                        poses: &on_rig.motion_poses,
                    },
                ]
            })
            .collect();
        let path = folder.path().join("rig_strip.png");
        motion_strip(&rows, 8, &input.scene, &input.carried, title, &path)?;
    }
    if options.gif {
        let rows: Vec<StripRow<'_>> =
            input.samples.iter().map(|(label, poses)| StripRow { label: label.clone(), poses }).collect();
        motion_gif(&rows, &input.scene, title, &GifOptions::default(), &folder.path().join("motion.gif"))?;
    }
    Ok(manifest)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Retry k starts from fresh noise (past every restart's seed of the earlier attempts) and,
    /// with RG-DNO, from the retrieved takes after those the earlier attempts started from.
    #[test]
    fn a_retry_starts_from_new_noise_and_the_next_retrieved_takes() {
        let mut config = GenerationConfig::new(Method::RgDno);
        config.seed = 7;
        config.dno.restarts = 3;
        assert_eq!((retry_seed(&config, 1), retry_seed(&config, 2)), (10, 13));
        let rg = RgDnoConfig { retrieved_motions: 2, ..RgDnoConfig::default() };
        assert_eq!((retry_rg_dno(&rg, 1).skip_retrieved, retry_rg_dno(&rg, 2).skip_retrieved), (2, 4));
        let skipping = RgDnoConfig { skip_retrieved: 1, ..RgDnoConfig::default() };
        assert_eq!(retry_rg_dno(&skipping, 1), RgDnoConfig { skip_retrieved: 2, ..RgDnoConfig::default() });
    }
}
