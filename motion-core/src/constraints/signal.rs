//! Points of the body and the per-frame quantities measured on them (ProgMoGen §3.2's atomic
//! measurements): joints `[B, T, 22, 3]` → point `[B, T, 3]` → signal `[B, T − lag, C]`.

use candle_core::{Result, Tensor, D};

use super::geometry::{constant, cross, dot, joint, norm, select_axes, unit};
use crate::program::{
    CentreOfMass, Derivative, Displacement, Distance, DistanceToLine, DistanceToPlane, FrameRef, Point, Position,
    Quantity, Space,
};
use crate::skeleton::{Joint, FACE_JOINTS, FPS, NUM_JOINTS};

/// ProgMoGen's `get_center_of_mass` bones `(parent, child)` and their mass weights (anchors §3.2;
/// the weights sum to 100.26). Each bone's mass sits at its midpoint.
const COM_BONES: [(Joint, Joint, f64); 21] = [
    (Joint::Pelvis, Joint::LeftHip, 7.5),
    (Joint::LeftHip, Joint::LeftKnee, 11.255),
    (Joint::LeftKnee, Joint::LeftAnkle, 5.05),
    (Joint::LeftAnkle, Joint::LeftFoot, 1.38),
    (Joint::Pelvis, Joint::RightHip, 7.5),
    (Joint::RightHip, Joint::RightKnee, 11.255),
    (Joint::RightKnee, Joint::RightAnkle, 5.05),
    (Joint::RightAnkle, Joint::RightFoot, 1.38),
    (Joint::Pelvis, Joint::Spine1, 6.0),
    (Joint::Spine1, Joint::Spine2, 6.65),
    (Joint::Spine2, Joint::Spine3, 6.5),
    (Joint::Spine3, Joint::Neck, 3.0),
    (Joint::Neck, Joint::Head, 5.0),
    (Joint::Spine3, Joint::LeftCollar, 3.0),
    (Joint::LeftCollar, Joint::LeftShoulder, 3.0),
    (Joint::LeftShoulder, Joint::LeftElbow, 3.075),
    (Joint::Spine3, Joint::RightCollar, 3.0),
    (Joint::RightCollar, Joint::RightShoulder, 3.0),
    (Joint::RightShoulder, Joint::RightElbow, 3.075),
    (Joint::RightElbow, Joint::RightWrist, 2.295),
    (Joint::LeftElbow, Joint::LeftWrist, 2.295),
];

/// Per-joint weights `c_j` with `CoM = Σ_j c_j·joint_j` (they sum to 1): each bone gives half
/// its weight to each end. `exclude_head` drops the neck–head bone
/// (ProgMoGen `get_center_of_mass_fixhead`) and renormalises.
pub fn centre_of_mass_weights(exclude_head: bool) -> [f64; NUM_JOINTS] {
    let mut weights = [0.0; NUM_JOINTS];
    let mut total = 0.0;
    for (a, b, w) in COM_BONES {
        if exclude_head && b == Joint::Head {
            continue;
        }
        weights[a.index()] += w / 2.0;
        weights[b.index()] += w / 2.0;
        total += w;
    }
    weights.map(|w| w / total)
}

/// The point's positions `[B, T, 3]` (m).
pub fn point(joints: &Tensor, point: &Point) -> Result<Tensor> {
    match point {
        Point::Joint(j) => joint(joints, *j),
        Point::Midpoint([a, b]) => (joint(joints, *a)? + joint(joints, *b)?)? * 0.5,
        Point::CentreOfMass(com) => centre_of_mass(joints, com),
        Point::FixedM(p) => {
            let (batch, frames, _, _) = joints.dims4()?;
            constant(p, joints.dtype(), joints.device())?.reshape((1, 1, 3))?.broadcast_as((batch, frames, 3))
        }
    }
}

fn centre_of_mass(joints: &Tensor, com: &CentreOfMass) -> Result<Tensor> {
    let weights = constant(&centre_of_mass_weights(com.exclude_head), joints.dtype(), joints.device())?
        .reshape((1, 1, NUM_JOINTS, 1))?;
    let body = joints.broadcast_mul(&weights)?.sum(2)?;
    match &com.load {
        None => Ok(body),
        Some(load) => {
            let [a, b] = load.between;
            let object = ((joint(joints, a)? + joint(joints, b)?)? * 0.5)?;
            (body + (object * load.mass_ratio)?)? / (1.0 + load.mass_ratio)
        }
    }
}

