//! Analytic two-bone inverse kinematics (hip → knee → ankle), as animation tools solve legs.

use glam::DVec3;

/// Where the knee and ankle go when the ankle should reach `target`: thigh and shin keep their
/// lengths `|knee − hip|` and `|ankle − knee|` exactly, and the knee bends in the plane that
/// holds the hip, the target and the original knee (the pole). A target out of reach is
/// replaced by the closest reachable point on the line from the hip. Returns `(knee, ankle,
/// reached)`.
pub fn solve_leg(hip: DVec3, knee: DVec3, ankle: DVec3, target: DVec3) -> (DVec3, DVec3, bool) {
    let (thigh, shin) = ((knee - hip).length(), (ankle - knee).length());
    let to_target = target - hip;
    let distance = to_target.length();
    let Some(u) = to_target.try_normalize() else { return (knee, ankle, false) };
    let (lo, hi) = ((thigh - shin).abs() + 1e-9, thigh + shin - 1e-9);
    let d = distance.clamp(lo, hi);
    // The pole: the original knee's offset from the original hip–ankle line, made
    // perpendicular to the new line.
    let u0 = (ankle - hip).try_normalize().unwrap_or(u);
    let bend = (knee - hip) - u0 * (knee - hip).dot(u0);
    let pole = (bend - u * bend.dot(u)).try_normalize().unwrap_or_else(|| u.any_orthonormal_vector());
    let along = (thigh * thigh + d * d - shin * shin) / (2.0 * d);
    let across = (thigh * thigh - along * along).max(0.0).sqrt();
    let new_knee = hip + u * along + pole * across;
    let new_ankle = hip + u * d;
    (new_knee, new_ankle, (distance - d).abs() < 1e-6)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reaches_the_target_keeping_bone_lengths_and_the_bend_plane() {
        let (hip, knee, ankle) = (DVec3::new(0.0, 0.9, 0.0), DVec3::new(0.0, 0.5, 0.05), DVec3::new(0.0, 0.1, 0.0));
        let target = DVec3::new(0.02, 0.15, 0.2);
        let (k, a, reached) = solve_leg(hip, knee, ankle, target);
        assert!(reached);
        assert!((a - target).length() < 1e-9);
        assert!(((k - hip).length() - (knee - hip).length()).abs() < 1e-9);
        assert!(((a - k).length() - (ankle - knee).length()).abs() < 1e-9);
        // The knee bends to the same side of the hip–ankle line as the original.
        let side = |knee: DVec3, ankle: DVec3| {
            let u = (ankle - hip).normalize();
            (knee - hip) - u * (knee - hip).dot(u)
        };
        assert!(side(k, a).dot(side(knee, ankle)) > 0.0);
        // Out of reach: the leg straightens toward the target.
        let (k, a, reached) = solve_leg(hip, knee, ankle, DVec3::new(0.0, -1.0, 0.0));
        assert!(!reached);
        assert!(((a - hip).length() - ((knee - hip).length() + (ankle - knee).length())).abs() < 1e-6);
        assert!(((k - hip).length() - (knee - hip).length()).abs() < 1e-9);
    }
}
