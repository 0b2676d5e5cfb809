//! The HumanML3D 263-d motion representation: layout, extraction from joint positions, the
//! differentiable recovery of joint positions on a rigid rest skeleton, and Mean/Std normalisation.
//!
//! Per feature frame (J = 22 joints; see `reference/anchors.md` §1.7):
//!
//! | slice | dims | meaning |
//! |---|---|---|
//! | `[0]` | 1 | root yaw velocity: arcsin of the y part of `r[t+1]·r[t]⁻¹` (half the yaw step, rad) |
//! | `[1..3]` | 2 | root x/z velocity, m/frame, in the heading frame of frame t+1 |
//! | `[3]` | 1 | root height y, m |
//! | `[4..67]` | 21×3 | joints 1..21 relative to the root's x/z, rotated to face +z (y absolute) |
//! | `[67..193]` | 21×6 | local joint rotations 1..21, continuous 6-D (first two matrix columns) |
//! | `[193..259]` | 22×3 | joint displacement t→t+1, m/frame, in the heading frame of frame t |
//! | `[259..263]` | 4 | foot contacts `[l_ankle, l_foot, r_ankle, r_foot]`, 0 or 1 |
//!
//! A clip of N joint frames gives N−1 feature frames.

mod extract;
mod normalization;
mod planted_feet;
mod recover;
mod rigid;

pub use extract::{canonicalize, extract_features, ExtractedMotion, FOOT_CONTACT_THRESHOLD_M2};
pub(crate) use extract::{facing_direction, heading_rotation};
pub use normalization::{MeanStd, NormalizationError};
pub use planted_feet::{root_velocity_from_planted_feet, PLANTED_CONTACT};
pub use recover::recover_from_ric;
pub use rigid::{rigid_bones, RestSkeleton};

use std::ops::Range;

use crate::skeleton::NUM_JOINTS;

/// Dimension of one feature frame.
pub const FEATURE_DIM: usize = 263;
/// Root yaw velocity (one value).
pub const ROOT_ROT_VEL: usize = 0;
/// Root x/z linear velocity.
pub const ROOT_LIN_VEL: Range<usize> = 1..3;
/// Root height.
pub const ROOT_Y: usize = 3;
/// Root-relative joint positions of joints 1..21.
pub const RIC: Range<usize> = 4..4 + (NUM_JOINTS - 1) * 3;
/// Continuous-6D local rotations of joints 1..21.
pub const ROT: Range<usize> = RIC.end..RIC.end + (NUM_JOINTS - 1) * 6;
/// Local joint velocities of all 22 joints.
pub const LOCAL_VEL: Range<usize> = ROT.end..ROT.end + NUM_JOINTS * 3;
/// Foot contacts.
pub const FOOT_CONTACT: Range<usize> = LOCAL_VEL.end..LOCAL_VEL.end + 4;

/// One frame of features.
pub type FeatureFrame = [f32; FEATURE_DIM];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout_covers_263_dims_without_gaps() {
        assert_eq!(RIC.start, ROOT_Y + 1);
        assert_eq!(ROOT_LIN_VEL.end, ROOT_Y);
        assert_eq!(FOOT_CONTACT.end, FEATURE_DIM);
        assert_eq!((RIC.len(), ROT.len(), LOCAL_VEL.len()), (63, 126, 66));
    }
}
