//! Whether an optimisation stage's criterion has stopped improving: judged every
//! [`CHECK_EVERY`] steps on the whole stage ([`Stall`]) or per row of an intermediate stage
//! ([`RowStall`]). A stage's end ([`crate::generation::schedule`]) asks it beside whether the
//! program is met.

/// Steps between two judgements of the motion.
pub const CHECK_EVERY: usize = 10;
/// The criterion has stopped improving when it fell by less than this fraction of its
/// [`StallScale`] over the last [`CHECK_EVERY`] steps.
pub const STALL_FRACTION: f64 = 0.01;

/// Judgements in a row without a new best after which a row of an intermediate stage that has
/// not met its program is done: more steps do not bring it nearer, and the final round fits
/// the whole program from wherever the row got to.
pub const UNMET_PATIENCE: usize = 2;

/// What a fall of the criterion is measured against when asking whether it has stalled.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum StallScale {
    /// Its value [`CHECK_EVERY`] steps before: for a stage whose stall is its only end (the
    /// inversion's polishes short of their tolerance, the soft blend), which goes on while it
    /// still gains a part of what is left.
    #[default]
    Recent,
    /// The larger of that and its value at the stage's first step: for a stage that also
    /// needs its program met ([`crate::generation::schedule::StageEnd`]). Once met, the criterion's residue is far below
    /// where the stage started, and its step-to-step noise would pass for progress against a
    /// fraction of itself.
    StageStart,
}

/// A criterion's record over one stage, asked whether it has stopped improving.
#[derive(Debug, Clone, Default)]
pub struct Stall {
    losses: Vec<f64>,
    scale: StallScale,
    /// Whether the fall is that of the lowest criterion so far (a stage that hands on its best
    /// iterate) rather than of the last one.
    of_best: bool,
}

impl Stall {
    /// A record judged against `scale`.
    pub fn with_scale(scale: StallScale) -> Self {
        Stall { losses: Vec::new(), scale, of_best: false }
    }

    /// A record judged against `scale` on the lowest criterion so far: for a stage that hands
    /// on its best iterate, which has stopped improving once no new best comes, however the
    /// last iterate swings around it.
    pub fn of_best(scale: StallScale) -> Self {
        Stall { losses: Vec::new(), scale, of_best: true }
    }

    /// Records the criterion after a step. True when this step is a check (a multiple of
    /// [`CHECK_EVERY`] steps, past the first `after`) at which the criterion fell by less than
    /// [`STALL_FRACTION`] of its [`StallScale`] over the last [`CHECK_EVERY`] steps (a rise
    /// counts as stalled).
    pub fn stalled_after(&mut self, loss: f64, after: usize) -> bool {
        self.losses.push(loss);
        if !self.at_check(after) {
            return false;
        }
        let taken = self.losses.len();
        let lowest = |losses: &[f64]| losses.iter().copied().fold(f64::INFINITY, f64::min);
        let (before, now) = match self.of_best {
            false => (self.losses[taken - 1 - CHECK_EVERY], self.losses[taken - 1]),
            true => (lowest(&self.losses[..taken - CHECK_EVERY]), lowest(&self.losses)),
        };
        let scale = match self.scale {
            StallScale::Recent => before.abs(),
            StallScale::StageStart => before.abs().max(self.losses[0].abs()),
        };
        before - now <= STALL_FRACTION * scale
    }

    /// Whether this step (the last recorded) is a check past the first `after` steps.
    pub fn at_check(&self, after: usize) -> bool {
        let taken = self.losses.len();
        taken > after.max(CHECK_EVERY) && taken % CHECK_EVERY == 0
    }

    /// Forgets the record (a new restart).
    pub fn clear(&mut self) {
        self.losses.clear();
    }
}

/// Each row's best criterion over an intermediate stage's judgements, and how many judgements
/// in a row it has gone without falling under that best by [`STALL_FRACTION`] of it.
#[derive(Debug, Clone, Default)]
pub struct RowStall {
    best: Vec<f64>,
    without_gain: Vec<usize>,
}

