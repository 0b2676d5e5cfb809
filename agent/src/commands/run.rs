//! `mogen run`: generate motions for a constraint program file with one method.

use std::path::{Path, PathBuf};

use clap::{Args, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use motion_core::evaluation::TaskReport;
use motion_core::export::OutputFolder;
use motion_core::generation::{Event, GenerationConfig, Guards, Method};
use motion_core::pipeline::{run_task, write_task, TaskSettings};
use motion_core::prior::Prior;
use motion_core::program::TaskProgram;
use motion_core::rgdno::candidates::RetrievalSource;
use motion_core::rgdno::RgDnoConfig;

use super::export::{print_exports, ExportFormats};
use super::flags;
use super::load::{load_prior, load_program};
use crate::paths;

/// A generation method on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum MethodArg {
    /// The prior's sample for the prompt, constraints ignored.
    Unconstrained,
    /// Optimise the motion directly (ProgMoGen's IK baseline: Adam lr 1e-2, 100 steps).
    Ik,
    /// IK plus a frame-to-frame smoothness term.
    IkReg,
    /// Optimise the diffusion start noise (ProgMoGen + DNO: 500 Adam steps, lr 0.05).
    Dno,
    /// Retrieval-guided DNO: retrieve a database motion for the hardest constraints, invert it,
    /// blend its noise with random noise through the best mask, then a last DNO round (needs the
    /// program's relational parse; falls back to DNO, saying why, without one).
    RgDno,
}

impl From<MethodArg> for Method {
    fn from(m: MethodArg) -> Method {
        match m {
            MethodArg::Unconstrained => Method::Unconstrained,
            MethodArg::Ik => Method::Ik,
            MethodArg::IkReg => Method::IkReg,
            MethodArg::Dno => Method::Dno,
            MethodArg::RgDno => Method::RgDno,
        }
    }
}

/// Options shared by every command that generates motions.
#[derive(Debug, Clone, Args)]
pub struct GenerationArgs {
    /// Motions generated together.
    #[arg(long, short = 'n', default_value_t = 1, value_parser = flags::samples)]
    pub samples: usize,
    /// Seed of the start noise (same seed, same machine: same motion).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Optimisation steps (DNO default 500; IK default 100; RG-DNO: every stage scaled by
    /// steps/500 from 50 + 50 inversion polish, 100 for the branches and the blend, 400 final).
    #[arg(long, value_parser = flags::steps)]
    pub steps: Option<usize>,
    /// Random restarts N_S of DNO and RG-DNO; the best per sample is kept.
    #[arg(long, default_value_t = 1, value_parser = flags::steps)]
    pub restarts: usize,
    /// Extra attempts for each sample that misses a constraint at its tolerance: it is generated
    /// again from fresh noise (attempt k + 1 from seed + k·restarts) and keeps its best attempt
    /// (most constraints met, then the lowest error); report.json's `attempt` says which. 0: off
    #[arg(long, default_value_t = 0)]
    pub retry_unmet: usize,
    /// DNO's peak Adam learning rate on the start noise (default 0.05, DNO's).
    #[arg(long, value_parser = flags::learning_rate)]
    pub lr: Option<f64>,
    /// DDIM steps of the sampler that DNO differentiates through (default 10).
    #[arg(long, value_parser = flags::ddim_steps)]
    pub ddim_steps: Option<usize>,
    /// Late start of DNO: optimise the noise of the unconstrained motion noised to this
    /// timestep (0–999) and denoise from there, instead of the start latent at 900.
    #[arg(long, value_parser = flags::timestep)]
    pub start_timestep: Option<usize>,
    /// Weight of DNO's noise decorrelation regulariser (default 1000, DNO's; 0: off).
    #[arg(long, value_parser = flags::weight)]
    pub decorrelate_scale: Option<f64>,
    /// Classifier-free guidance scale of the prior (1 = conditional only).
    #[arg(long, default_value_t = motion_core::diffusion::Guidance::MDM_SCALE, value_parser = flags::guidance)]
    pub guidance: f64,
    /// Weight of DNO's jitter guard on joint accelerations above 0.15 m/frame² (0: off).
    #[arg(long, default_value_t = Guards::DEFAULT.jitter, value_parser = flags::weight)]
    pub jitter_weight: f64,
    /// Weight of DNO's flight guard: in every 0.75 s some joint comes within 0.10 m of the floor,
    /// so no leap hangs in the air longer than an athlete's jump (0.7 s) (0: off).
    #[arg(long, default_value_t = Guards::DEFAULT.flight, value_parser = flags::weight)]
    pub flight_weight: f64,
    /// Weight of DNO's ballistic guard: in flight the centre of mass falls at g, so a leap's
    /// height fits its time in the air (0: off).
    #[arg(long, default_value_t = Guards::DEFAULT.ballistic, value_parser = flags::weight)]
    pub ballistic_weight: f64,
    /// Weight of DNO's floor guard: no joint under the floor (the summed depth, m), so a
    /// constraint such as "feet on the ground" is not met by a foot sunk into it (0: off).
    #[arg(long, default_value_t = Guards::DEFAULT.floor, value_parser = flags::weight)]
    pub floor_weight: f64,
    /// Switch off the contact-aware clean-up (foot locking with leg IK) of the output; the report
    /// gives every figure before and after it when it runs.
    #[arg(long)]
    pub no_foot_lock: bool,
    /// Switch off the kinematic refinement: the bounded, smooth joint-space layer (rigid bones,
    /// joints moved at most 0.25 m) that closes the last centimetres of the program's geometric
    /// constraints before the foot clean-up, e.g. arms drawn in to pass a narrow gap.
    #[arg(long)]
    pub no_refine: bool,
    /// Trained prior file.
    #[arg(long, default_value_os_t = paths::default_prior())]
    pub prior: PathBuf,
    #[command(flatten)]
    pub formats: ExportFormats,
    /// What RG-DNO retrieves from: a motion corpus (`.safetensors.gz`: its train split, with
    /// mirrored copies), a database file of `mogen data build` (`.safetensors`) or a catalog of
    /// clips (`.json`, built in memory with every augmentation); default: the train split of the
    /// shipped corpus (7.5 h of CMU and HDM05 capture; its validation and test splits are never
    /// retrieved).
    #[arg(long, value_name = "FILE")]
    pub database: Option<PathBuf>,
    /// RG-DNO settings as JSON (fields of `RgDnoConfig`: retrieval, inversion, first_steps,
    /// first_lr, segments, mask_kinds, mask_batch, reward, final_steps, final_lr, ablation;
    /// missing fields keep the paper's defaults), e.g. '{"retrieval": {"related_weight": 0.01}}',
    /// the supplementary's reward for a task '{"reward": "steps_raising_hands"}' (also
    /// narrow_gap, low_barrier; or the weights '{"reward": {"semantic": 0.5}}') or Table 4's
    /// '{"ablation": "random_only"}' (also retrieved_only, no_parsing, half_mask, no_reward,
    /// same_sets).
    #[arg(long, value_parser = parse_rg_dno_config, default_value = "{}")]
    pub rg_dno: Box<RgDnoConfig>,
}

