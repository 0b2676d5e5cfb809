//! The built-in constraint library and its compiler: a validated [`TaskProgram`] becomes a
//! batched, differentiable loss on joint positions (ProgMoGen §3.2–3.3, RG-DNO supp. D).
//!
//! [`CompiledProgram::compile`] validates the program and resolves everything that does not
//! depend on the motion (frame selections, unit vectors, joint lists) once per run;
//! [`CompiledProgram::evaluate`] maps joints `[B, T, 22, 3]` (m, y up, 20 fps, `T` = the
//! program's frames) to the total `Σ_i w_i·E_i` `[B]` and every constraint's error `E_i` `[B]`.
//! Every error is finite and ≥ 0 and is 0 when its constraint holds; each formula is documented
//! on its [`Expr`] variant. Gradients flow to the joints through every term except the
//! frame masks of conditions and scene gates, which select without gradient as ProgMoGen does.
//!
//! [`TaskProgram`]: crate::program::TaskProgram
//! [`Expr`]: crate::program::Expr

mod body;
mod carry;
pub mod checked;
mod compiled;
mod count;
mod error;
mod flight;
mod frames;
mod geometry;
mod node;
mod probe;
mod satisfaction;
mod scene;
mod signal;
mod support;
#[cfg(test)]
mod tests;

pub use body::{bone_radius_m, surface_points, HEAD_RADIUS_M, SURFACE_POINTS};
pub use carry::{carry_errors, torso_distance, TORSO_CHAIN};
pub use compiled::{CompiledProgram, Evaluation};
pub use count::soft_event_count;
pub use error::ConstraintError;
pub use flight::{flight_deficit, FLIGHT_JOINTS};
pub use geometry::NORM_EPS;
pub use probe::{probe_motion, GradientCheck, STANDING};
pub use satisfaction::{Check, Satisfaction, Unit};
pub use scene::{is_obstacle, primitive_error};
pub use signal::{centre_of_mass_weights, point, root_relative, second_difference, signal, velocity};
pub use support::FOOT_HALF_WIDTH_M;
