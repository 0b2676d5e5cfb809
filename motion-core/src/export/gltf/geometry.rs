//! Triangle meshes of the GLB: the capsule body round a skeleton and the unit cube that scene
//! boxes scale. Positions in metres, project axes.

use std::f64::consts::{FRAC_PI_2, TAU};

use glam::DVec3;

use crate::export::armature::ArmatureNode;
use crate::skeleton::{Joint, NUM_JOINTS};

/// Vertices round a capsule's axis.
const SEGMENTS: usize = 10;
/// Latitude rings of each capsule cap, its equator included.
const CAP_RINGS: usize = 3;
/// Below this bone length (m) a capsule is drawn as a sphere.
const SPHERE_M: f64 = 1e-6;
/// Radius of the thin capsule round a bone that carries none of our joints (a finger, a twist
/// bone), m.
const EXTRA_BONE_M: f64 = 0.012;

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

/// The body round an armature in the bind pose `bind` (each node's position, m), with
/// `joint_nodes` the node of each of our joints, and per vertex its skin joints (`JOINTS_0`: the
/// bound node's index, then three unused zeros; skin joint `i` is node `i`).
///
/// Between the nodes of a joint and its parent joint runs a capsule of that joint's radius, bound
/// to the parent joint's node, and the head and hands get spheres bound to their own nodes. Every
/// other bone (from a node no joint names to its parent) below the pelvis node, such as a finger
/// or a twist bone, gets a thin capsule ([`EXTRA_BONE_M`]) bound to its parent; nodes
/// outside the pelvis's subtree (a `root` on the floor, IK targets under it) get none.
pub(super) fn body(bind: &[DVec3], nodes: &[ArmatureNode], joint_nodes: &[usize; NUM_JOINTS]) -> (Geometry, Vec<u16>) {
    let mut pieces: Vec<(DVec3, DVec3, f64, usize)> = Vec::new();
    for joint in Joint::ALL {
        let node = joint_nodes[joint.index()];
        if let Some(parent) = joint.parent() {
            let from = joint_nodes[parent.index()];
            pieces.push((bind[from], bind[node], bone_radius_m(joint), from));
        }
        pieces.extend(end_sphere_m(joint).map(|radius| (bind[node], bind[node], radius, node)));
    }
    let pelvis = joint_nodes[Joint::Pelvis.index()];
    let mut in_body = vec![false; nodes.len()];
    for (n, node) in nodes.iter().enumerate() {
        in_body[n] = n == pelvis || node.parent.is_some_and(|p| in_body[p]);
        let extra =
            node.parent.filter(|p| in_body[n] && !joint_nodes.contains(&n) && bind[*p].distance(bind[n]) > SPHERE_M);
        pieces.extend(extra.map(|p| (bind[p], bind[n], EXTRA_BONE_M, p)));
    }
    let mut geometry = Geometry::default();
    let mut bound_to = Vec::new();
    for (from, to, radius, bound) in pieces {
        let before = geometry.positions.len();
        geometry.capsule(from, to, radius);
        // Skin joints fit in a u16: the writer refuses armatures of more nodes.
        bound_to.extend((before..geometry.positions.len()).flat_map(|_| [bound as u16, 0, 0, 0]));
    }
    (geometry, bound_to)
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::*;
    use crate::export::armature::our_joint_nodes;
    use crate::export::retarget::TargetRig;
    use crate::skeleton::rest_pose;

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
        let nodes: Vec<ArmatureNode> = Joint::ALL
            .map(|j| ArmatureNode {
                name: j.name().into(),
                parent: j.parent().map(Joint::index),
                offset_m: DVec3::ZERO,
                end_site_m: None,
                translated: false,
            })
            .into();
        let (body, bound_to) = body(&rest, &nodes, &our_joint_nodes());
        assert_outward(&body);
        assert_eq!(bound_to.len(), 4 * body.positions.len());
        assert!(bound_to.chunks(4).all(|j| usize::from(j[0]) < NUM_JOINTS && j[1..] == [0, 0, 0]));
        // The head's sphere moves with the head; the forearm with the elbow.
        let head = rest[Joint::Head.index()];
        let bound = |joint: Joint, p: DVec3| {
            bound_to[4 * body.positions.iter().position(|q| *q == p).unwrap()] == joint.index() as u16
        };
        assert!(bound(Joint::Head, head + DVec3::Y * 0.1));
        let wrist = rest[Joint::LeftWrist.index()];
        let elbow = rest[Joint::LeftElbow.index()];
        let down = (wrist - elbow).normalize();
        assert!(bound(Joint::LeftElbow, elbow - down * bone_radius_m(Joint::LeftWrist)));
    }

    #[test]
    fn a_rigs_extra_bones_below_the_pelvis_get_thin_capsules() {
        let rig =
            TargetRig::read(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/rigs/unreal.bvh"), None).unwrap();
        let rest = rig.rest_positions();
        let (body, bound_to) = body(&rest, &rig.nodes, &rig.map);
        assert_outward(&body);
        let node = |name: &str| rig.nodes.iter().position(|n| n.name == name).unwrap() as u16;
        let bound: Vec<u16> = bound_to.chunks(4).map(|j| j[0]).collect();
        assert!(bound.iter().all(|&n| usize::from(n) < rig.nodes.len()));
        // The fingers are drawn, each phalanx moving with the one before; the root on the floor
        // and the IK bones under it are not.
        for (finger, parent) in [("index_02_l", "index_01_l"), ("index_01_r", "hand_r")] {
            let tip = rest[usize::from(node(finger))];
            let mut near = body.positions.iter().zip(&bound).filter(|(p, _)| p.distance(tip) < EXTRA_BONE_M + 1e-9);
            assert!(near.any(|(_, b)| *b == node(parent)), "{finger}");
        }
        for unbound in ["root", "ik_foot_root", "ik_foot_l", "ik_foot_r"] {
            assert!(!bound.contains(&node(unbound)), "{unbound}");
        }
    }
}