/// The quantity's signal `[B, T − lag, C]` in its unit ([`Quantity::unit`]).
pub fn signal(joints: &Tensor, quantity: &Quantity) -> Result<Tensor> {
    match quantity {
        Quantity::Position(Position { of, axes, space }) => {
            let p = point(joints, of)?;
            let p = match space {
                Space::World => p,
                Space::Root => root_relative(joints, &p)?,
            };
            select_axes(&p, *axes)
        }
        Quantity::Displacement(Displacement { of, since, axes }) => {
            let p = point(joints, of)?;
            let frames = p.dim(1)?;
            let at = since.resolve(frames as u32).ok_or_else(|| frame_error(*since, frames))? as usize;
            select_axes(&p.broadcast_sub(&p.narrow(1, at, 1)?)?, *axes)
        }
        Quantity::Velocity(Derivative { of, axes }) => select_axes(&velocity(&point(joints, of)?)?, *axes),
        Quantity::Speed(Derivative { of, axes }) => {
            norm(&select_axes(&velocity(&point(joints, of)?)?, *axes)?)?.unsqueeze(D::Minus1)
        }
        Quantity::Acceleration(Derivative { of, axes }) => {
            select_axes(&(second_difference(&point(joints, of)?)? * (FPS * FPS))?, *axes)
        }
        Quantity::Distance(Distance { a, b, axes }) => {
            let d = (point(joints, a)? - point(joints, b)?)?;
            norm(&select_axes(&d, *axes)?)?.unsqueeze(D::Minus1)
        }
        Quantity::DistanceToLine(DistanceToLine { of, point_m, direction }) => {
            let p = point(joints, of)?;
            let origin = constant(point_m, p.dtype(), p.device())?;
            let dir = constant(&unit(*direction), p.dtype(), p.device())?;
            norm(&cross(&p.broadcast_sub(&origin)?, &dir)?)?.unsqueeze(D::Minus1)
        }
        Quantity::DistanceToPlane(DistanceToPlane { of, point_m, normal, signed }) => {
            let p = point(joints, of)?;
            let origin = constant(point_m, p.dtype(), p.device())?;
            let n = constant(&unit(*normal), p.dtype(), p.device())?;
            let d = dot(&p.broadcast_sub(&origin)?, &n)?.unsqueeze(D::Minus1)?;
            if *signed {
                Ok(d)
            } else {
                d.abs()
            }
        }
    }
}

fn frame_error(frame: FrameRef, frames: usize) -> candle_core::Error {
    candle_core::Error::Msg(format!("frame {frame:?} is outside a motion of {frames} frames"))
}

/// Forward difference along axis 1 (frames) × fps: positions `[B, T, ..]` (m) → velocities
/// `[B, T − 1, ..]` (m/s).
pub fn velocity(p: &Tensor) -> Result<Tensor> {
    let frames = p.dim(1)?;
    if frames < 2 {
        candle_core::bail!("a velocity needs at least 2 frames, the motion has {frames}");
    }
    (p.narrow(1, 1, frames - 1)? - p.narrow(1, 0, frames - 1)?)? * FPS
}

/// Second difference along axis 1 (frames), `x[t+2] − 2·x[t+1] + x[t]`: `[B, T − 2, ..]` in
/// units per frame².
pub fn second_difference(x: &Tensor) -> Result<Tensor> {
    let frames = x.dim(1)?;
    if frames < 3 {
        candle_core::bail!("an acceleration needs at least 3 frames, the motion has {frames}");
    }
    (x.narrow(1, 2, frames - 2)? - (x.narrow(1, 1, frames - 2)? * 2.0)?)? + x.narrow(1, 0, frames - 2)?
}

/// `p` `[B, T, 3]` in HumanML3D's root frame: relative to the pelvis on the ground plane (y
/// stays absolute) and rotated so the body faces +z. The facing direction of each frame is
/// `f = y × across` with `across` = (right hip − left hip) + (right shoulder − left shoulder),
/// normalised over (x, z); +x is then the character's left `l = (f_z, 0, −f_x)`.
pub fn root_relative(joints: &Tensor, p: &Tensor) -> Result<Tensor> {
    let fj = FACE_JOINTS;
    let across = ((joint(joints, fj.right_hip)? - joint(joints, fj.left_hip)?)?
        + (joint(joints, fj.right_shoulder)? - joint(joints, fj.left_shoulder)?)?)?;
    let (ax, az) = (across.narrow(D::Minus1, 0, 1)?, across.narrow(D::Minus1, 2, 1)?);
    // f = y × across = (a_z, 0, −a_x), normalised on the ground plane.
    let length = ((ax.sqr()? + az.sqr()?)? + super::geometry::NORM_EPS)?.sqrt()?;
    let (fx, fz) = ((az / &length)?, (ax.neg()? / &length)?);
    let d = p.broadcast_sub(&joint(joints, Joint::Pelvis)?)?;
    let (dx, y, dz) = (d.narrow(D::Minus1, 0, 1)?, p.narrow(D::Minus1, 1, 1)?, d.narrow(D::Minus1, 2, 1)?);
    let x_local = ((&dx * &fz)? - (&dz * &fx)?)?;
    let z_local = ((&dx * &fx)? + (&dz * &fz)?)?;
    Tensor::cat(&[x_local, y, z_local], D::Minus1)
}
