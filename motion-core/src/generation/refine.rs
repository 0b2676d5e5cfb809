//! Kinematic refinement: the last centimetres of a program's geometric constraints closed in
//! joint space on a rigid skeleton, as an animator's IK layer over captured or generated motion.
//!
//! **Why.** The prior makes only the motions its data shows, and DNO moves its start noise
//! inside that set. Every shipped training walk carries its arms the same way: in 8 samples of
//! "a person walks forward" the elbows swing 0.278–0.282 m and the wrists 0.30–0.33 m out to the
//! side of the pelvis, and DNO's Task-1 output keeps exactly that carriage (elbows 0.29–0.30 m)
//! at every learning rate, decorrelation weight and guidance tried: no start noise gives a walk
//! with the arms held in, so both narrow-gap tasks stopped 0.12–0.15 m into the walls. A person
//! walking through a 0.4 m gap keeps their walk and draws the arms in; [`refine`] does that: it
//! adds to the motion a smooth, bounded offset layer that lowers the program's error.
//!
//! **What.** Variables: joint positions `P` `[B, T, 22, 3]` (m), started at the motion `J`; the
//! refined motion is `Q = rigid_bones(P)` (each bone keeps `P`'s direction at `J`'s length, so
//! bones are rigid by construction). With the offset `D = Q − J`, per sample:
//!
//! `L = E_geo(Q) + w_a·Σ_j mean_t ‖D[t+1] − 2D[t] + D[t−1]‖² + w_v·Σ_j mean_t ‖D[t+1] − D[t]‖²
//!      + w_o·Σ_j mean_t ‖D‖² + w_k·Σ_{trunk bones p→c} mean_t ‖D_c − D_p‖²/ℓ²
//!      + W·Σ_j mean_t relu(‖D‖ − cap)² + W·Σ_j mean_t relu(min(J_y, 0) − Q_y)²
//!      + W·Σ_{ankles, toes} mean_t [J_y < 5 cm]·‖D‖²`
//!
//! (`D_c − D_p` is the change of a bone vector, `ℓ` its length: the trunk term is the squared
//! chord of each trunk bone's turn.)
//!
//! `E_geo` is the program's `Σ wᵢ·Eᵢ` without its counting constraints (steps, counted extrema:
//! a count is made by the motion's own strides, never by shifting joints), `W` a fixed steep
//! weight that keeps every joint within [`RefineConfig::max_offset_m`] of where it was and
//! above the floor `y = 0` (or no deeper than it was: a crouch bends the knees, it does not sink
//! the feet), and that holds every ankle and toe that is on the ground (lower than 5 cm) where
//! it is, so stance feet are neither lifted nor slid. Adam on
//! `P` with a cosine-decayed step of [`RefineConfig::lr_m`] metres.
//!
//! **Honesty.** The layer is bounded and smooth, so it cannot turn a walk into a crawl: a
//! constraint that needs a different motion (a 0.5 m barrier) stays violated and the report says
//! so. A sample keeps its refined motion only when the whole program's error (counts included)
//! did not rise, no constraint it met (in natural units, [`CompiledProgram::satisfaction`])
//! fails after, and no flight grows past [`FLOATING_FLIGHT_S`] (lifting a touch-down between
//! two hops to meet a height makes one leap that hangs in the air: seen on
//! `mogen_jump_over_box`, 0.7 → 1.55 s); [`RefineReport`] gives the error and the largest joint
//! offset, and the run's report gives every figure before and after the clean-up stages.

use candle_core::{DType, Result, Tensor, Var, D};
use serde::{Deserialize, Serialize};

use crate::constraints::{CompiledProgram, ConstraintError};
use crate::generation::schedule::Schedule;
use crate::metrics::{longest_flight_s, FLOATING_FLIGHT_S};
use crate::motion::tensor_to_poses;
use crate::optim::AdamW;
use crate::representation::{rigid_bones, RestSkeleton};
use crate::skeleton::{Joint, CONTACT_JOINTS};

