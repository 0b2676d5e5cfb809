//! An object held between two hands (ProgMoGen HOI-2, "carry a box/ball"): the hands apart by
//! the object's size and the object clear of the torso ([`crate::program::Carry`]).

use candle_core::{Result, Tensor, D};

use super::body::bone_radius_m;
use super::geometry::{dot, joint, norm};
use crate::skeleton::Joint;

/// The spine chain whose bone capsules ([`bone_radius_m`]) make the torso an object must clear.
pub const TORSO_CHAIN: [Joint; 5] = [Joint::Pelvis, Joint::Spine1, Joint::Spine2, Joint::Spine3, Joint::Neck];

/// Distance (m) from points `c` `[B, T, 3]` to the torso's surface, `[B, T]` (negative inside):
/// the least, over the capsules of [`TORSO_CHAIN`]'s bones, of the distance to the bone's segment
/// minus its radius.
pub fn torso_distance(joints: &Tensor, c: &Tensor) -> Result<Tensor> {
    let mut nearest: Option<Tensor> = None;
    for pair in TORSO_CHAIN.windows(2) {
        let (a, b) = (joint(joints, pair[0])?, joint(joints, pair[1])?);
        let ab = (&b - &a)?;
        let along = dot(&(c - &a)?, &ab)?.div(&(dot(&ab, &ab)? + 1e-12)?)?.clamp(0.0, 1.0)?;
        let closest = (a + ab.broadcast_mul(&along.unsqueeze(D::Minus1)?)?)?;
        let surface = (norm(&(c - closest)?)? - bone_radius_m(pair[1]))?;
        nearest = Some(match nearest {
            None => surface,
            Some(n) => n.minimum(&surface)?,
        });
    }
    nearest.ok_or_else(|| candle_core::Error::Msg("the torso chain has no bone".into()))
}

/// Per frame, `[B, T]` each: the hands' distance minus the object's diameter (m, signed), and how
/// far the object (a ball of that diameter centred between the hands) comes inside
/// `clearance` of the torso's surface (m, ≥ 0).
pub fn carry_errors(joints: &Tensor, hands: [Joint; 2], diameter: f64, clearance: f64) -> Result<(Tensor, Tensor)> {
    let (a, b) = (joint(joints, hands[0])?, joint(joints, hands[1])?);
    let gap = (norm(&(&a - &b)?)? - diameter)?;
    let centre = ((a + b)? * 0.5)?;
    let intrusion = ((diameter / 2.0 + clearance) - torso_distance(joints, &centre)?)?.relu()?;
    Ok((gap, intrusion))
}
