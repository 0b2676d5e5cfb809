//! The layout of a 263-d HumanML3D feature frame: which dimensions hold what.

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
