//! Analytic two-bone leg IK: the hip stays, the knee bends in the plane of the original knee,
//! the ankle goes to its target (or the closest point the leg reaches) and the toe follows at
//! the fixed ankle–toe length. Every bone keeps the length it had in the input frame.
//!
//! Near full extension the reach is softened ("soft IK", as animation rigs do): the law of
//! cosines puts the knee at `√(reach − distance)` from the hip–ankle line, so a target crossing
//! the reach limit snaps a straight knee bent within a frame. Within `soft_m` of the limit the
//! ankle instead approaches it exponentially and never quite straightens the leg.

use glam::DVec3;

/// One leg's joints, metres, world axes (y up).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Leg {
    /// Hip joint (never moved).
    pub hip: DVec3,
    /// Knee joint.
    pub knee: DVec3,
    /// Ankle joint.
    pub ankle: DVec3,
    /// Toe-ball joint (HumanML3D's `*_foot`).
    pub toe: DVec3,
}

/// A solved leg and whether the ankle reached its target.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LegSolution {
    /// The new joints; `hip` is the input's.
    pub leg: Leg,
    /// `false` when the ankle target was farther from the hip than thigh + shin, or nearer than
    /// |thigh − shin|; the ankle then lies on the hip–target line, at the [`soft_reach`] distance.
    pub reached: bool,
}

/// Solves `leg` so that the ankle lies at `ankle_target` and the toe points at `toe_target`.
///
/// Thigh `|knee − hip|`, shin `|ankle − knee|` and foot `|toe − ankle|` keep their input lengths.
/// A target nearer than `thigh + shin − soft_m` to the hip is hit exactly; beyond, the ankle lies
/// on the hip–target line at [`soft_reach`] of the distance, m.
/// The knee lies in the plane spanned by the hip→target line and `pole`, the way the knee
/// bends ([`knee_bend`], or [`knee_poles`] over several frames); any vector perpendicular to that
/// line when `pole` lies along it. The toe is placed at the foot's
/// length from the new ankle towards `toe_target` (exactly on it when the two targets are a
/// foot's length apart).
pub fn solve_leg(leg: &Leg, ankle_target: DVec3, toe_target: DVec3, pole: DVec3, soft_m: f64) -> LegSolution {
    let thigh = (leg.knee - leg.hip).length();
    let shin = (leg.ankle - leg.knee).length();
    let foot = (leg.toe - leg.ankle).length();
    let to_target = ankle_target - leg.hip;
    let axis = to_target.try_normalize().or((leg.ankle - leg.hip).try_normalize()).unwrap_or(DVec3::NEG_Y);
    // Reach limits; a tiny floor keeps the law of cosines finite when thigh = shin.
    let (min_reach, max_reach) = (((thigh - shin).abs()).max(1e-9), thigh + shin);
    let distance = to_target.length();
    let reached = distance >= min_reach && distance <= max_reach;
    let distance = soft_reach(distance, max_reach, soft_m).max(min_reach);
    let pole = perpendicular(pole, axis).unwrap_or_else(|| axis.any_orthonormal_vector());
    // Law of cosines for the angle at the hip between the hip→ankle line and the thigh.
    let cos_hip = ((thigh * thigh + distance * distance - shin * shin) / (2.0 * thigh * distance)).clamp(-1.0, 1.0);
    let sin_hip = (1.0 - cos_hip * cos_hip).max(0.0).sqrt();
    let knee = leg.hip + thigh * (cos_hip * axis + sin_hip * pole);
    let ankle = leg.hip + distance * axis;
    let toe_direction =
        (toe_target - ankle).try_normalize().or((leg.toe - leg.ankle).try_normalize()).unwrap_or(DVec3::Z);
    let toe = ankle + foot * toe_direction;
    LegSolution { leg: Leg { hip: leg.hip, knee, ankle, toe }, reached }
}

