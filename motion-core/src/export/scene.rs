//! The task's scene primitives and position targets as solid boxes, for the 3-D outputs (glTF
//! meshes, the viewer).
//!
//! A constraint's primitive is a region (a gap between two infinite walls, a barrier over a z
//! range); to draw it we give it a finite, conventional size: walls 2 m high and 0.1 m thick, an
//! overhead barrier 0.1 m thick and as wide as the motion's x extent plus 1 m, a hurdle's bar
//! likewise. Where a primitive has no z range, it spans the motions' z extent plus 1 m each way.
//! The ground is not drawn here (viewers draw their own grid). A position target (an `equal`
//! constraint on a world position) is a marker 6 cm thick along each constrained axis, spanning
//! the motions along each free horizontal axis and lying on the floor when the height is free:
//! a point for x, y, z, a floor mark for x, z, a finish line across the path for z alone.
//! Boxes are in the project's axes (m, y up, +z forward, +x left).

use glam::{DQuat, DVec3};

use crate::program::{Expr, Primitive, Quantity, Space, TaskProgram};
use crate::skeleton::Pose;

/// Height of drawn walls, m.
const WALL_HEIGHT_M: f64 = 2.0;
/// Thickness of drawn walls, barriers and outlines, m.
const THICKNESS_M: f64 = 0.1;
/// How far beyond the motions an unbounded primitive is drawn, m.
const PAD_M: f64 = 1.0;
/// Half-width of a drawn balance beam that is a line, m.
const LINE_BEAM_HALF_WIDTH_M: f64 = 0.05;
/// Half thickness of a target marker along a constrained axis, m.
const TARGET_HALF_M: f64 = 0.03;
/// Height of a target marker lying on the floor, m.
const FLOOR_MARK_M: f64 = 0.01;

/// What a box stands for, for colours and names.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SceneRole {
    /// Something the body must not enter (wall, barrier, hurdle).
    Obstacle,
    /// The outline of a region the body must stay inside.
    Region,
    /// Something to stand or walk on (a balance beam).
    Support,
    /// Where a constraint asks a point of the body to be.
    Target,
}

/// A position a constraint asks a point of the body to reach (an `equal` constraint on a world
/// position).
#[derive(Debug, Clone, PartialEq)]
pub struct PositionTarget {
    /// Name, e.g. `c2: the pelvis ends 5 m ahead`.
    pub name: String,
    /// The constrained x, y, z, m; `None` where the constraint leaves a coordinate free.
    pub coordinates_m: [Option<f64>; 3],
}

/// The position targets of `program` (inside `and`, `or` and `not` too).
pub fn position_targets(program: &TaskProgram) -> Vec<PositionTarget> {
    let mut out = Vec::new();
    for constraint in &program.constraints {
        let name = match &constraint.description {
            Some(text) => format!("{}: {text}", constraint.id),
            None => format!("{} target", constraint.id),
        };
        constraint.expr.walk("", &mut |expr, _| {
            let Expr::Equal(equal) = expr else { return };
            let Quantity::Position(position) = &equal.quantity else { return };
            if position.space == Space::World {
                let mut coordinates_m = [None; 3];
                for (&axis, &value) in position.axes.indices().iter().zip(&equal.target) {
                    coordinates_m[axis] = Some(value);
                }
                out.push(PositionTarget { name: name.clone(), coordinates_m });
            }
        });
    }
    out
}

/// One solid box: `centre_m` and `half_extents_m` along the box's own axes, turned by `rotation`.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SceneBox {
    /// Name, e.g. `gap left wall`.
    pub name: String,
    /// What it stands for.
    pub role: SceneRole,
    /// Centre, m.
    pub centre_m: [f64; 3],
    /// Half sizes along the box's x, y, z, m.
    pub half_extents_m: [f64; 3],
    /// Rotation of the box (x, y, z, w), unit.
    pub rotation_xyzw: [f64; 4],
}

