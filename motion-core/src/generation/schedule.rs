//! When an optimisation stage ends: at its step budget (the paper's schedule), or as soon as
//! the work is done (issue 59): every constraint met at its tolerance (the judgement of
//! `report.json`) and the criterion no longer improving.
//!
//! The criterion holds the program's error and the guards (no one-frame jitter, no long flight,
//! free fall in flight, no joint under the floor), so a stage that stops because it has stopped
//! improving has also stopped improving its guards; the stop is only asked after the learning
//! rate's warm-up, and only every [`CHECK_EVERY`] steps, when the judgement's cost (the
//! motion's joints and the program's checks, no denoiser pass) is small beside a step's.

use std::ops::Range;

use candle_core::Tensor;
use serde::{Deserialize, Serialize};

use crate::constraints::CompiledProgram;
use crate::dno::DnoStep;
use crate::numeric::mean;
use crate::prior::Prior;

/// When a stage of DNO ends.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Schedule {
    /// Every stage runs its whole step budget (the papers' fixed schedule; the tables').
    #[default]
    Paper,
    /// A stage ends when every constraint is met at its tolerance and the criterion has
    /// improved by less than [`STALL_FRACTION`] over the last [`CHECK_EVERY`] steps, or at its
    /// budget: DNO's, and RG-DNO's branches (each on its own group) and final round. RG-DNO's
    /// mask search is screened by a cheap sampler first, and its soft blend is skipped when the
    /// chosen binary masks meet the program; its inversion runs its budget.
    UntilMet,
}

impl Schedule {
    /// Whether this is the papers' schedule (written reports leave it out).
    pub fn is_paper(&self) -> bool {
        *self == Schedule::Paper
    }
}

/// Steps between two judgements of the motion.
pub const CHECK_EVERY: usize = 10;
/// The criterion has stopped improving when it fell by less than this fraction over the last
/// [`CHECK_EVERY`] steps.
pub const STALL_FRACTION: f64 = 0.01;

/// When one DNO stage ends under a [`Schedule`]: asked after every step with the step's motion
/// (normalised features `[N, T, 263]`), it answers whether the stage is done (never, under
/// [`Schedule::Paper`]).
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
    /// The mean criterion of the current restart, per step.
    losses: Vec<f64>,
    round: usize,
}

impl<'a> StageEnd<'a> {
    /// The end of a stage that fits `compiled` on every row, whose motions the prior decodes;
    /// no stop within the first `warmup` steps.
    pub fn new(
        schedule: Schedule,
        prior: &'a Prior,
        compiled: &'a CompiledProgram,
        initial: &'a Tensor,
        warmup: usize,
    ) -> Self {
        Self::of_parts(schedule, prior, vec![(compiled, None)], initial, warmup)
    }

    /// The end of a stage that fits each program of `parts` on its own rows.
    pub fn of_parts(
        schedule: Schedule,
        prior: &'a Prior,
        parts: Vec<(&'a CompiledProgram, Option<Range<usize>>)>,
        initial: &'a Tensor,
        warmup: usize,
    ) -> Self {
        StageEnd { schedule, prior, parts, initial, warmup, losses: Vec::new(), round: 0 }
    }

    /// Whether restart `round`'s stage is done after `step` with motion `x`: under
    /// [`Schedule::UntilMet`], every sample meets every constraint and the mean criterion
    /// stalled over the last [`CHECK_EVERY`] steps.
    pub fn done(&mut self, round: usize, step: &DnoStep, x: &Tensor) -> candle_core::Result<bool> {
        if self.schedule == Schedule::Paper {
            return Ok(false);
        }
        if round != self.round {
            self.round = round;
            self.losses.clear();
        }
        self.losses.push(mean(&step.loss));
        let taken = self.losses.len();
        if taken <= self.warmup.max(CHECK_EVERY) || taken % CHECK_EVERY != 0 {
            return Ok(false);
        }
        let (before, now) = (self.losses[taken - 1 - CHECK_EVERY], self.losses[taken - 1]);
        if before - now > STALL_FRACTION * before.abs() {
            return Ok(false);
        }
        let joints = self.prior.to_joints(x)?;
        for (compiled, rows) in &self.parts {
            let part = match rows {
                Some(rows) => joints.narrow(0, rows.start, rows.len())?,
                None => joints.clone(),
            };
            let judged = compiled.satisfaction(&part, Some(self.initial)).map_err(candle_core::Error::wrap)?;
            if !judged.iter().all(|c| c.pass.iter().all(|&p| p)) {
                return Ok(false);
            }
        }
        Ok(true)
    }
}