/// What `--database` names ([`RetrievalSource::from_path`]), else the shipped corpus's train
/// split.
pub fn retrieval_source(file: Option<&Path>) -> RetrievalSource {
    RetrievalSource::from_path(file.map_or_else(paths::default_corpus, Path::to_path_buf))
}

fn parse_rg_dno_config(text: &str) -> Result<Box<RgDnoConfig>, String> {
    serde_json::from_str(text).map_err(|e| format!("not an RG-DNO config: {e}"))
}

impl GenerationArgs {
    /// Everything a run of `method` needs: the generation settings, RG-DNO's stages (scaled to
    /// `--steps` when given) and its database.
    pub fn settings(&self, method: Method) -> TaskSettings {
        let rg_dno = match self.steps {
            Some(steps) => self.rg_dno.scaled_to(steps),
            None => (*self.rg_dno).clone(),
        };
        TaskSettings {
            generation: self.config(method),
            rg_dno,
            database: retrieval_source(self.database.as_deref()),
            retry_unmet: self.retry_unmet,
        }
    }

    /// The generation settings for `method`.
    pub fn config(&self, method: Method) -> GenerationConfig {
        let mut config = GenerationConfig::new(method);
        config.samples = self.samples;
        config.seed = self.seed;
        config.guidance = self.guidance;
        config.dno.restarts = self.restarts;
        config.guards = Guards {
            jitter: self.jitter_weight,
            flight: self.flight_weight,
            ballistic: self.ballistic_weight,
            floor: self.floor_weight,
        };
        config.foot_lock.enabled = !self.no_foot_lock;
        config.refine.enabled = !self.no_refine;
        if let Some(lr) = self.lr {
            config.dno.lr = lr;
        }
        config.dno.start_timestep = self.start_timestep;
        if let Some(scale) = self.decorrelate_scale {
            config.dno.decorrelate_scale = scale;
        }
        if let Some(ddim_steps) = self.ddim_steps {
            config.dno.ddim_steps = ddim_steps;
        }
        if let Some(steps) = self.steps {
            config.dno.steps = steps;
            config.direct.steps = steps;
        }
        config
    }
}

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
    /// (world coordinates, the scene drawn), program.json, sample_<i>/motion.bvh and
    /// sample_<i>/motion.glb (rotations on a rigid skeleton; the GLB has a skinned figure and the
    /// scene), viewer.html (3-D, offline) and export.json (the files and the rotation fit).
    #[arg(long, short, default_value = "out/run")]
    out: PathBuf,
}