/// The trunk's bones, by child joint: their turns are weighted by [`RefineConfig::trunk_stiffness`].
const TRUNK: [Joint; 9] = [
    Joint::LeftHip,
    Joint::RightHip,
    Joint::Spine1,
    Joint::Spine2,
    Joint::Spine3,
    Joint::Neck,
    Joint::Head,
    Joint::LeftCollar,
    Joint::RightCollar,
];

/// An ankle or toe lower than this (m) is on the ground and held in place by the layer.
const PLANTED_HEIGHT_M: f64 = 0.05;

/// Weight `W` of the hinge on offsets beyond the cap (per m² of excess, summed over joints).
const CAP_WEIGHT: f64 = 1.0e4;

/// Settings of the refinement; the defaults are what the narrow-gap tasks were tuned on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RefineConfig {
    /// Whether it runs (off: the motion is returned as it is).
    pub enabled: bool,
    /// Adam steps.
    pub steps: usize,
    /// Peak Adam step on the joint positions, m (cosine-decayed to 0 over the steps).
    pub lr_m: f64,
    /// No joint moves farther than this from where the motion put it, m.
    pub max_offset_m: f64,
    /// `w_a`: weight of the offset's acceleration (keeps the layer free of spikes).
    pub acceleration_weight: f64,
    /// `w_v`: weight of the offset's velocity (keeps the layer slowly varying).
    pub velocity_weight: f64,
    /// `w_o`: weight of the offset itself (only what a constraint needs moves).
    pub offset_weight: f64,
    /// `w_k`: stiffness of the trunk (the bones to the hips, spine, neck, head and collars):
    /// weight of the change of their directions, so the arms move and the torso does not fold.
    pub trunk_stiffness: f64,
}

impl Default for RefineConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            steps: 600,
            lr_m: 0.004,
            max_offset_m: 0.25,
            acceleration_weight: 20.0,
            velocity_weight: 2.0,
            offset_weight: 0.1,
            trunk_stiffness: 10.0,
        }
    }
}

impl RefineConfig {
    /// Errors on settings the loop cannot run with.
    pub fn validate(&self) -> std::result::Result<(), String> {
        for (name, value) in [
            ("lr_m", self.lr_m),
            ("max_offset_m", self.max_offset_m),
            ("acceleration_weight", self.acceleration_weight),
            ("velocity_weight", self.velocity_weight),
            ("offset_weight", self.offset_weight),
            ("trunk_stiffness", self.trunk_stiffness),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(format!("refine.{name} must be finite and non-negative, got {value}"));
            }
        }
        Ok(())
    }
}

/// What the refinement did to one sample.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RefineReport {
    /// Whether the refined motion was kept (false: off, nothing to refine, or the program's
    /// error would have risen).
    pub applied: bool,
    /// The whole program's `Σ wᵢ·Eᵢ` before.
    pub error_before: f64,
    /// The same after (equal to `error_before` when not applied).
    pub error_after: f64,
    /// Largest distance any joint moved, m.
    pub max_offset_m: f64,
    /// Mean distance the joints moved, m.
    pub mean_offset_m: f64,
    /// Adam steps run (0 where none did: off, nothing to refine, or under
    /// [`Schedule::UntilMet`] a batch that already met every geometric constraint at its
    /// tolerance).
    #[serde(default)]
    pub steps: usize,
}

