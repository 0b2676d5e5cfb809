//! Motions on the user's own rig: a skeleton read from a BVH file or a skinned glTF character
//! ([`TargetRig`], [`character`]), its nodes matched to our 22 joints by the bone names of the
//! common conventions or an explicit map ([`names`]), and the motion carried onto it with its feet kept where the motion plants them
//! ([`transfer`]), written in the rig's own unit and up axis (and into the character's own file).

pub mod character;
pub mod judge;
pub mod names;
pub mod rig;
pub mod transfer;

#[cfg(test)]
mod tests;

pub use judge::{judge_on_rig, RigConstraint, RigJudge};
pub use names::{Convention, Matched};
pub use rig::TargetRig;
pub use transfer::{retarget, RetargetReport, Retargeted};