pub fn run(args: RunArgs) -> anyhow::Result<()> {
    let program = load_program(&args.program)?;
    let folder = OutputFolder::create(&args.out)?;
    let device = candle_core::Device::Cpu;
    let prior = load_prior(&args.generation.prior, &device)?;
    let settings = args.generation.settings(args.method.into());
    let report = run_program(&prior, &program, &settings, folder, args.generation.formats)?;
    print_summary(&report);
    Ok(())
}

/// Runs `program` with `settings` ([`motion_core::pipeline`]) and writes every output into
/// `folder`, all at once when everything is made (a failure leaves the folder as it was), with
/// progress on stderr: a bar on a terminal, plain lines otherwise.
pub fn run_program(
    prior: &Prior,
    program: &TaskProgram,
    settings: &TaskSettings,
    folder: OutputFolder,
    formats: ExportFormats,
) -> anyhow::Result<TaskReport> {
    let bar = ProgressBar::new(0);
    bar.set_style(
        ProgressStyle::with_template("{prefix} [{bar:30}] {pos}/{len} loss {msg} ({elapsed}, eta {eta})")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let start = std::time::Instant::now();
    // Not a terminal (a log, CI): instead of the bar, a plain line on the first and last step
    // of a stage and at least every PLAIN_PROGRESS_EVERY between.
    let mut last_line: Option<std::time::Instant> = None;
    let show = |event: Event<'_>| match event {
        Event::Step { stage, round, step, steps, loss } => {
            bar.set_prefix(stage.to_owned());
            bar.set_length(steps as u64);
            bar.set_position(step as u64);
            bar.set_message(format!("{loss:.5} (round {round})"));
            let due = last_line.is_none_or(|t| t.elapsed() >= PLAIN_PROGRESS_EVERY);
            if bar.is_hidden() && (due || step <= 1 || step == steps) {
                last_line = Some(std::time::Instant::now());
                eprintln!(
                    "{stage} round {round}: step {step}/{steps} loss {loss:.5} ({:.0} s)",
                    start.elapsed().as_secs_f64()
                );
            }
        }
        Event::Note(note) => bar.suspend(|| eprintln!("{note}")),
    };
    let device = candle_core::Device::Cpu;
    let run = run_task(prior, program, settings, &device, show)?;
    bar.finish_and_clear();
    let manifest = write_task(&folder, prior, program, &run, formats.options())?;
    print_exports(&folder, &manifest, formats);
    let out = folder.commit()?;
    eprintln!("wrote {}/{{program.json,features.npy,joints.npy,report.json,strip.png}}", out.display());
    Ok(run.report)
}

/// Longest silence on a non-terminal stderr during generation.
const PLAIN_PROGRESS_EVERY: std::time::Duration = std::time::Duration::from_secs(5);