/// Refines `joints` `[B, T, 22, 3]` (m, rigid bones) against `compiled`'s geometric
/// constraints; `initial` as for [`CompiledProgram::evaluate`]. Runs `config.steps` Adam steps;
/// under [`Schedule::UntilMet`] none when every sample already meets every geometric
/// constraint at its tolerance (the judgement of `report.json`: the stage's work is done). Returns the joints (the input rows where not applied) and one
/// report per sample.
pub fn refine(
    joints: &Tensor,
    compiled: &CompiledProgram,
    initial: Option<&Tensor>,
    config: &RefineConfig,
    schedule: Schedule,
) -> std::result::Result<(Tensor, Vec<RefineReport>), ConstraintError> {
    let batch = joints.dim(0)?;
    let before = per_sample(&compiled.evaluate(joints, initial)?.total)?;
    let geometric = compiled.geometric();
    let unchanged = |e: &f64| RefineReport {
        applied: false,
        error_before: *e,
        error_after: *e,
        max_offset_m: 0.0,
        mean_offset_m: 0.0,
        steps: 0,
    };
    let rest = RestSkeleton::mean_of(joints)?;
    let (Some(rest), true, false) = (rest, config.enabled && config.steps > 0, geometric.is_empty()) else {
        return Ok((joints.clone(), before.iter().map(unchanged).collect()));
    };
    if schedule == Schedule::UntilMet && geometric.met_by_every_sample(joints, initial)? {
        return Ok((joints.clone(), before.iter().map(unchanged).collect()));
    }
    let start = joints.detach().to_dtype(DType::F32)?;
    let p = Var::from_tensor(&start)?;
    let mut adam = AdamW::new(vec![p.clone()], 0.0)?;
    let layer = Layer::new(&start, &rest)?;
    for step in 0..config.steps {
        let q = rigid_bones(p.as_tensor(), &rest)?;
        let objective = (geometric.evaluate(&q.to_dtype(joints.dtype())?, initial)?.total.to_dtype(DType::F32)?
            + layer.penalty(&q, config)?)?;
        let grads = objective.sum_all()?.backward()?;
        let decay = ((std::f64::consts::PI * step as f64 / config.steps as f64).cos() + 1.0) / 2.0;
        adam.step(&grads, config.lr_m * decay)?;
    }
    let refined = rigid_bones(p.as_tensor(), &rest)?.to_dtype(joints.dtype())?.detach();
    let after = per_sample(&compiled.evaluate(&refined, initial)?.total)?;
    let offsets = (&refined - joints)?.sqr()?.sum(D::Minus1)?.sqrt()?.flatten_from(1)?; // [B, T·22]
    let max_offset = per_sample(&offsets.max(D::Minus1)?)?;
    let mean_offset = per_sample(&offsets.mean(D::Minus1)?)?;
    let verdicts_before = compiled.satisfaction(joints, initial)?;
    let verdicts_after = compiled.satisfaction(&refined, initial)?;
    let flights =
        |j: &Tensor| -> Result<Vec<f64>> { Ok(tensor_to_poses(j)?.iter().map(|m| longest_flight_s(m)).collect()) };
    let (flight_before, flight_after) = (flights(joints)?, flights(&refined)?);
    let keep: Vec<bool> = (0..batch)
        .map(|i| {
            let no_new_failure = verdicts_before.iter().zip(&verdicts_after).all(|(b, a)| !b.pass[i] || a.pass[i]);
            let no_new_float = flight_after[i] <= flight_before[i].max(FLOATING_FLIGHT_S);
            after[i].is_finite() && after[i] <= before[i] && no_new_failure && no_new_float
        })
        .collect();
    let reports = (0..batch)
        .map(|i| match keep[i] {
            true => RefineReport {
                applied: true,
                error_before: before[i],
                error_after: after[i],
                max_offset_m: max_offset[i],
                mean_offset_m: mean_offset[i],
                steps: config.steps,
            },
            false => unchanged(&before[i]),
        })
        .collect();
    let mask = Tensor::from_vec(keep.iter().map(|&k| u8::from(k)).collect(), (batch, 1, 1, 1), joints.device())?;
    let out = mask.broadcast_as(joints.shape())?.where_cond(&refined, joints)?;
    Ok((out, reports))
}

