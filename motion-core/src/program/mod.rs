//! Constraint programs: a motion task as typed data (ProgMoGen's "motion programming", RG-DNO's
//! constraint sets with a relational task parse).
//!
//! A [`TaskProgram`] is what an LLM (or a person) writes as JSON: a text prompt for the prior, a
//! clip length, named constraint [`Expr`]essions and an optional [`RelationalParse`]. Nothing in it
//! is executed: a later compiler maps every node to tensor operations on joints `[B, T, 22, 3]`
//! and sums `weight × error` over the constraints (ProgMoGen's AND). Programs are checked in three
//! layers, all reporting JSON paths such as `constraints[2].expr.args[1].height_m`:
//! 1. [`TaskProgram::from_json`]: serde with `deny_unknown_fields`, snake_case [`Joint`] names,
//!    non-empty lists, unsigned counts and frames;
//! 2. [`TaskProgram::validate`]: finite and sensible numbers, frames inside the clip, consistent
//!    fields, ids of the relational parse;
//! 3. [`validate_json`]: the generated [`json_schema`] (what strict structured output enforces).
//!
//! Conventions ([`crate::skeleton`]): y up, metres, +x the character's left, start facing +z at
//! the origin, 20 fps.
//!
//! [`Joint`]: crate::skeleton::Joint

mod error;
mod expr;
mod limits;
mod quantity;
mod scene;
mod schema;
mod serde_util;
mod task;
mod validate;

#[cfg(test)]
mod tests;

pub use error::{Problem, ProgramError};
pub use expr::{
    Airborne, Args, BoneDirection, Carry, ComInSupport, Count, Equal, EventRegion, Events, Expr, Extremum, FootContact,
    GreaterThan, LessThan, Metric, Not, SceneConstraint, SelfCollision, StayNearInitial, Steps, Support,
};
pub use limits::{MAX_CONSTRAINTS, MAX_FRAMES, MAX_TEXT_CHARS};
pub use quantity::{
    Axes, CarriedLoad, CentreOfMass, Condition, Derivative, Displacement, Distance, DistanceToLine, DistanceToPlane,
    FrameRange, FrameRef, FrameSelection, Point, Position, Quantity, Reduce, Space, Unit,
};
pub use scene::{BalanceBeam, Body, Gap, Ground, Hurdle, InsideBox, JointSet, OverheadBarrier, Primitive, Wall};
pub use schema::{json_schema, validate_json};
pub use serde_util::NonEmpty;
pub use task::{ConstraintGroups, NamedConstraint, RelationalParse, TaskProgram, CONFIDENT_RETRIEVAL};
