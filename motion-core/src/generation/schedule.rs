//! When an optimisation stage ends: at its step budget (the paper's schedule, the default), or
//! as soon as its work is done: the motion meets every constraint at its tolerance (the
//! judgement of `report.json`), the criterion has stopped improving, and the motion the stage
//! would hand on looks no worse than capture or than the prior's own sample.
//!
//! The criterion holds the program's error and the guards (no one-frame jitter, no long flight,
//! free fall in flight, no joint under the floor). Foot skate and peak acceleration are not in
//! it and move as the optimiser keeps going (DNO's raw foot skate on Task 1 rises from 0.02 to
//! 0.41 over its 500 steps, and the cleaned figure moves between 0.11 and 0.20), so a stage
//! whose motion is shown also judges them, on the motion after the foot clean-up: under their
//! bars, or no nearer to them over the last [`LOOK_PATIENCE`] judgements (a crawl's own skate,
//! far above a walk's bar, that more steps do not lower). The stop is only asked after the
//! learning rate's warm-up and every [`crate::generation::stall::CHECK_EVERY`] steps, when the
//! judgement's cost (the motion's joints, the program's checks and the clean-up, no denoiser
//! pass) is small beside a step's.

use std::ops::Range;

use candle_core::Tensor;
use serde::{Deserialize, Serialize};

use crate::cleanup::{foot_lock, FootLockConfig};
use crate::constraints::CompiledProgram;
use crate::dno::DnoStep;
use crate::generation::stall::{RowStall, Stall, StallScale, STALL_FRACTION};
use crate::metrics::{foot_skate_ratio, max_acceleration, CAPTURE_FOOT_SKATE, CAPTURE_MAX_ACCELERATION, LOOK_SLACK};
use crate::motion::tensor_to_poses;
use crate::numeric::mean;
use crate::prior::Prior;

/// When a stage of DNO ends, and the sampler and retries a run gets where it does not set them
/// ([`crate::generation::method::Method::ddim_steps`], [`Schedule::retries_unmet`]). The papers' schedule is the
/// library's default, which its tests and tables reproduce; `mogen`'s command line runs
/// [`Schedule::UntilMet`] unless told `--schedule paper`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Schedule {
    /// Every stage runs its whole step budget (the papers' fixed schedule; the tables').
    #[default]
    Paper,
    /// Every stage ends when its work is done, or at its budget:
    /// - DNO and RG-DNO's final round when every constraint is met, the criterion has stalled
    ///   ([`Stall`]) and the motion looks no worse than its bar ([`LookBar`]) or no longer
    ///   comes nearer to it ([`LookFloor`]);
    /// - RG-DNO's branches when each branch meets its own group or, without counts, no longer
    ///   comes nearer to it (the final round finishes the motion);
    /// - for a program without counts, in every DNO stage, a sample that is done (a shown
    ///   stage's sample that meets the program and looks no worse than its bars, an
    ///   intermediate stage's that no longer comes nearer its program) is held where it is
    ///   while the others go on, and costs no more denoiser passes
    ///   ([`crate::dno::optimize_until`]);
    /// - for a program without counts, RG-DNO's final round hands on per sample the
    ///   best-looking met motion of its judgements, judges its criterion's lowest value for the
    ///   stall, and has its look at the floor after one judgement without gain
    ///   ([`StageEnd::handing_on_best_look`]);
    /// - the inversion's polishes and RG-DNO's soft blend when their objective has stalled;
    ///   the inversion's polishes also once the motion is within [`INVERSION_TOLERANCE_M`] of
    ///   the retrieved one (the joint polish is then skipped);
    /// - RG-DNO's mask search scores its candidates by eq. 13 in the order a cheap sampler
    ///   ranks them, stops sampling a sample whose best has not changed over the last
    ///   [`crate::generation::rgdno::config::RgDnoConfig::mask_patience`] candidates (for a
    ///   counting program: ends once no sample's best has), and ends once every sample's best
    ///   meets the program (then the soft blend is skipped too) or has stopped changing;
    /// - for a program without counts, RG-DNO's stages before its final round sample through
    ///   every other DDIM timestep without guidance
    ///   ([`crate::generation::rgdno::config::RgDnoConfig::early_stride`],
    ///   [`crate::generation::rgdno::config::RgDnoConfig::early_unguided`]), and the final
    ///   round starts on that sampler until the program is met, then finishes on the whole,
    ///   guided one;
    /// - the kinematic refinement is skipped when every sample already meets every geometric
    ///   constraint at its tolerance.
    UntilMet,
}