/// What the offset layer's penalty compares with, built once from the motion `start`
/// `[B, T, 22, 3]`: the trunk's bone indices and inverse lengths, the planted feet and the floor
/// each joint may not go below.
struct Layer {
    start: Tensor,
    contact: Tensor,
    /// `[B, T, 4, 1]`: 1 where an ankle or toe is lower than [`PLANTED_HEIGHT_M`].
    planted: Tensor,
    /// `[B, T, 22, 1]`: `min(J_y, 0)`.
    floor: Tensor,
    trunk_parents: Tensor,
    trunk_children: Tensor,
    /// `[1, 1, 9, 1]`: 1/ℓ of each trunk bone.
    trunk_scale: Tensor,
}

impl Layer {
    fn new(start: &Tensor, rest: &RestSkeleton) -> Result<Self> {
        let device = start.device();
        let height = |t: &Tensor| t.narrow(D::Minus1, 1, 1);
        let contact = Tensor::new(CONTACT_JOINTS.map(|j| j.index() as u32).as_slice(), device)?;
        let planted = height(&start.index_select(&contact, 2)?)?.lt(PLANTED_HEIGHT_M)?.to_dtype(start.dtype())?;
        let (parents, children): (Vec<u32>, Vec<u32>) =
            TRUNK.iter().filter_map(|&c| Some((c.parent()?.index() as u32, c.index() as u32))).unzip();
        let inverse_lengths: Vec<f64> = TRUNK.iter().map(|&c| 1.0 / rest.bone_lengths_m[c.index()].max(1e-3)).collect();
        Ok(Self {
            start: start.clone(),
            floor: height(start)?.minimum(0.0)?,
            planted,
            contact,
            trunk_parents: Tensor::new(parents, device)?,
            trunk_children: Tensor::new(children, device)?,
            trunk_scale: Tensor::from_vec(inverse_lengths, (1, 1, TRUNK.len(), 1), device)?.to_dtype(start.dtype())?,
        })
    }

    /// The penalty per sample `[B]` for the refined joints `q` `[B, T, 22, 3]`, with
    /// `D = q − start`: acceleration, velocity, size, trunk turn, the cap hinge, the floor hinge
    /// and the planted feet, each summed over joints and averaged over frames.
    fn penalty(&self, q: &Tensor, config: &RefineConfig) -> Result<Tensor> {
        let d = &(q - &self.start)?;
        let frames = d.dim(1)?;
        let per_sample = |t: &Tensor| -> Result<Tensor> { t.sum(D::Minus1)?.sum(D::Minus1)?.mean(D::Minus1) };
        let length = (d.sqr()?.sum_keepdim(D::Minus1)? + 1e-12)?.sqrt()?;
        // Feet on the ground stay where they are: an ankle or toe lower than PLANTED_HEIGHT_M
        // keeps its position (the legs bend above it), so the layer neither lifts nor slides them.
        let held = d.index_select(&self.contact, 2)?.broadcast_mul(&self.planted)?;
        // No joint goes below the floor y = 0, nor deeper than it already was.
        let sinking = (&self.floor - q.narrow(D::Minus1, 1, 1)?)?.relu()?;
        let mut total = ((per_sample(&d.sqr()?)? * config.offset_weight)?
            + (per_sample(&(length - config.max_offset_m)?.relu()?.sqr()?)? * CAP_WEIGHT)?
            + (per_sample(&sinking.sqr()?)? * CAP_WEIGHT)?
            + (per_sample(&held.sqr()?)? * CAP_WEIGHT)?)?;
        if config.trunk_stiffness > 0.0 {
            let turn = (d.index_select(&self.trunk_children, 2)? - d.index_select(&self.trunk_parents, 2)?)?;
            let turn = turn.broadcast_mul(&self.trunk_scale)?;
            total = (total + (per_sample(&turn.sqr()?)? * config.trunk_stiffness)?)?;
        }
        if frames >= 2 {
            let velocity = (d.narrow(1, 1, frames - 1)? - d.narrow(1, 0, frames - 1)?)?;
            total = (total + (per_sample(&velocity.sqr()?)? * config.velocity_weight)?)?;
            if frames >= 3 {
                let acceleration = (velocity.narrow(1, 1, frames - 2)? - velocity.narrow(1, 0, frames - 2)?)?;
                total = (total + (per_sample(&acceleration.sqr()?)? * config.acceleration_weight)?)?;
            }
        }
        Ok(total)
    }
}