/// Which way the knee of `leg` bends, m: the knee's offset from the hip–ankle line, plus a
/// little of `forward` (up to `STRAIGHT_KNEE_M` as the offset shrinks to 0), so a leg that is
/// straight or nearly so bends forward like a knee rather than wherever round-off points.
///
/// Taken against the leg's own hip–ankle line, not the line to the new target: a straight
/// stance leg whose ankle is held ahead of where it was would otherwise have its thigh direction
/// read as a backward bend, and its knee flips behind the leg for a frame (seen as a 0.49
/// m/frame² spike on the README's gap task). Its length says how well the frame defines the
/// direction, so a sum over neighbouring frames weights the well-bent ones.
pub fn knee_bend(leg: &Leg, forward: DVec3) -> DVec3 {
    let line = (leg.ankle - leg.hip).try_normalize().unwrap_or(DVec3::NEG_Y);
    let knee = leg.knee - leg.hip;
    let offset = knee - knee.dot(line) * line;
    let straightness = (1.0 - offset.length() / STRAIGHT_KNEE_M).max(0.0);
    offset + STRAIGHT_KNEE_M * straightness * forward.normalize_or_zero()
}

/// Frames on either side whose [`knee_bend`]s [`knee_poles`] sums (0.1 s at 20 fps).
pub const KNEE_BEND_FRAMES: usize = 2;

/// The pole of each frame's leg solve: the [`knee_bend`]s of the frames within
/// [`KNEE_BEND_FRAMES`] summed (`legs` and the body's `forwards`, one per frame). A knee the
/// motion holds nearly straight for a frame or two bends only 2–3 cm off its hip–ankle line,
/// sideways or backwards as it happens; a leg the IK bends further there would swing its knee
/// that way and back within a frame (up to 0.23 m/frame² on generated turning walks). In the sum
/// the well-bent neighbours, whose bends are 10–20 cm long, set the direction.
pub fn knee_poles(legs: &[Leg], forwards: &[DVec3]) -> Vec<DVec3> {
    let bends: Vec<DVec3> = legs.iter().zip(forwards).map(|(leg, &forward)| knee_bend(leg, forward)).collect();
    (0..bends.len())
        .map(|t| bends[t.saturating_sub(KNEE_BEND_FRAMES)..(t + KNEE_BEND_FRAMES + 1).min(bends.len())].iter().sum())
        .collect()
}

/// A knee less than this off its hip–ankle line counts as nearly straight, m.
const STRAIGHT_KNEE_M: f64 = 0.01;

/// Distance from the hip at which a leg of full reach `max_reach` (m) puts an ankle whose target
/// is `distance` away: the distance itself up to `max_reach − soft_m`, then
/// `max_reach − soft_m·exp(−(distance − max_reach + soft_m)/soft_m)`, which continues it with
/// the same slope and approaches `max_reach` without reaching it (`soft_m` = 0: a hard clamp).
pub fn soft_reach(distance: f64, max_reach: f64, soft_m: f64) -> f64 {
    let start = max_reach - soft_m;
    if soft_m <= 0.0 || distance <= start {
        distance.min(max_reach)
    } else {
        max_reach - soft_m * (-(distance - start) / soft_m).exp()
    }
}

