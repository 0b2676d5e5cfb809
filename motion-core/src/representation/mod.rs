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
mod layout;
mod normalization;
mod planted_feet;
mod recover;
mod rigid;

pub use extract::{canonicalize, extract_features, ExtractedMotion, FOOT_CONTACT_THRESHOLD_M2};
pub(crate) use extract::{facing_direction, heading_rotation};
pub use layout::{FeatureFrame, FEATURE_DIM, FOOT_CONTACT, LOCAL_VEL, RIC, ROOT_LIN_VEL, ROOT_ROT_VEL, ROOT_Y, ROT};
pub use normalization::{MeanStd, NormalizationError};
pub use planted_feet::{root_velocity_from_planted_feet, PLANTED_CONTACT};
pub use recover::recover_from_ric;
pub use rigid::{rigid_bones, RestSkeleton};