impl Schedule {
    /// Extra attempts from fresh noise for a sample that misses a constraint or the skill the
    /// prompt asks for, where a run does
    /// not set them ([`crate::pipeline::TaskSettings::retry_unmet`]): none under the papers'
    /// schedule; one under [`Schedule::UntilMet`], which spends part of the time its early ends
    /// save on a second try of what it did not meet.
    pub fn retries_unmet(self) -> usize {
        match self {
            Schedule::Paper => 0,
            Schedule::UntilMet => 1,
        }
    }
}

/// The inversion has reproduced the retrieved motion once its mean joint distance is under
/// this, m: the position tolerance of the constraints ([`crate::constraints`]' 0.05 m).
pub const INVERSION_TOLERANCE_M: f64 = 0.05;

/// Judgements of a met, stalled motion above its look bar, with no sample's look coming nearer
/// its bar by [`STALL_FRACTION`] of the bar, after which the look counts as at its floor.
pub const LOOK_PATIENCE: usize = 3;

/// [`LOOK_PATIENCE`] of a stage that hands on the best-looking met motion its judgements saw
/// ([`StageEnd::handing_on_best_look`]): waiting no longer risks ending on a worse look than one
/// already seen, only missing a better one to come.
pub const BEST_LOOK_PATIENCE: usize = 1;

/// The bars a shown motion's figures must stay under, per sample: the larger of the capture's
/// figure and the same figure of the prior's own unoptimised sample after the clean-up, raised
/// by [`LOOK_SLACK`]. A task that asks for what capture's walks do not do (a crawl skates on
/// hands and knees) starts from a sample that does it, and keeps that sample's bar.
#[derive(Debug, Clone)]
pub struct LookBar {
    foot_skate: Vec<f64>,
    max_acceleration: Vec<f64>,
}

/// The cleaned motion's figures of every sample of joints `[B, T, 22, 3]`: foot skate ratio and
/// peak acceleration (m/frame²), after the clean-up `config` (when it is enabled).
fn looks(joints: &Tensor, config: &FootLockConfig) -> candle_core::Result<Vec<(f64, f64)>> {
    tensor_to_poses(joints)?
        .iter()
        .map(|poses| {
            let figures = |p: &[_]| (foot_skate_ratio(p), max_acceleration(p));
            if !config.enabled {
                return Ok(figures(poses));
            }
            let locked = foot_lock(poses, None, config).map_err(candle_core::Error::wrap)?;
            Ok(figures(&locked.poses))
        })
        .collect()
}

impl LookBar {
    /// The bars of each sample of the unoptimised motion `initial` `[B, T, 22, 3]`, judged after
    /// the clean-up `foot_lock` (the one the generation ends with).
    pub fn of_initial(initial: &Tensor, foot_lock: &FootLockConfig) -> candle_core::Result<Self> {
        let raise = 1.0 + LOOK_SLACK;
        let (foot_skate, max_acceleration) = looks(initial, foot_lock)?
            .into_iter()
            .map(|(skate, acc)| (raise * skate.max(CAPTURE_FOOT_SKATE), raise * acc.max(CAPTURE_MAX_ACCELERATION)))
            .unzip();
        Ok(LookBar { foot_skate, max_acceleration })
    }

