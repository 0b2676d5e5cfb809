//! The generation options every command that makes motions shares, and the method on the
//! command line.

use std::path::{Path, PathBuf};

use clap::{Args, ValueEnum};
use motion_core::generation::method::{GenerationConfig, Method};
use motion_core::generation::objective::Guards;
use motion_core::generation::rgdno::candidates::RetrievalSource;
use motion_core::generation::rgdno::config::RgDnoConfig;
use motion_core::generation::schedule::Schedule;
use motion_core::pipeline::TaskSettings;

use super::export_formats::ExportFormats;
use super::flags;
use agent::paths;

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

/// When DNO's stages end, on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ScheduleArg {
    /// Every stage runs its whole step budget (the papers' schedule: reproduces their tables).
    Paper,
    /// Each stage ends once its work is done, or at its budget (checked every 10 steps after
    /// the warm-up): DNO and the final round once every constraint is met, the loss has
    /// stopped improving (it fell by under 1 % of the stage's first loss over 10 steps) and the
    /// cleaned motion's foot skate and peak acceleration are within 10 % of capture's walks or
    /// of the prior's own sample (or have come no nearer to that over three checks: a crawl's
    /// own skate); RG-DNO's branches once each meets its group or has stopped coming nearer
    /// to it; without counts, a sample done before the others is held and costs no more
    /// passes; the inversion
    /// once its loss stalls or, for a program without counts, its motion is within 0.05 m of
    /// the retrieved one; the soft blend once its loss stalls. RG-DNO's mask candidates
    /// are scored in the order a cheap sampler ranks them until every sample's mask meets the
    /// program (the soft blend is then skipped) or has not changed over 64 candidates, and
    /// the refinement is skipped when nothing is left to close. Unless set, DNO samples with 5
    /// DDIM steps (RG-DNO with 10) and a sample that misses a constraint or the skill the
    /// prompt asks for is tried once more.
    /// The default.
    UntilMet,
}

impl From<ScheduleArg> for Schedule {
    fn from(s: ScheduleArg) -> Schedule {
        match s {
            ScheduleArg::Paper => Schedule::Paper,
            ScheduleArg::UntilMet => Schedule::UntilMet,
        }
    }
}

/// Options shared by every command that generates motions.
#[derive(Debug, Clone, Args)]
pub struct GenerationArgs {
    /// Motions generated together (under `--schedule until-met`, RG-DNO runs those of a program
    /// without counts side by side, one per core).
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
    /// When each optimisation stage ends: `until-met` (the default) ends each stage once its work
    /// is done and the motion looks no worse than capture or the prior's own sample, samples
    /// DNO with 5 DDIM steps (RG-DNO keeps 10, its stages before the final round on every other
    /// one and unguided for a program without counts) and tries a sample that missed a
    /// constraint or the skill the prompt asks for once more;
    /// `paper` runs every step of the papers' budgets with 10 DDIM steps and no retry (their
    /// tables' schedule; fixtures/results/issue59-early-stride/).
    #[arg(long, value_enum, default_value_t = ScheduleArg::UntilMet)]
    pub schedule: ScheduleArg,
    /// Extra attempts for each sample that misses a constraint at its tolerance, or that does
    /// not do the skill the prompt asks for beyond walking (a crawl, a hop, a carry, ...: its
    /// detector, report.json's `skill`): it is generated again from fresh noise (attempt k + 1
    /// from seed + k·restarts; with RG-DNO, from the next retrieved takes) and keeps its best
    /// attempt (most constraints met, then the skill done, then the lowest error);
    /// report.json's `attempt` says which. 0: off (default: 1, or 0 with `--schedule paper`).
    #[arg(long)]
    pub retry_unmet: Option<usize>,
    /// DNO's peak Adam learning rate on the start noise (default 0.05, DNO's).
    #[arg(long, value_parser = flags::learning_rate)]
    pub lr: Option<f64>,
    /// DDIM steps of the sampler that DNO differentiates through (default: 10, or 5 for DNO
    /// and the baselines under `--schedule until-met`, the default).
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
    /// shipped corpus (7.9 h of CMU, HDM05 and ACCAD capture, 6.2 h of it in the train split;
    /// its validation and test splits are never retrieved).
    #[arg(long, value_name = "FILE")]
    pub database: Option<PathBuf>,
    /// RG-DNO settings as JSON (fields of `RgDnoConfig`: retrieval, inversion, first_steps,
    /// first_lr, segments, mask_kinds, mask_batch, mask_patience, early_stride, early_unguided,
    /// reward, final_steps, final_lr, ablation, retrieved_motions, skip_retrieved; missing fields
    /// keep the paper's defaults), e.g.
    /// '{"retrieval": {"related_weight": 0.01}}', '{"retrieved_motions": 2}' (start from the best
    /// crops of two takes in turn, each sample keeping its better attempt),
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
    /// `--steps` when given), its database and the export choices (a `--rig` that cannot be
    /// used fails here, before any work).
    pub fn settings(&self, method: Method) -> anyhow::Result<TaskSettings> {
        let rg_dno = match self.steps {
            Some(steps) => self.rg_dno.scaled_to(steps),
            None => (*self.rg_dno).clone(),
        };
        Ok(TaskSettings {
            generation: self.config(method),
            rg_dno,
            database: retrieval_source(self.database.as_deref()),
            retry_unmet: self.retry_unmet.unwrap_or(Schedule::from(self.schedule).retries_unmet()),
            exports: self.formats.options()?,
        })
    }

    /// The generation settings for `method`.
    pub fn config(&self, method: Method) -> GenerationConfig {
        let mut config = GenerationConfig::new(method);
        config.samples = self.samples;
        config.seed = self.seed;
        config.guidance = self.guidance;
        config.schedule = self.schedule.into();
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
        config.dno.ddim_steps = self.ddim_steps.unwrap_or(method.ddim_steps(config.schedule));
        if let Some(steps) = self.steps {
            config.dno.steps = steps;
            config.direct.steps = steps;
        }
        config
    }
}