/// The region the motions occupy, m: sizes unbounded primitives.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SceneExtent {
    /// Smallest x, y, z of any joint.
    pub min_m: DVec3,
    /// Largest x, y, z of any joint.
    pub max_m: DVec3,
}

impl SceneExtent {
    /// The bounding box of every joint of `motions`; a 1 m cube at the origin when empty.
    pub fn of<'a>(motions: impl IntoIterator<Item = &'a [Pose]>) -> Self {
        let mut points = motions.into_iter().flatten().flatten().copied().filter(|p| p.is_finite());
        let Some(first) = points.next() else {
            return Self { min_m: DVec3::splat(-0.5), max_m: DVec3::splat(0.5) };
        };
        let (min_m, max_m) = points.fold((first, first), |(lo, hi), p| (lo.min(p), hi.max(p)));
        Self { min_m, max_m }
    }
}

fn aligned(name: String, role: SceneRole, lo: DVec3, hi: DVec3) -> SceneBox {
    SceneBox {
        name,
        role,
        centre_m: ((lo + hi) * 0.5).to_array(),
        half_extents_m: ((hi - lo).abs() * 0.5).to_array(),
        rotation_xyzw: [0.0, 0.0, 0.0, 1.0],
    }
}

/// Boxes drawing `primitives` and `targets` around motions occupying `extent`.
pub fn scene_boxes(primitives: &[Primitive], targets: &[PositionTarget], extent: SceneExtent) -> Vec<SceneBox> {
    let z_span = |range: Option<[f64; 2]>| range.unwrap_or([extent.min_m.z - PAD_M, extent.max_m.z + PAD_M]);
    let x_span = [extent.min_m.x - PAD_M, extent.max_m.x + PAD_M];
    let mut out = Vec::new();
    for primitive in primitives {
        match primitive {
            Primitive::Gap(gap) => {
                let [z0, z1] = z_span(gap.z_range_m);
                let inner = gap.width_m / 2.0;
                for (side, sign) in [("left", 1.0), ("right", -1.0)] {
                    let near = gap.centre_x_m + sign * inner;
                    let far = near + sign * THICKNESS_M;
                    out.push(aligned(
                        format!("gap {side} wall"),
                        SceneRole::Obstacle,
                        DVec3::new(near, 0.0, z0),
                        DVec3::new(far, WALL_HEIGHT_M, z1),
                    ));
                }
            }
            Primitive::OverheadBarrier(bar) => {
                let [z0, z1] = bar.z_range_m;
                let [x0, x1] = bar.x_range_m.unwrap_or(x_span);
                let y = bar.underside_height_m;
                out.push(aligned(
                    "overhead barrier".into(),
                    SceneRole::Obstacle,
                    DVec3::new(x0, y, z0),
                    DVec3::new(x1, y + THICKNESS_M, z1),
                ));
            }
            Primitive::Hurdle(hurdle) => {
                let [z0, z1] = hurdle.z_range_m;
                let [x0, x1] = hurdle.x_range_m.unwrap_or(x_span);
                out.push(aligned(
                    "hurdle".into(),
                    SceneRole::Obstacle,
                    DVec3::new(x0, 0.0, z0),
                    DVec3::new(x1, hurdle.height_m, z1),
                ));
            }
            Primitive::Ground(_) => {}
            Primitive::InsideBox(region) => {
                let x = region.x_range_m.unwrap_or(x_span);
                let z = region.z_range_m.unwrap_or(z_span(None));
                let y = region.y_range_m.unwrap_or([0.0, 0.0]);
                let h = (y[1] - y[0]).max(THICKNESS_M);
                // Four low rails on the region's border.
                let t = THICKNESS_M / 2.0;
                let rails = [
                    ("front", DVec3::new(x[0], y[0], z[1] - t), DVec3::new(x[1], y[0] + h, z[1] + t)),
                    ("back", DVec3::new(x[0], y[0], z[0] - t), DVec3::new(x[1], y[0] + h, z[0] + t)),
                    ("left", DVec3::new(x[1] - t, y[0], z[0]), DVec3::new(x[1] + t, y[0] + h, z[1])),
                    ("right", DVec3::new(x[0] - t, y[0], z[0]), DVec3::new(x[0] + t, y[0] + h, z[1])),
                ];
                for (side, lo, hi) in rails {
                    out.push(aligned(format!("region {side} edge"), SceneRole::Region, lo, hi));
                }
            }
            Primitive::Wall(wall) => {
                let normal = DVec3::from_array(wall.normal).try_normalize().unwrap_or(DVec3::X);
                let point = DVec3::from_array(wall.point_m);
                let size = (extent.max_m - extent.min_m).max_element() + 2.0 * PAD_M;
                // The box's x axis along the normal, its face on the plane, on the blocked side.
                let rotation = DQuat::from_rotation_arc(DVec3::X, normal);
                // Centred where the motions' centre projects onto the plane.
                let middle = (extent.min_m + extent.max_m) * 0.5;
                let on_plane = middle - normal * (middle - point).dot(normal);
                let centre = on_plane - normal * (THICKNESS_M / 2.0);
                out.push(SceneBox {
                    name: "wall".into(),
                    role: SceneRole::Obstacle,
                    centre_m: centre.to_array(),
                    half_extents_m: [THICKNESS_M / 2.0, size / 2.0, size / 2.0],
                    rotation_xyzw: rotation.normalize().to_array(),
                });
            }
            Primitive::BalanceBeam(beam) => {
                let direction = DVec3::from_array(beam.direction).try_normalize().unwrap_or(DVec3::Z);
                // A stretch of the beam, or an endless one drawn as long as the scene.
                let (point, length) = match beam.extent_m {
                    Some([from, to]) => (DVec3::from_array(beam.point_m) + direction * ((from + to) / 2.0), to - from),
                    None => (DVec3::from_array(beam.point_m), (extent.max_m - extent.min_m).length() + 2.0 * PAD_M),
                };
                let half_width = if beam.half_width_m > 0.0 { beam.half_width_m } else { LINE_BEAM_HALF_WIDTH_M };
                let rotation = DQuat::from_rotation_arc(DVec3::Z, direction);
                // The beam's top surface on its centre line.
                let centre = point - DVec3::Y * (THICKNESS_M / 2.0);
                out.push(SceneBox {
                    name: "balance beam".into(),
                    role: SceneRole::Support,
                    centre_m: centre.to_array(),
                    half_extents_m: [half_width, THICKNESS_M / 2.0, length / 2.0],
                    rotation_xyzw: rotation.normalize().to_array(),
                });
            }
        }
    }
    for target in targets {
        let span = |axis: usize| match (target.coordinates_m[axis], axis) {
            (Some(v), _) => [v - TARGET_HALF_M, v + TARGET_HALF_M],
            (None, 1) => [0.0, FLOOR_MARK_M],
            (None, _) => [extent.min_m[axis] - PAD_M, extent.max_m[axis] + PAD_M],
        };
        let [x, y, z] = [span(0), span(1), span(2)];
        out.push(aligned(
            target.name.clone(),
            SceneRole::Target,
            DVec3::new(x[0], y[0], z[0]),
            DVec3::new(x[1], y[1], z[1]),
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::program::{BalanceBeam, Gap, OverheadBarrier};

    fn extent() -> SceneExtent {
        SceneExtent { min_m: DVec3::new(-0.3, 0.0, 0.0), max_m: DVec3::new(0.3, 1.7, 5.0) }
    }

    #[test]
    fn a_gap_is_two_walls_whose_inner_faces_are_the_gap() {
        let gap = Primitive::Gap(Gap { centre_x_m: 0.0, width_m: 0.4, margin_m: 0.1, z_range_m: Some([0.5, 3.5]) });
        let boxes = scene_boxes(&[gap], &[], extent());
        assert_eq!(boxes.len(), 2);
        let inner: Vec<f64> =
            boxes.iter().map(|b| b.centre_m[0] - b.half_extents_m[0] * b.centre_m[0].signum()).collect();
        assert!((inner[0] - 0.2).abs() < 1e-12 && (inner[1] + 0.2).abs() < 1e-12, "{inner:?}");
        assert!((boxes[0].centre_m[2] - 2.0).abs() < 1e-12 && (boxes[0].half_extents_m[2] - 1.5).abs() < 1e-12);
    }

    #[test]
    fn a_barrier_starts_at_its_underside_and_spans_the_motion() {
        let bar = Primitive::OverheadBarrier(OverheadBarrier {
            underside_height_m: 0.5,
            margin_m: 0.0,
            z_range_m: [2.0, 3.0],
            x_range_m: None,
        });
        let boxes = scene_boxes(&[bar], &[], extent());
        let b = &boxes[0];
        assert!((b.centre_m[1] - b.half_extents_m[1] - 0.5).abs() < 1e-12);
        assert!(
            b.centre_m[0] - b.half_extents_m[0] <= -1.3 + 1e-12 && b.centre_m[0] + b.half_extents_m[0] >= 1.3 - 1e-12
        );
        assert_eq!(b.role, SceneRole::Obstacle);
    }

    #[test]
    fn a_table_covers_its_x_range_and_a_beam_its_stretch() {
        let table = Primitive::OverheadBarrier(OverheadBarrier {
            underside_height_m: 1.0,
            margin_m: 0.0,
            z_range_m: [3.2, 3.8],
            x_range_m: Some([-1.0, 0.1]),
        });
        let beam = Primitive::BalanceBeam(BalanceBeam {
            point_m: [0.0, 0.0, 0.0],
            direction: [0.0, 0.0, 1.0],
            half_width_m: 0.1,
            horizontal: true,
            extent_m: Some([1.0, 3.0]),
        });
        let boxes = scene_boxes(&[table, beam], &[], extent());
        let t = &boxes[0];
        assert!((t.centre_m[0] - t.half_extents_m[0] + 1.0).abs() < 1e-12);
        assert!((t.centre_m[0] + t.half_extents_m[0] - 0.1).abs() < 1e-12);
        let b = &boxes[1];
        // Centred on its stretch (z from 1 to 3 m along +z) and as long as it.
        assert!((b.centre_m[2] - 2.0).abs() < 1e-12 && (b.half_extents_m[2] - 1.0).abs() < 1e-12, "{b:?}");
    }

    #[test]
    fn a_target_on_z_alone_is_a_finish_line_across_the_path() {
        let text = include_str!("../../../fixtures/tasks/rgdno_task1_narrow_gap.json");
        let program = TaskProgram::from_json_validated(text).unwrap();
        let targets = position_targets(&program);
        assert_eq!(targets.len(), 1, "{targets:?}");
        assert_eq!(targets[0].coordinates_m, [None, None, Some(5.0)]);
        assert!(targets[0].name.starts_with("c2: "), "{}", targets[0].name);
        let boxes = scene_boxes(&[], &targets, extent());
        let line = &boxes[0];
        assert_eq!(line.role, SceneRole::Target);
        assert!((line.centre_m[2] - 5.0).abs() < 1e-12 && (line.half_extents_m[2] - TARGET_HALF_M).abs() < 1e-12);
        // Across the motion (x from -0.3 to 0.3, padded) and on the floor.
        assert!(line.centre_m[0] - line.half_extents_m[0] <= -1.3 + 1e-12);
        assert!((line.centre_m[1] - FLOOR_MARK_M / 2.0).abs() < 1e-12);
        // A full 3-D target is a small cube at the point.
        let point = PositionTarget { name: "p".into(), coordinates_m: [Some(0.5), Some(1.2), Some(2.0)] };
        let cube = &scene_boxes(&[], &[point], extent())[0];
        for (k, expected) in [0.5, 1.2, 2.0].into_iter().enumerate() {
            assert!(
                (cube.centre_m[k] - expected).abs() < 1e-12 && (cube.half_extents_m[k] - TARGET_HALF_M).abs() < 1e-12
            );
        }
    }
}