    /// How far each sample of `joints` `[B, T, 22, 3]`, after the clean-up `foot_lock`, lies
    /// from its bars: the larger of its foot skate and peak acceleration, each over its bar
    /// (at most 1 under both bars).
    pub fn excess(&self, joints: &Tensor, foot_lock: &FootLockConfig) -> candle_core::Result<Vec<f64>> {
        Ok(looks(joints, foot_lock)?
            .iter()
            .zip(self.foot_skate.iter().zip(&self.max_acceleration))
            .map(|(&(skate, acc), (&skate_bar, &acc_bar))| (skate / skate_bar).max(acc / acc_bar))
            .collect())
    }
}

/// A shown motion's look over the judgements of one restart: done once every sample is under
/// its bars, or when for [`LOOK_PATIENCE`] judgements in a row no sample above its bar came
/// nearer to it than its best by [`STALL_FRACTION`] of the bar.
#[derive(Debug, Clone)]
pub struct LookFloor {
    best: Vec<f64>,
    without_gain: usize,
    /// Judgements without gain that make the floor.
    patience: usize,
}

impl Default for LookFloor {
    fn default() -> Self {
        Self::with_patience(LOOK_PATIENCE)
    }
}

impl LookFloor {
    /// A floor reached after `patience` judgements without gain.
    pub fn with_patience(patience: usize) -> Self {
        LookFloor { best: Vec::new(), without_gain: 0, patience }
    }

    /// Records one judgement's [`LookBar::excess`] per sample; true when the look is done.
    pub fn done_after(&mut self, excess: &[f64]) -> bool {
        if excess.iter().all(|&e| e <= 1.0) {
            return true;
        }
        if self.best.len() != excess.len() {
            self.best = excess.to_vec();
            return false;
        }
        let gained = excess.iter().zip(&self.best).any(|(&now, &best)| now > 1.0 && now < best - STALL_FRACTION);
        for (best, &now) in self.best.iter_mut().zip(excess) {
            *best = best.min(now);
        }
        self.without_gain = if gained { 0 } else { self.without_gain + 1 };
        self.without_gain >= self.patience
    }
}

/// Per row, the lowest [`LookBar::excess`] a judgement saw on a motion that met the program, and
/// that motion `[T, 263]` (none before one met).
type BestLook = Vec<Option<(f64, Tensor)>>;

/// What ends a stage under [`Schedule::UntilMet`].
enum Goal<'a> {
    /// A shown motion: every constraint met, the criterion stalled, and the look under its bars
    /// (made at the first judgement from the unoptimised motion and the generation's clean-up)
    /// or at its floor.
    Shown { foot_lock: &'a FootLockConfig, bar: Option<LookBar>, floor: LookFloor, best_look: Option<BestLook> },
    /// An intermediate one: every row meets the program of its rows or no longer comes nearer
    /// to it ([`RowStall`]).
    Met { stuck: RowStall },
}

/// When one DNO stage ends under a [`Schedule`]: asked after every step with the motion the
/// stage would hand on were it to end there (normalised features `[N, T, 263]`), it answers
/// whether the stage is done (never, under [`Schedule::Paper`]).
pub struct StageEnd<'a> {
    schedule: Schedule,
    prior: &'a Prior,
    /// The programs the stage fits, each with the rows of the motion it judges (all of them
    /// for `None`; RG-DNO's branches fit `C1` on the first `B` rows and `C2` on the next `B`).
    parts: Vec<(&'a CompiledProgram, Option<Range<usize>>)>,
    /// The unoptimised motion `[B, T, 22, 3]` that `stay_near_initial` terms compare with.
    initial: &'a Tensor,
    /// Steps of the learning rate's warm-up: no stop before them.
    warmup: usize,
    goal: Goal<'a>,
    /// Whether a sample may end before the others: for programs without counts. A counting
    /// program's criterion plateaus and then drops as an event forms, and its stages end
    /// together, on every sample's judgement.
    per_sample: bool,
    /// The mean criterion of the current restart.
    stall: Stall,
    round: usize,
}

