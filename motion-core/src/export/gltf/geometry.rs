//! Triangle meshes of the GLB: the capsule body round a skeleton and the unit cube that scene
//! boxes scale. Positions in metres, project axes.

use std::f64::consts::{FRAC_PI_2, TAU};

use glam::DVec3;

use crate::skeleton::{Joint, Pose};

/// Vertices round a capsule's axis.
const SEGMENTS: usize = 10;
/// Latitude rings of each capsule cap, its equator included.
const CAP_RINGS: usize = 3;
/// Below this bone length (m) a capsule is drawn as a sphere.
const SPHERE_M: f64 = 1e-6;

/// Radius of the capsule round the bone from `joint`'s parent to `joint`, m.
fn bone_radius_m(joint: Joint) -> f64 {
    match joint {
        // The root: no bone ends there.
        Joint::Pelvis => 0.0,
        Joint::Spine1 | Joint::Spine2 | Joint::Spine3 => 0.1,
        Joint::LeftHip | Joint::RightHip => 0.08,
        Joint::LeftKnee | Joint::RightKnee => 0.07,
        Joint::LeftAnkle | Joint::RightAnkle => 0.055,
        Joint::LeftFoot | Joint::RightFoot => 0.04,
        Joint::Neck | Joint::Head => 0.05,
        Joint::LeftCollar | Joint::RightCollar => 0.06,
        Joint::LeftShoulder | Joint::RightShoulder => 0.055,
        Joint::LeftElbow | Joint::RightElbow => 0.05,
        Joint::LeftWrist | Joint::RightWrist => 0.04,
    }
}

/// Radius of the sphere drawn round an end joint, m: the head and the hands.
fn end_sphere_m(joint: Joint) -> Option<f64> {
    match joint {
        Joint::Head => Some(0.1),
        Joint::LeftWrist | Joint::RightWrist => Some(0.045),
        _ => None,
    }
}

/// Triangles with a normal per vertex, m.
#[derive(Debug, Default)]
pub(super) struct Geometry {
    pub(super) positions: Vec<DVec3>,
    /// Unit outward normals, one per position.
    pub(super) normals: Vec<DVec3>,
    /// Vertex indices, counter-clockwise seen from outside.
    pub(super) triangles: Vec<[u32; 3]>,
}

impl Geometry {
    /// Adds the surface of the points within `radius_m` of the segment `a`–`b`: two caps of
    /// [`CAP_RINGS`] rings and a pole each, [`SEGMENTS`] vertices per ring; a sphere where `a = b`.
    pub(super) fn capsule(&mut self, a: DVec3, b: DVec3, radius_m: f64) {
        let axis = (b - a).try_normalize().unwrap_or(DVec3::Y);
        let across = axis.any_orthonormal_vector();
        let third = axis.cross(across);
        let step = FRAC_PI_2 / CAP_RINGS as f64;
        let mut rings: Vec<(DVec3, f64)> = (1..CAP_RINGS).map(|i| (a, step * i as f64 - FRAC_PI_2)).collect();
        rings.push((a, 0.0));
        if a.distance(b) > SPHERE_M {
            rings.push((b, 0.0));
        }
        rings.extend((1..CAP_RINGS).map(|i| (b, step * i as f64)));

        let base = self.positions.len() as u32;
        let mut vertex = |centre: DVec3, direction: DVec3| {
            self.positions.push(centre + direction * radius_m);
            self.normals.push(direction);
        };
        vertex(a, -axis);
        for &(centre, latitude) in &rings {
            for k in 0..SEGMENTS {
                let angle = TAU * k as f64 / SEGMENTS as f64;
                let around = across * angle.cos() + third * angle.sin();
                vertex(centre, axis * latitude.sin() + around * latitude.cos());
            }
        }
        vertex(b, axis);
        let ring = |r: usize, k: usize| base + 1 + (r * SEGMENTS + k % SEGMENTS) as u32;
        let last = rings.len() - 1;
        let top = ring(last, 0) + SEGMENTS as u32;
        // The angle grows counter-clockwise seen from +axis: the fans and strips wind with it.
        for k in 0..SEGMENTS {
            self.triangles.push([base, ring(0, k + 1), ring(0, k)]);
            for r in 0..last {
                self.triangles.push([ring(r, k), ring(r, k + 1), ring(r + 1, k + 1)]);
                self.triangles.push([ring(r, k), ring(r + 1, k + 1), ring(r + 1, k)]);
            }
            self.triangles.push([ring(last, k), ring(last, k + 1), top]);
        }
    }