fn per_sample(t: &Tensor) -> Result<Vec<f64>> {
    t.to_dtype(DType::F64)?.to_vec1::<f64>()
}

#[cfg(test)]
mod tests {
    // Test helpers may unwrap: a failure is the test failing.
    #![allow(clippy::unwrap_used)]

    use candle_core::Device;
    use glam::DVec3;

    use super::*;
    use crate::constraints::STANDING;
    use crate::program::TaskProgram;
    use crate::skeleton::{bone_lengths, NUM_JOINTS};
    use crate::testing::finite_difference_check;

    type Motion = Vec<[[f64; 3]; NUM_JOINTS]>;

    /// The standing pose with the arms held out (elbows at |x| = 0.26 m, wrists at 0.32 m),
    /// walking along +z at 1 m/s with the arms swinging ±4 cm forward and back.
    fn arms_out(frames: usize) -> Motion {
        (0..frames)
            .map(|t| {
                let swing = 0.04 * (t as f64 * 0.5).sin();
                let mut pose = STANDING.map(|[x, y, z]| [x, y, z + 0.05 * t as f64]);
                for (joint, x, dz) in [(18, 0.26, 0.5), (19, -0.26, -0.5), (20, 0.32, 1.0), (21, -0.32, -1.0)] {
                    pose[joint][0] = x;
                    pose[joint][2] += swing * dz;
                }
                pose
            })
            .collect()
    }

    fn tensor(motion: &Motion) -> Tensor {
        let flat: Vec<f64> = motion.iter().flatten().flatten().copied().collect();
        Tensor::from_vec(flat, (1, motion.len(), NUM_JOINTS, 3), &Device::Cpu).unwrap()
    }

    fn poses(joints: &Tensor) -> Motion {
        let rows = joints.squeeze(0).unwrap().to_vec3::<f64>().unwrap();
        rows.iter().map(|f| std::array::from_fn(|j| [f[j][0], f[j][1], f[j][2]])).collect()
    }