impl<'a> StageEnd<'a> {
    /// The end of a stage whose motion is shown (DNO's, RG-DNO's final round): it fits
    /// `compiled` on every row from the unoptimised motion `initial`; the generation ends with
    /// the clean-up `foot_lock`; no stop within the first `warmup` steps.
    pub fn shown(
        schedule: Schedule,
        prior: &'a Prior,
        compiled: &'a CompiledProgram,
        initial: &'a Tensor,
        warmup: usize,
        foot_lock: &'a FootLockConfig,
    ) -> Self {
        let goal = Goal::Shown { foot_lock, bar: None, floor: LookFloor::default(), best_look: None };
        Self::with_goal(schedule, prior, vec![(compiled, None)], initial, warmup, goal)
    }

    /// The end of an intermediate stage that fits each program of `parts` on its own rows.
    pub fn intermediate(
        schedule: Schedule,
        prior: &'a Prior,
        parts: Vec<(&'a CompiledProgram, Option<Range<usize>>)>,
        initial: &'a Tensor,
        warmup: usize,
    ) -> Self {
        Self::with_goal(schedule, prior, parts, initial, warmup, Goal::Met { stuck: RowStall::default() })
    }

    /// This shown stage handing on, per sample, the best-looking motion that met the program at
    /// its judgements ([`Self::best_looking`]) where that looks better than the stage's own
    /// result. Its look floor then comes after [`BEST_LOOK_PATIENCE`] judgements without gain,
    /// and its criterion has stalled once its lowest value stops falling ([`Stall::of_best`]):
    /// once met, the last iterate swings around that best at every step, and the motion
    /// handed on is the best-looking of those judged. Only for a program without counts (a
    /// counting program's stage ends as [`Self::shown`]'s); an intermediate stage is left as it
    /// is.
    pub fn handing_on_best_look(mut self) -> Self {
        if !self.per_sample {
            return self;
        }
        if let Goal::Shown { floor, best_look, .. } = &mut self.goal {
            *floor = LookFloor::with_patience(BEST_LOOK_PATIENCE);
            *best_look = Some(Vec::new());
            self.stall = Stall::of_best(StallScale::StageStart);
        }
        self
    }

    /// The motion to hand on from a stage built [`Self::handing_on_best_look`] whose result is
    /// `x` `[B, T, 263]`: each row replaced by the best-looking met motion its judgements saw
    /// where that one lies nearer its look bars (lower [`LookBar::excess`]). `None` where no
    /// row changes (no judgement met the program, or the result looks at least as good).
    pub fn best_looking(&self, x: &Tensor) -> candle_core::Result<Option<Tensor>> {
        let Goal::Shown { foot_lock, bar: Some(bar), best_look: Some(looks), .. } = &self.goal else {
            return Ok(None);
        };
        if looks.iter().all(Option::is_none) {
            return Ok(None);
        }
        let excess = bar.excess(&self.prior.to_joints(x)?, foot_lock)?;
        let mut changed = false;
        let rows = (0..x.dim(0)?)
            .map(|b| match looks.get(b) {
                Some(Some((best, motion))) if *best < excess[b] => {
                    changed = true;
                    Ok(motion.clone())
                }
                _ => x.get(b),
            })
            .collect::<candle_core::Result<Vec<_>>>()?;
        if !changed {
            return Ok(None);
        }
        Tensor::stack(&rows, 0).map(Some)
    }

    fn with_goal(
        schedule: Schedule,
        prior: &'a Prior,
        parts: Vec<(&'a CompiledProgram, Option<Range<usize>>)>,
        initial: &'a Tensor,
        warmup: usize,
        goal: Goal<'a>,
    ) -> Self {
        let per_sample = parts.iter().all(|(compiled, _)| !compiled.has_counts());
        StageEnd {
            schedule,
            prior,
            per_sample,
            parts,
            initial,
            warmup,
            goal,
            stall: Stall::with_scale(StallScale::StageStart),
            round: 0,
        }
    }

    /// Which samples of restart `round`'s stage are done after `step`, handing on motion `x`
    /// (per row, true: done; the run ends when every row is). For a program with counts every
    /// row is done at once, on the rules' "every row" halves alone; otherwise:
    /// - an intermediate stage, at every judgement: every row once each meets its part's
    ///   program or, short of it, has gone [`crate::generation::stall::UNMET_PATIENCE`]
    ///   judgements without a new best; before that, each row short of its program without a
    ///   new best (a met row goes on with the others: the margin it gains survives the stages
    ///   after it);
    /// - a shown stage, at a judgement where the criterion has stalled: every row once every
    ///   row meets the program and the look is under its bars or at its floor; before that,
    ///   each row that meets the program and looks no worse than its bars (it has nothing left
    ///   to gain, and costs no more passes while the others go on).
    pub fn done(&mut self, round: usize, step: &DnoStep, x: &Tensor) -> candle_core::Result<Vec<bool>> {
        let going = vec![false; step.loss.len()];
        if self.schedule == Schedule::Paper {
            return Ok(going);
        }
        if round != self.round {
            self.round = round;
            self.stall.clear();
            match &mut self.goal {
                Goal::Shown { floor, best_look, .. } => {
                    *floor = LookFloor::with_patience(floor.patience);
                    if let Some(looks) = best_look {
                        looks.clear();
                    }
                }
                Goal::Met { stuck } => *stuck = RowStall::default(),
            }
        }
        let stalled = self.stall.stalled_after(mean(&step.loss), self.warmup);
        let judged = match self.goal {
            Goal::Shown { .. } => stalled,
            Goal::Met { .. } => self.stall.at_check(self.warmup),
        };
        if !judged {
            return Ok(going);
        }
        let joints = self.prior.to_joints(x)?;
        let met = self.met_rows(&joints)?;
        match &mut self.goal {
            Goal::Shown { foot_lock, bar, floor, best_look } => {
                let all_met = met.iter().all(|&m| m);
                if !met.iter().any(|&m| m) || !(all_met || self.per_sample) {
                    return Ok(going);
                }
                let bar = match bar {
                    Some(bar) => bar,
                    None => bar.insert(LookBar::of_initial(self.initial, foot_lock)?),
                };
                let excess = bar.excess(&joints, foot_lock)?;
                if let Some(looks) = best_look {
                    looks.resize(met.len(), None);
                    for (b, (look, (&met, &excess))) in looks.iter_mut().zip(met.iter().zip(&excess)).enumerate() {
                        if met && look.as_ref().is_none_or(|(best, _)| excess < *best) {
                            *look = Some((excess, x.get(b)?));
                        }
                    }
                }
                if all_met && floor.done_after(&excess) {
                    return Ok(vec![true; met.len()]);
                }
                if !self.per_sample {
                    return Ok(going);
                }
                Ok(met.iter().zip(&excess).map(|(&m, &e)| m && e <= 1.0).collect())
            }
            Goal::Met { .. } if !self.per_sample => Ok(vec![met.iter().all(|&m| m); met.len()]),
            Goal::Met { stuck } => {
                // Only a row short of its program is held for want of progress.
                let stuck: Vec<bool> =
                    stuck.stuck_after(&step.loss).into_iter().zip(&met).map(|(stuck, &met)| stuck && !met).collect();
                if met.iter().zip(&stuck).all(|(&met, &stuck)| met || stuck) {
                    return Ok(vec![true; met.len()]);
                }
                Ok(stuck)
            }
        }
    }

    /// Whether each row of `joints` meets every constraint of the part that judges it (a row
    /// no part judges is met).
    fn met_rows(&self, joints: &Tensor) -> candle_core::Result<Vec<bool>> {
        let mut met = vec![true; joints.dim(0)?];
        for (compiled, rows) in &self.parts {
            let rows = rows.clone().unwrap_or(0..met.len());
            let part = joints.narrow(0, rows.start, rows.len())?;
            let judged = compiled.met_per_sample(&part, Some(self.initial)).map_err(candle_core::Error::wrap)?;
            for (m, part_met) in met[rows].iter_mut().zip(judged) {
                *m &= part_met;
            }
        }
        Ok(met)
    }
}

#[cfg(test)]
mod tests {
    use candle_core::{DType, Device};
    use glam::DVec3;

    use super::*;
    use crate::motion::poses_to_tensor;
    use crate::skeleton::{rest_pose, Pose};

    /// 40 frames standing still, or with both feet on the floor sliding sideways at `speed`
    /// m/s.
    fn standing(speed: f64) -> Tensor {
        let poses: Vec<Pose> = (0..40)
            .map(|t| {
                let mut pose = rest_pose();
                let lowest = pose.iter().map(|j| j.y).fold(f64::INFINITY, f64::min);
                for j in pose.iter_mut() {
                    *j -= DVec3::new(0.0, lowest, 0.0);
                }
                for foot in [crate::skeleton::Joint::LeftFoot, crate::skeleton::Joint::RightFoot] {
                    pose[foot.index()].x += speed * t as f64 / crate::skeleton::FPS;
                }
                pose
            })
            .collect();
        poses_to_tensor(&[poses], DType::F32, &Device::Cpu).unwrap()
    }

    #[test]
    fn the_look_bar_lets_a_still_motion_pass_and_holds_back_a_skating_one() {
        let still = standing(0.0);
        let off = FootLockConfig { enabled: false, ..FootLockConfig::default() };
        let bar = LookBar::of_initial(&still, &off).unwrap();
        assert!(bar.excess(&still, &off).unwrap()[0] <= 1.0);
        assert!(bar.excess(&standing(1.5), &off).unwrap()[0] > 1.0, "feet sliding at 1.5 m/s on every frame");
    }

    #[test]
    fn a_look_above_its_bar_is_at_its_floor_after_three_judgements_without_gain() {
        let judged = |excesses: &[[f64; 2]]| {
            let mut floor = LookFloor::default();
            excesses.iter().position(|e| floor.done_after(e)).map(|at| at + 1)
        };
        assert_eq!(judged(&[[0.9, 1.0]]), Some(1), "under both bars at once");
        assert_eq!(judged(&[[2.7, 1.2], [2.8, 1.2], [2.9, 1.2], [2.9, 1.21]]), Some(4), "no sample nearer");
        assert_eq!(judged(&[[2.7, 1.2], [2.8, 1.2], [2.8, 1.1], [2.9, 1.2], [2.9, 1.2]]), None, "one gained");
        assert_eq!(judged(&[[2.7, 1.2], [2.695, 1.2], [2.69, 1.2], [2.685, 1.2]]), Some(4), "gains under 1 %");
        // A sample's gain under its bar does not hold the other's floor back.
        assert_eq!(judged(&[[2.0, 1.0], [2.0, 0.5], [2.0, 0.2], [2.0, 0.1]]), Some(4));
        let steady = [[3.0, 1.0], [2.5, 1.0], [2.0, 1.0], [1.5, 1.0], [1.2, 1.0], [1.0, 1.0]];
        assert_eq!(judged(&steady), Some(6), "coming down to its bar");
    }

    /// Three motions of the prior, `[1, 40, 263]` each, and the prior.
    fn prior_motions() -> (Prior, Vec<Tensor>) {
        let device = Device::Cpu;
        let prior = crate::generation::shipped_prior(&device);
        let text = prior.encode_text(&["a person walks forward"], &device).unwrap();
        let guidance = crate::diffusion::Guidance::default().for_text(&text).unwrap();
        let solver = crate::dno::UnrolledDdim::new(&prior.mdm, text, guidance, 10).unwrap();
        let motions = (1..=3)
            .map(|seed| {
                let z = crate::diffusion::noise::gaussian((1, 40, crate::representation::FEATURE_DIM), seed, &device);
                solver.sampler.sample(solver.denoiser, &z.unwrap(), &solver.text, solver.guidance).unwrap()
            })
            .collect();
        (prior, motions)
    }

    fn compiled(min_pelvis_height_m: f64) -> CompiledProgram {
        let program = crate::program::TaskProgram::from_json_validated(&format!(
            r#"{{"text": "a person walks forward", "frames": 40, "constraints": [{{"id": "c1", "expr":
            {{"op": "greater_than", "quantity": {{"kind": "position", "of": {{"joint": "pelvis"}}, "axes": "y"}},
            "min": {min_pelvis_height_m}, "frames": {{"keyframes": ["first"]}}}}}}]}}"#
        ))
        .unwrap();
        CompiledProgram::compile(&program, &Device::Cpu).unwrap()
    }

    /// Judges motions 1 and 2 of `motions` at the first two checks of a shown stage built
    /// handing on its best look, on a flat criterion, and asks what it hands on for motion 0.
    fn hand_on(
        prior: &Prior,
        motions: &[Tensor],
        compiled: &CompiledProgram,
        schedule: Schedule,
        lock: &FootLockConfig,
    ) -> Option<Tensor> {
        let initial = prior.to_joints(&motions[0]).unwrap();
        let mut end = StageEnd::shown(schedule, prior, compiled, &initial, 0, lock).handing_on_best_look();
        for step in 0..30 {
            let figures = DnoStep {
                step,
                steps: 100,
                lr: 0.0,
                loss: vec![1.0],
                decorrelation: vec![0.0],
                diff_norm: vec![0.0],
                grad_norm: vec![0.0],
            };
            end.done(0, &figures, &motions[1 + step / 20]).unwrap();
        }
        end.best_looking(&motions[0]).unwrap()
    }

    #[test]
    fn a_stage_handing_on_its_best_look_hands_on_the_best_looking_met_motion_it_judged() {
        let (prior, motions) = prior_motions();
        let lock = FootLockConfig::default();
        let bar = LookBar::of_initial(&prior.to_joints(&motions[0]).unwrap(), &lock).unwrap();
        let excess: Vec<f64> =
            motions.iter().map(|x| bar.excess(&prior.to_joints(x).unwrap(), &lock).unwrap()[0]).collect();
        let handed = hand_on(&prior, &motions, &compiled(0.1), Schedule::UntilMet, &lock);
        // Judged at steps 20 (motion 1) and 30 (motion 2); the stage's own result is motion 0.
        let judged = if excess[2] < excess[1] { 2 } else { 1 };
        match handed {
            Some(x) => {
                assert!(excess[judged] < excess[0], "{excess:?}");
                assert_eq!(
                    x.flatten_all().unwrap().to_vec1::<f32>().unwrap(),
                    motions[judged].flatten_all().unwrap().to_vec1::<f32>().unwrap()
                );
            }
            None => assert!(excess[0] <= excess[judged], "{excess:?}"),
        }
        // Motion 0 handed on from what it judged, on the motion that looks worst: always a change.
        let worst = (0..3).max_by(|&a, &b| excess[a].total_cmp(&excess[b])).unwrap();
        let reordered: Vec<Tensor> =
            [worst].into_iter().chain((0..3).filter(|&k| k != worst)).map(|k| motions[k].clone()).collect();
        assert!(
            hand_on(&prior, &reordered, &compiled(0.1), Schedule::UntilMet, &lock).is_some()
                || excess.iter().all(|&e| e == excess[worst])
        );
        // Nothing met (the pelvis 5 m up), or the papers' schedule: the result is handed on as it is.
        assert!(hand_on(&prior, &reordered, &compiled(5.0), Schedule::UntilMet, &lock).is_none());
        assert!(hand_on(&prior, &reordered, &compiled(0.1), Schedule::Paper, &lock).is_none());
    }
}