/// The unit component of `v` perpendicular to the unit `axis`, if it is not negligible.
fn perpendicular(v: DVec3, axis: DVec3) -> Option<DVec3> {
    let p = v - v.dot(axis) * axis;
    (p.length() > 1e-9 * v.length().max(1.0)).then(|| p.normalize())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bent_leg() -> Leg {
        Leg {
            hip: DVec3::new(0.1, 0.9, 0.0),
            knee: DVec3::new(0.1, 0.5, 0.12),
            ankle: DVec3::new(0.1, 0.07, 0.0),
            toe: DVec3::new(0.1, 0.02, 0.12),
        }
    }

    fn lengths(l: &Leg) -> [f64; 3] {
        [(l.knee - l.hip).length(), (l.ankle - l.knee).length(), (l.toe - l.ankle).length()]
    }

    fn assert_lengths_kept(before: &Leg, after: &Leg) {
        for (a, b) in lengths(before).iter().zip(lengths(after)) {
            assert!((a - b).abs() <= 1e-12 * a, "{a} vs {b}");
        }
    }

    #[test]
    fn a_reachable_target_is_hit_with_every_length_kept() {
        let leg = bent_leg();
        let ankle = DVec3::new(0.15, 0.065, 0.1);
        let toe = ankle + DVec3::new(0.0, -0.05, 0.12);
        let s = solve_leg(&leg, ankle, toe, DVec3::Z, 0.0);
        assert!(s.reached);
        assert_eq!(s.leg.hip, leg.hip);
        assert!((s.leg.ankle - ankle).length() < 1e-12);
        assert!((s.leg.toe - toe).length() < 1e-3, "toe target a foot's length away (±1 mm)");
        assert_lengths_kept(&leg, &s.leg);
        // The knee stays on the pole's side: in front (+z) of the hip–ankle line.
        let axis = (s.leg.ankle - s.leg.hip).normalize();
        let bend = perpendicular(s.leg.knee - s.leg.hip, axis).unwrap();
        assert!(bend.z > 0.9, "knee bends forward like the original: {bend}");
    }

    #[test]
    fn a_straight_leg_held_ahead_bends_its_knee_forward() {
        // A straight stance leg under the hip; its ankle is held 15 cm ahead and 5 cm higher (the
        // network slid it back). Against the line to the target the straight thigh points back.
        let leg = Leg {
            hip: DVec3::new(0.1, 0.9, 0.0),
            knee: DVec3::new(0.1, 0.485, 0.0),
            ankle: DVec3::new(0.1, 0.07, 0.0),
            toe: DVec3::new(0.1, 0.02, 0.12),
        };
        let ankle = DVec3::new(0.1, 0.12, 0.15);
        let s = solve_leg(&leg, ankle, ankle + DVec3::new(0.0, -0.05, 0.12), DVec3::Z, 0.01);
        assert!(s.reached);
        assert_lengths_kept(&leg, &s.leg);
        let axis = (s.leg.ankle - s.leg.hip).normalize();
        let bend = perpendicular(s.leg.knee - s.leg.hip, axis).unwrap();
        assert!(bend.z > 0.9, "the knee bends forward, not behind the leg: {bend}");
    }

    #[test]
    fn the_original_targets_give_back_the_original_leg() {
        let leg = bent_leg();
        let s = solve_leg(&leg, leg.ankle, leg.toe, DVec3::Z, 0.0);
        assert!(s.reached);
        for (a, b) in [(s.leg.knee, leg.knee), (s.leg.ankle, leg.ankle), (s.leg.toe, leg.toe)] {
            assert!((a - b).length() < 1e-12, "{a} vs {b}");
        }
    }

    #[test]
    fn an_unreachable_target_gives_the_closest_reachable_point() {
        let leg = bent_leg();
        let far = leg.hip + DVec3::new(0.0, -2.0, 0.0);
        let s = solve_leg(&leg, far, far + DVec3::Z, DVec3::Z, 0.0);
        assert!(!s.reached);
        let [thigh, shin, _] = lengths(&leg);
        // Straight leg pointing at the target.
        assert!((s.leg.ankle - (leg.hip - DVec3::Y * (thigh + shin))).length() < 1e-12);
        assert_lengths_kept(&leg, &s.leg);
        // Too near: the ankle stops |thigh − shin| from the hip.
        let near = solve_leg(&leg, leg.hip + DVec3::new(0.0, -1e-3, 0.0), leg.toe, DVec3::Z, 0.0);
        assert!(!near.reached);
        assert!(((near.leg.ankle - leg.hip).length() - (thigh - shin).abs()).abs() < 1e-12);
        assert_lengths_kept(&leg, &near.leg);
    }

    #[test]
    fn a_straight_leg_bends_forward() {
        let leg = Leg {
            hip: DVec3::new(0.0, 1.0, 0.0),
            knee: DVec3::new(0.0, 0.55, 0.0),
            ankle: DVec3::new(0.0, 0.1, 0.0),
            toe: DVec3::new(0.0, 0.05, 0.12),
        };
        let s = solve_leg(&leg, DVec3::new(0.0, 0.2, 0.0), leg.toe + DVec3::Y * 0.1, DVec3::new(0.0, 0.0, 2.0), 0.0);
        assert!(s.reached);
        assert!(s.leg.knee.z > 0.1, "knee forward (+z): {}", s.leg.knee);
        assert_lengths_kept(&leg, &s.leg);
    }

    #[test]
    fn a_knee_straight_for_one_frame_keeps_bending_the_way_its_neighbours_do() {
        // Seven frames of a leg bent forward (+z) by 20 cm, except frame 3: nearly straight, its
        // knee 2 cm off the hip–ankle line, outwards and a little back.
        let [thigh, shin] = [0.45, 0.45];
        let leg_bent = |off: DVec3| {
            let (hip, ankle) = (
                DVec3::new(0.1, 0.9, 0.0),
                DVec3::new(0.1, 0.9 - 2.0 * (0.45f64.powi(2) - off.length_squared()).sqrt(), 0.0),
            );
            Leg { hip, knee: (hip + ankle) / 2.0 + off, ankle, toe: ankle + DVec3::new(0.0, -0.05, 0.12) }
        };
        let odd = DVec3::new(0.018, 0.0, -0.009);
        let legs: Vec<Leg> = (0..7).map(|t| leg_bent(if t == 3 { odd } else { DVec3::new(0.0, 0.0, 0.2) })).collect();
        let poles = knee_poles(&legs, &[DVec3::Z; 7]);
        let cos = poles[3].normalize().dot(DVec3::Z);
        assert!(cos > 0.95, "frame 3's pole follows its neighbours: {}", poles[3]);
        // Held 20 cm nearer the hip (a lifted, caught foot), frame 3's knee bends forward, as
        // in the frames around it; with the frame's own bend it would swing out and back.
        let leg = legs[3];
        let target = leg.ankle + DVec3::Y * 0.2;
        let knee_off = |pole: DVec3| {
            let s = solve_leg(&leg, target, target + DVec3::new(0.0, -0.05, 0.12), pole, 0.0);
            assert!(s.reached);
            assert_lengths_kept(&leg, &s.leg);
            s.leg.knee - (s.leg.hip + s.leg.ankle) / 2.0
        };
        let (smoothed, own) = (knee_off(poles[3]), knee_off(knee_bend(&leg, DVec3::Z)));
        assert!(smoothed.z > 0.2 && smoothed.x.abs() < 0.08, "forward: {smoothed}");
        assert!(own.x > 0.2 && own.z < 0.0, "the frame's own bend points out and back: {own}");
        assert!((thigh + shin - (leg.ankle - leg.hip).length()) < 0.002, "nearly straight in the input");
    }

    #[test]
    fn the_soft_reach_is_smooth_and_never_straightens_the_leg() {
        let (reach, soft) = (0.9, 0.02);
        assert_eq!(soft_reach(0.5, reach, soft), 0.5);
        assert_eq!(soft_reach(1.5, reach, 0.0), reach);
        // Continuous with slope 1 where it starts, then approaching the reach from below.
        let start = reach - soft;
        assert!((soft_reach(start + 1e-7, reach, soft) - (start + 1e-7)).abs() < 1e-12);
        let mut last = start;
        for k in 1..200 {
            let d = soft_reach(start + 0.001 * k as f64, reach, soft);
            assert!(d > last && d < reach, "{d}");
            last = d;
        }
        // A target sweeping through the reach limit moves the knee smoothly: its second
        // difference over 1 mm steps stays small (a hard clamp makes a cusp there).
        let leg = bent_leg();
        let [thigh, shin, _] = lengths(&leg);
        let knee_at = |d: f64, soft: f64| {
            let target = leg.hip + d * DVec3::new(0.0, -1.0, 0.05).normalize();
            solve_leg(&leg, target, target + DVec3::Z * 0.13, DVec3::Z, soft).leg.knee
        };
        let kink = |soft: f64| {
            (-40..40)
                .map(|k| {
                    let d = thigh + shin + 0.001 * k as f64;
                    (knee_at(d + 0.001, soft) - 2.0 * knee_at(d, soft) + knee_at(d - 0.001, soft)).length()
                })
                .fold(0.0, f64::max)
        };
        assert!(kink(0.0) > 0.01, "hard clamp: {}", kink(0.0));
        assert!(kink(soft) < 0.1 * kink(0.0), "soft {} vs hard {}", kink(soft), kink(0.0));
        // 1 cm out of reach: the leg stops 2 cm · e^(−1.5) = 4.5 mm short of straight.
        let s = solve_leg(&leg, leg.hip - DVec3::Y * (thigh + shin + 0.01), leg.toe, DVec3::Z, soft);
        let short = thigh + shin - (s.leg.ankle - leg.hip).length();
        assert!(!s.reached && (short - 0.02 * (-1.5f64).exp()).abs() < 1e-12, "{short}");
        assert_lengths_kept(&leg, &s.leg);
    }
}