    fn compile(frames: usize, constraints: &[&str]) -> CompiledProgram {
        let list: Vec<String> =
            constraints.iter().enumerate().map(|(i, e)| format!(r#"{{"id": "c{}", "expr": {e}}}"#, i + 1)).collect();
        let text = format!(r#"{{"text": "", "frames": {frames}, "constraints": [{}]}}"#, list.join(", "));
        CompiledProgram::compile(&TaskProgram::from_json(&text).unwrap(), &Device::Cpu).unwrap()
    }

    const GAP: &str = r#"{"op": "scene", "body": {"joints": "all"}, "primitive": {"kind": "gap", "centre_x_m": 0.0, "width_m": 0.4}}"#;

    fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
        (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>().sqrt()
    }

    #[test]
    fn arms_are_drawn_into_a_gap_on_rigid_bones_while_the_legs_keep_their_motion() {
        let motion = arms_out(30);
        let compiled = compile(30, &[GAP]);
        let before = compiled.satisfaction(&tensor(&motion), None).unwrap()[0].checks[0].value[0];
        assert!((before - 0.12).abs() < 1e-9, "the wrists start 0.12 m into the walls: {before}");
        let (out, reports) =
            refine(&tensor(&motion), &compiled, None, &RefineConfig::default(), Schedule::Paper).unwrap();
        let after = compiled.satisfaction(&out, None).unwrap()[0].checks[0].value[0];
        assert!(after <= 0.01, "penetration left: {after} m");
        let report = &reports[0];
        assert_eq!(report.steps, RefineConfig::default().steps);
        let (fast, fast_reports) =
            refine(&tensor(&motion), &compiled, None, &RefineConfig::default(), Schedule::UntilMet).unwrap();
        assert_eq!(fast_reports, reports, "an unmet program: the whole budget under either schedule");
        assert_eq!(poses(&fast), poses(&out));
        let (again, met) = refine(&out, &compiled, None, &RefineConfig::default(), Schedule::UntilMet).unwrap();
        assert!(!met[0].applied && met[0].steps == 0, "{:?}", met[0]);
        assert_eq!(poses(&again), poses(&out), "a met program: nothing to refine");
        assert!(report.applied && report.error_after < report.error_before, "{report:?}");
        assert!(report.max_offset_m <= RefineConfig::default().max_offset_m + 1e-3, "{report:?}");
        let refined = poses(&out);
        // Rigid bones: every bone keeps one length over the clip.
        let lengths: Vec<[f64; NUM_JOINTS]> = refined.iter().map(|p| bone_lengths(&p.map(DVec3::from_array))).collect();
        for j in 1..NUM_JOINTS {
            let (lo, hi) =
                lengths.iter().map(|l| l[j]).fold((f64::MAX, f64::MIN), |(lo, hi), l| (lo.min(l), hi.max(l)));
            assert!(hi - lo < 1e-4, "bone to joint {j} stretches from {lo} to {hi} m");
        }
        for (a, b) in motion.iter().zip(&refined) {
            for j in 0..NUM_JOINTS {
                assert!(b[j][1] >= a[j][1].min(0.0) - 1e-3, "joint {j} sank through the floor: {}", b[j][1]);
            }
            // Legs and pelvis keep their motion within 2 cm, the toes on the ground within 2 mm;
            // the arms carry the change.
            for j in [0, 1, 2, 4, 5, 7, 8] {
                assert!(distance(a[j], b[j]) < 0.02, "leg joint {j} moved {} m", distance(a[j], b[j]));
            }
            for j in [10, 11] {
                assert!(distance(a[j], b[j]) < 0.002, "planted toe {j} moved {} m", distance(a[j], b[j]));
            }
        }
        // The layer is smooth: no joint's acceleration grows by more than 5 mm/frame².
        for t in 1..refined.len() - 1 {
            for j in 0..NUM_JOINTS {
                let acc = |m: &Motion| {
                    let d: [f64; 3] = std::array::from_fn(|k| m[t + 1][j][k] - 2.0 * m[t][j][k] + m[t - 1][j][k]);
                    distance(d, [0.0; 3])
                };
                assert!(acc(&refined) <= acc(&motion) + 0.005, "frame {t}, joint {j}: {}", acc(&refined));
            }
        }
    }

    #[test]
    fn a_refinement_that_would_join_two_hops_into_one_long_flight_is_not_kept() {
        // Two 9-frame hops (every joint 0.2 m up) with a 2-frame touch-down between them (toes
        // at 7 cm: on the ground for the flight metric, not planted for the layer).
        let lift = |t: usize| match t {
            5..=12 | 15..=22 => 0.2,
            13 | 14 => 0.05,
            _ => 0.0,
        };
        let motion: Motion = (0..30).map(|t| STANDING.map(|[x, y, z]| [x, y + lift(t), z])).collect();
        let pelvis_high = r#"{"op": "greater_than", "quantity": {"kind": "position", "of": {"joint": "pelvis"}, "axes": "y"}, "min": 1.2, "frames": {"range": {"from": {"frame": 5}, "to": {"frame": 22}}}}"#;
        let compiled = compile(30, &[pelvis_high]);
        let (out, reports) =
            refine(&tensor(&motion), &compiled, None, &RefineConfig::default(), Schedule::Paper).unwrap();
        // Lifting the touch-down would lower the error but leave the body 0.9 s in the air.
        assert!(!reports[0].applied, "{:?}", reports[0]);
        assert_eq!(poses(&out), motion);
    }

    #[test]
    fn a_constraint_out_of_reach_stays_unmet_and_no_joint_moves_past_the_cap() {
        let motion = arms_out(20);
        let head_low = r#"{"op": "less_than", "quantity": {"kind": "position", "of": {"joint": "head"}, "axes": "y"}, "max": 0.5}"#;
        let compiled = compile(20, &[head_low]);
        let config = RefineConfig::default();
        let (out, reports) = refine(&tensor(&motion), &compiled, None, &config, Schedule::Paper).unwrap();
        let verdict = &compiled.satisfaction(&out, None).unwrap()[0];
        assert!(!verdict.pass[0], "a standing figure cannot put its head 1.1 m lower by an offset layer");
        for (a, b) in motion.iter().zip(&poses(&out)) {
            for j in 0..NUM_JOINTS {
                assert!(distance(a[j], b[j]) <= config.max_offset_m + 0.01, "joint {j} moved {}", distance(a[j], b[j]));
            }
        }
        assert!(reports[0].max_offset_m <= config.max_offset_m + 0.01, "{:?}", reports[0]);
    }

    #[test]
    fn counting_constraints_and_a_switched_off_refinement_leave_the_motion_as_it_is() {
        let motion = tensor(&arms_out(20));
        let steps = r#"{"op": "steps", "target_count": 4}"#;
        let (out, reports) =
            refine(&motion, &compile(20, &[steps]), None, &RefineConfig::default(), Schedule::Paper).unwrap();
        assert_eq!((&out - &motion).unwrap().abs().unwrap().max_all().unwrap().to_scalar::<f64>().unwrap(), 0.0);
        assert!(!reports[0].applied);
        let off = RefineConfig { enabled: false, ..RefineConfig::default() };
        let (out, reports) = refine(&motion, &compile(20, &[GAP]), None, &off, Schedule::Paper).unwrap();
        assert_eq!((&out - &motion).unwrap().abs().unwrap().max_all().unwrap().to_scalar::<f64>().unwrap(), 0.0);
        assert!(!reports[0].applied && reports[0].error_after == reports[0].error_before);
    }

    #[test]
    fn bad_settings_are_named() {
        let bad = RefineConfig { lr_m: f64::NAN, ..RefineConfig::default() };
        assert!(bad.validate().unwrap_err().contains("refine.lr_m"));
        let bad = RefineConfig { trunk_stiffness: -1.0, ..RefineConfig::default() };
        assert!(bad.validate().unwrap_err().contains("refine.trunk_stiffness"));
    }

    #[test]
    fn the_layer_penalty_has_the_finite_difference_gradient() {
        let motion = tensor(&arms_out(6));
        let rest = RestSkeleton::mean_of(&motion).unwrap().unwrap();
        let config = RefineConfig { max_offset_m: 0.05, ..RefineConfig::default() };
        // Offsets up to ±0.1 m, so the cap hinge is active on some joints.
        let offsets: Vec<f64> = (0..6 * NUM_JOINTS * 3).map(|i| 0.1 * ((i * 37 % 101) as f64 / 50.0 - 1.0)).collect();
        let q = (&motion + Tensor::from_vec(offsets, (1, 6, NUM_JOINTS, 3), &Device::Cpu).unwrap()).unwrap();
        // Every joint 0.1 m lower: the feet go under the floor, so the floor hinge is active too.
        let lowered =
            (&q - Tensor::new(&[0.0, 0.1, 0.0], &Device::Cpu).unwrap().broadcast_as(q.shape()).unwrap()).unwrap();
        let layer = Layer::new(&motion, &rest).unwrap();
        finite_difference_check(&lowered, |q| layer.penalty(q, &config)?.sum_all(), 1e-6, 1e-4).unwrap();
    }
}