    /// Adds the cube of side 1 centred at the origin, four vertices per face.
    pub(super) fn unit_cube(&mut self) {
        for (axis, first) in [(DVec3::X, DVec3::Y), (DVec3::Y, DVec3::Z), (DVec3::Z, DVec3::X)] {
            for normal in [axis, -axis] {
                let second = normal.cross(first);
                let base = self.positions.len() as u32;
                for (s, t) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
                    self.positions.push((normal + first * s + second * t) * 0.5);
                    self.normals.push(normal);
                }
                self.triangles.push([base, base + 1, base + 2]);
                self.triangles.push([base, base + 2, base + 3]);
            }
        }
    }
}

/// The body in the bind pose `bind` (joint positions, m) and, per vertex, its skin joints
/// (`JOINTS_0`: the bound joint's index, then three unused zeros).
pub(super) fn body(bind: &Pose) -> (Geometry, Vec<u8>) {
    let mut geometry = Geometry::default();
    let mut bound_to = Vec::new();
    for joint in Joint::ALL {
        let at = bind[joint.index()];
        let mut pieces = Vec::new();
        if let Some(parent) = joint.parent() {
            pieces.push((bind[parent.index()], bone_radius_m(joint), parent));
        }
        pieces.extend(end_sphere_m(joint).map(|radius| (at, radius, joint)));
        for (from, radius, bound) in pieces {
            let before = geometry.positions.len();
            geometry.capsule(from, at, radius);
            for _ in before..geometry.positions.len() {
                bound_to.extend([bound.index() as u8, 0, 0, 0]);
            }
        }
    }
    (geometry, bound_to)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::skeleton::{rest_pose, NUM_JOINTS};

    /// Every triangle's face normal points the way of its vertices' normals.
    fn assert_outward(geometry: &Geometry) {
        assert_eq!(geometry.positions.len(), geometry.normals.len());
        for t in &geometry.triangles {
            let [a, b, c] = t.map(|i| geometry.positions[i as usize]);
            let face = (b - a).cross(c - a);
            let normal: DVec3 = t.iter().map(|&i| geometry.normals[i as usize]).sum();
            assert!(face.length() > 1e-12 && face.dot(normal) > 0.0, "{t:?}");
        }
    }

    #[test]
    fn capsules_and_cubes_face_outwards() {
        let (a, b) = (DVec3::new(0.1, 1.0, 0.0), DVec3::new(0.3, 0.6, 0.2));
        let mut capsule = Geometry::default();
        capsule.capsule(a, b, 0.05);
        assert_outward(&capsule);
        for p in &capsule.positions {
            let s = ((*p - a).dot(b - a) / (b - a).length_squared()).clamp(0.0, 1.0);
            assert!((p.distance(a + (b - a) * s) - 0.05).abs() < 1e-12);
        }
        let mut sphere = Geometry::default();
        sphere.capsule(a, a, 0.1);
        assert_outward(&sphere);
        let mut cube = Geometry::default();
        cube.unit_cube();
        assert_outward(&cube);
        assert!(cube.positions.iter().all(|p| p.abs() == DVec3::splat(0.5)));
    }

    #[test]
    fn every_body_vertex_is_bound_to_one_joint() {
        let rest = rest_pose();
        let (body, bound_to) = body(&rest);
        assert_outward(&body);
        assert_eq!(bound_to.len(), 4 * body.positions.len());
        assert!(bound_to.chunks(4).all(|j| (j[0] as usize) < NUM_JOINTS && j[1..] == [0, 0, 0]));
        // The head's sphere moves with the head; the forearm with the elbow.
        let head = rest[Joint::Head.index()];
        let bound = |joint: Joint, p: DVec3| {
            bound_to[4 * body.positions.iter().position(|q| *q == p).unwrap()] == joint.index() as u8
        };
        assert!(bound(Joint::Head, head + DVec3::Y * 0.1));
        let wrist = rest[Joint::LeftWrist.index()];
        let elbow = rest[Joint::LeftElbow.index()];
        let down = (wrist - elbow).normalize();
        assert!(bound(Joint::LeftElbow, elbow - down * bone_radius_m(Joint::LeftWrist)));
    }
}