impl RowStall {
    /// Records one judgement's criterion per row; true for each row that has now gone
    /// [`UNMET_PATIENCE`] judgements without a new best (a NaN is never a gain).
    pub fn stuck_after(&mut self, loss: &[f64]) -> Vec<bool> {
        if self.best.len() != loss.len() {
            self.best = loss.to_vec();
            self.without_gain = vec![0; loss.len()];
            return vec![false; loss.len()];
        }
        let rows = self.best.iter_mut().zip(&mut self.without_gain).zip(loss);
        rows.map(|((best, without_gain), &now)| {
            if now < *best - STALL_FRACTION * best.abs() || (best.is_nan() && !now.is_nan()) {
                *without_gain = 0;
            } else {
                *without_gain += 1;
            }
            *best = best.min(now);
            *without_gain >= UNMET_PATIENCE
        })
        .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_criterion_is_judged_every_ten_steps_after_the_warmup_and_a_rise_counts_as_stalled() {
        let mut stall = Stall::default();
        let checks: Vec<usize> =
            (1..=40).filter(|&step| stall.stalled_after(1.0 / step as f64, 15) || stall.at_check(15)).collect();
        assert_eq!(checks, [20, 30, 40], "checks past the warm-up only");
        let mut falling = Stall::default();
        assert!(!(1..=20).any(|step| falling.stalled_after(1.0 - 0.01 * step as f64, 0)));
        let mut flat = Stall::default();
        assert_eq!((1..=20).filter(|_| flat.stalled_after(1.0, 0)).count(), 1, "flat: stalled at step 20");
        let mut rising = Stall::default();
        assert!((1..=20).any(|step| rising.stalled_after(step as f64, 0)));
        // From 1 down to a residue halving every step: each check sees the last ten steps fall
        // by 99.9 % of themselves but by under 1 % of the stage's start.
        let residue = |step: i32| if step == 1 { 1.0 } else { 0.5f64.powi(step) };
        let mut against_start = Stall::with_scale(StallScale::StageStart);
        let stalls: Vec<i32> = (1..=30).filter(|&step| against_start.stalled_after(residue(step), 0)).collect();
        assert_eq!(stalls, [20, 30], "against the start, a residue under 1 % of it has stalled");
        let mut against_itself = Stall::default();
        assert!(!(1..=30).any(|step| against_itself.stalled_after(residue(step), 0)), "against itself it falls");
        let mut halving = Stall::with_scale(StallScale::StageStart);
        assert!(
            !(1..=20).any(|step| halving.stalled_after(0.5f64.powi(step / 4), 0)),
            "falling by more than 1 % of the start every ten steps"
        );
    }

    #[test]
    fn a_criterion_of_best_stalls_once_no_new_best_comes_however_the_last_swings() {
        // Down from 1 to 0.1 over the first nine steps, then swinging above that best: 0.35,
        // and at every tenth step 0.5, 0.4, 0.3 (each 0.1 under the one ten steps before).
        let loss = |step: usize| match step {
            1..=9 => 1.0 - 0.1125 * (step - 1) as f64,
            _ if step % 10 == 0 => 0.5 - 0.01 * (step - 10) as f64,
            _ => 0.35,
        };
        let mut of_best = Stall::of_best(StallScale::StageStart);
        let mut of_last = Stall::with_scale(StallScale::StageStart);
        let best: Vec<usize> = (1..=30).filter(|&step| of_best.stalled_after(loss(step), 0)).collect();
        let last: Vec<usize> = (1..=30).filter(|&step| of_last.stalled_after(loss(step), 0)).collect();
        assert_eq!(best, [20, 30], "no new best after step 9");
        assert!(last.is_empty(), "the last value falls by 0.1 every ten steps: {last:?}");
    }

    #[test]
    fn a_row_is_stuck_after_two_judgements_without_a_new_best() {
        let mut stall = RowStall::default();
        // Row 0 keeps falling; row 1 rises, then gains 0.5 % (under 1 % of its best), then
        // falls again; row 2 is flat.
        let judgements = [[1.0, 0.5, 2.0], [0.8, 0.6, 2.0], [0.6, 0.4975, 2.0], [0.4, 0.3, 2.0]];
        let stuck: Vec<Vec<bool>> = judgements.iter().map(|loss| stall.stuck_after(loss)).collect();
        assert_eq!(stuck[0], [false, false, false], "the first judgement sets the bests");
        assert_eq!(stuck[1], [false, false, false]);
        assert_eq!(stuck[2], [false, true, true], "two judgements without a gain of 1 %");
        assert_eq!(stuck[3], [false, false, true], "a new best counts again");
    }
}