/// Prints the headline figures of a run.
pub fn print_summary(report: &TaskReport) {
    println!(
        "{}: constraint error {:.6} (per sample {:?}) in {:.1} s",
        report.config.method,
        report.constraint_error,
        report.constraint_error_per_sample.iter().map(|e| format!("{e:.5}")).collect::<Vec<_>>(),
        report.seconds
    );
    for c in &report.constraints {
        let mean = c.error.iter().sum::<f64>() / c.error.len().max(1) as f64;
        let passed = c.pass.iter().filter(|p| **p).count();
        println!(
            "  {} (weight {}): loss {:.6}, met by {passed}/{} samples  {}",
            c.id,
            c.weight,
            mean,
            c.pass.len(),
            c.description.as_deref().unwrap_or("")
        );
        for check in &c.checks {
            let worst = check.value.iter().copied().fold(0.0, f64::max);
            println!(
                "      {}: worst {worst:.3} {} (tolerance {}; per sample {:?})",
                check.what,
                check.unit,
                check.tolerance,
                check.value.iter().map(|v| format!("{v:.3}")).collect::<Vec<_>>()
            );
        }
    }
    println!("  all constraints met by {:.0}% of the samples", 100.0 * report.success_rate);
    if let Some(why) = &report.fallback {
        println!("  RG-DNO fell back to DNO: {why}");
    }
    if let Some(attempt) = report.attempt.as_ref().filter(|a| a.iter().any(|&k| k > 0)) {
        let kept: Vec<String> = attempt.iter().map(|k| (k + 1).to_string()).collect();
        println!("  attempt kept per sample (1 = the first): {}", kept.join(", "));
    }
    if let Some(rg) = &report.rg_dno {
        if let Some(r) = rg.retrieved.first() {
            println!(
                "  retrieved {} resized to {} frames, C_R score {:.4}, best of {} candidates ({} after the semantic \
                 check) in {:.1} s; inversion error {:.3} m",
                r.source,
                report.frames,
                r.score,
                rg.candidates,
                rg.consistent_candidates,
                rg.seconds.retrieval,
                rg.inversion_error_m
            );
        }
        for (i, m) in rg.masks.iter().enumerate() {
            println!(
                "  sample {i}: {:?} mask {:0w$b}, F_C {:.4}, reward {:.4}{}",
                m.candidate.kind,
                m.candidate.bits,
                m.constraint_error,
                m.reward,
                rg.restart
                    .get(i)
                    .filter(|_| report.config.dno.restarts > 1)
                    .map_or(String::new(), |r| format!(" (restart {r} of {})", report.config.dno.restarts)),
                w = m.candidate.segments
            );
        }
        let s = &rg.seconds;
        println!(
            "  RG-DNO seconds: retrieval {:.1}, inversion {:.1}, branches {:.1}, masks {:.1}, soft blend {:.1}, final \
             round {:.1}",
            s.retrieval, s.inversion, s.branches, s.masks, s.soft_blend, s.final_round
        );
    }
    let penetration = report.max_scene_penetration_m.map_or("n/a".to_owned(), |p| format!("{p:.4} m"));
    println!(
        "  foot skate {:.3}, max acceleration {:.4} m/frame², max scene penetration {penetration}, head-neck incorrect {:.2}",
        report.motion.foot_skate_ratio, report.motion.max_acceleration, report.motion.head_neck_incorrect_ratio
    );
    if let Some(steps) = &report.steps {
        println!(
            "  steps (leg alternations) {} (target {}), success {:.2}",
            steps.counts_text(),
            steps.target,
            steps.success_rate
        );
    }
    let cleanup = &report.cleanup;
    if cleanup.refine_enabled {
        let kept = cleanup.refine.iter().filter(|r| r.applied).count();
        let moved = cleanup.refine.iter().filter(|r| r.applied).map(|r| r.max_offset_m).fold(0.0, f64::max);
        let errors: Vec<String> =
            cleanup.refine.iter().map(|r| format!("{:.4} → {:.4}", r.error_before, r.error_after)).collect();
        println!(
            "  refinement: kept for {kept}/{} samples, joints moved up to {moved:.3} m, constraint error {}",
            cleanup.refine.len(),
            errors.join(", ")
        );
    } else {
        println!("  refinement: off");
    }
    if cleanup.enabled {
        let before = &cleanup.before;
        let locked: usize = cleanup.samples.iter().flat_map(|s| s.contacts.iter()).map(|c| c.locked_frames).sum();
        let moved = cleanup.samples.iter().map(|s| s.max_displacement_m).fold(0.0, f64::max);
        let shortened: usize = cleanup.samples.iter().map(|s| s.shortened).sum();
        let raised = cleanup.samples.iter().map(|s| s.raised_m).fold(0.0, f64::max);
        let held: usize = cleanup.samples.iter().map(|s| s.held_above_floor).sum();
        let penetration = before.max_scene_penetration_m.map_or("n/a".to_owned(), |p| format!("{p:.4} m"));
        println!(
            "  foot clean-up: {locked} joint-frames locked ({shortened} sliding contacts cut to their steadiest \
             stretch), sinking frames raised up to {raised:.3} m, {held} leg-frames held above the floor, joints \
             moved up to {moved:.3} m; the network's motion before the refinement and the clean-up: foot skate {:.3}, \
             all constraints met by {:.0}%, max scene penetration {penetration}{}",
            before.motion.foot_skate_ratio,
            100.0 * before.success_rate,
            before.steps.as_ref().map_or(String::new(), |s| format!(", steps {s:?}"))
        );
    } else {
        println!("  foot clean-up: off");
    }
}
