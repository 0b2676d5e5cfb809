//! BVH (Biovision hierarchy) text of an [`ArmatureTrack`]: our 22 joints
//! ([`RotationTrack::armature`](super::RotationTrack::armature)) or a user's rig
//! ([`super::retarget`]).
//!
//! # What the file holds
//! - **Hierarchy**: the armature's nodes under their names, node 0 the `ROOT`, children in node
//!   order. Each `OFFSET` is the node's rest offset from its parent in the parent's rest frame
//!   (every rest frame is the world's). A node with an end ([`ArmatureNode::end_site_m`]) carries
//!   it as an `End Site`. On our track the nodes are the 22 joints under their snake_case names,
//!   which are SMPL's (`pelvis`, `left_hip`, …), `pelvis` the root, and the five end joints
//!   (head, wrists, feet) end [`END_SITE_M`](super::armature::END_SITE_M) further along their
//!   own bone. BVH separates its tokens by whitespace, so a name that holds any (glTF allows
//!   "Left Arm") is written with `_` in its place (`Left_Arm`), and an empty name as
//!   `joint_<node>`; the GLB beside it keeps the names as they are.
//! - **Channels**: translated nodes ([`ArmatureNode::translated`]: the root, and on our track
//!   the six joints with animated offsets, hips, spine1, neck and collars) have `Xposition
//!   Yposition Zposition Zrotation Xrotation Yrotation`, every other node `Zrotation Xrotation
//!   Yrotation`. The root's positions are its world position; another node's are its offset from
//!   its parent in the parent's frame at that frame. As for the root, a node's position channels
//!   **replace** its `OFFSET` for the frame; Blender's importer (`io_anim_bvh`: pose location =
//!   channels − OFFSET, in the bone's rest frame) and ours ([`crate::import::bvh`]) read them
//!   so. The root's `OFFSET` being the rest position, readers that add it agree where it is zero.
//! - **Rotations**: Euler angles in degrees, intrinsic, applied as BVH readers apply channels,
//!   left to right: the local rotation is `L = Rz(z) · Rx(x) · Ry(y)` (column vectors; the same
//!   rotation read extrinsically is y about the world y, then x, then z). A node's world
//!   transform is `parent_world · Translate(OFFSET) · L`, with the frame's positions in place of
//!   `OFFSET` where the node has position channels (the root: `Translate(position) · L`). This
//!   is the armature's own forward kinematics, so a reader poses exactly its nodes.
//! - **Continuity**: each frame's angles are, of the two Euler triples of the rotation (`(z, x, y)`
//!   and `(z + 180, 180 − x, y + 180)`) shifted by whole turns, the one nearest the previous
//!   frame's, so no channel jumps by about 360° between frames and keyframe interpolation (as in
//!   Blender) never spins a joint the long way round. Angles may leave (−180°, 180°].
//! - **Motion**: `Frames` = the track's frames, `Frame Time` = 1 / fps seconds.
//! - **Axes** ([`BvhAxes`]): the project's by default: right-handed, **y up**, the character
//!   starts facing **+z**, **+x is its left**. Blender's BVH import with its defaults (forward
//!   −Z, up Y) puts our `(x, y, z)` at Blender's `(x, −z, y)`: upright, facing −Y, left at +X. A
//!   Z-up file (a user's rig that is one) holds our `(x, y, z)` as `(x, −z, y)`, rotations
//!   turned alike, as [`crate::import::bvh`] reads Z-up files.
//! - **Units**: metres (default), centimetres ([`BvhUnit`]) or a rig's own unit, for offsets and
//!   positions. Lengths are written to the micrometre (6 decimals in metres, 4 in centimetres),
//!   angles with 4 decimals; trailing zeros are dropped.

use std::fmt::Write as _;
use std::path::Path;

use glam::{DQuat, DVec3, EulerRot};

use super::armature::{ArmatureNode, ArmatureTrack};
use super::error::{write_atomically, ExportError};
use crate::import::bvh::UpAxis;

/// Decimals of angles, degrees (1e-4° moves a point 1 m away by 2 µm).
const ANGLE_DECIMALS: usize = 4;

/// Decimals of `Frame Time`, seconds.
const FRAME_TIME_DECIMALS: usize = 9;

/// The length unit of a written BVH file.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum BvhUnit {
    /// Metres (the project's unit).
    #[default]
    Metres,
    /// Centimetres (what Mixamo and MotionBuilder exports use).
    Centimetres,
}

impl BvhUnit {
    /// File units per metre.
    pub fn per_metre(self) -> f64 {
        match self {
            BvhUnit::Metres => 1.0,
            BvhUnit::Centimetres => 100.0,
        }
    }

    /// The unit's name as manifests write it (`tests/blender/check_bvh.py` reads it back):
    /// `metres` or `centimetres`.
    pub fn name(self) -> &'static str {
        match self {
            BvhUnit::Metres => "metres",
            BvhUnit::Centimetres => "centimetres",
        }
    }
}

/// How a BVH file measures: its length unit and up axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BvhAxes {
    /// File units per metre (positive).
    pub per_metre: f64,
    /// The file's up axis; a Z-up file holds our `(x, y, z)` as `(x, −z, y)`.
    pub up: UpAxis,
}

impl From<BvhUnit> for BvhAxes {
    fn from(unit: BvhUnit) -> Self {
        BvhAxes { per_metre: unit.per_metre(), up: UpAxis::Y }
    }
}

impl BvhAxes {
    /// Decimals of a length: micrometre precision (6 in metres, 4 in centimetres).
    fn decimals(self) -> usize {
        (6.0 - self.per_metre.log10()).round().clamp(0.0, 9.0) as usize
    }

    /// The file's axes turned from ours: `Rx(90°)` for a Z-up file, else the identity.
    fn turn(self) -> DQuat {
        match self.up {
            UpAxis::Y => DQuat::IDENTITY,
            UpAxis::Z => DQuat::from_rotation_x(std::f64::consts::FRAC_PI_2),
        }
    }

    /// A length vector in metres, our axes, as three numbers in the file's unit and axes.
    fn vector(self, v_m: DVec3) -> String {
        (self.turn() * v_m * self.per_metre).to_array().map(|c| number(c, self.decimals())).join(" ")
    }
}

/// The BVH text of `track` in `axes` (see the module doc for every convention), for a track whose
/// [`ArmatureTrack::inconsistency`] is `None` ([`write_bvh`] checks it).
pub fn bvh_text(track: &ArmatureTrack, axes: BvhAxes) -> String {
    let order = hierarchy_order(&track.nodes);
    let mut out = String::from("HIERARCHY\n");
    write_node(&mut out, &track.nodes, axes, 0, 0);
    let frame_time = number(1.0 / track.fps, FRAME_TIME_DECIMALS);
    let _ = write!(out, "MOTION\nFrames: {}\nFrame Time: {frame_time}\n", track.frames());
    // Where each translated node's translation sits in a frame's list.
    let mut slot = vec![None; track.nodes.len()];
    for (k, i) in (0..track.nodes.len()).filter(|i| track.nodes[*i].translated).enumerate() {
        slot[i] = Some(k);
    }
    let turn = axes.turn();
    let mut previous: Option<Vec<DVec3>> = None;
    for (local, translations) in track.local.iter().zip(&track.translations_m) {
        let angles: Vec<DVec3> = local
            .iter()
            .enumerate()
            .map(|(i, q)| euler_zxy_near(turn * *q * turn.conjugate(), previous.as_ref().map(|p| p[i])))
            .collect();
        let mut values: Vec<String> = Vec::with_capacity(6 * track.nodes.len());
        for &i in &order {
            if let Some(k) = slot[i] {
                values.push(axes.vector(translations[k]));
            }
            values.extend(angles[i].to_array().map(|a| number(a.to_degrees(), ANGLE_DECIMALS)));
        }
        previous = Some(angles);
        out.push_str(&values.join(" "));
        out.push('\n');
    }
    out
}

/// Writes [`bvh_text`] to `path` atomically. Fails on a track that is not consistent
/// ([`ArmatureTrack::inconsistency`]: no frames, rotations and translations of different
/// lengths) and when writing fails.
pub fn write_bvh(path: &Path, track: &ArmatureTrack, axes: BvhAxes) -> Result<(), ExportError> {
    if let Some(what) = track.inconsistency() {
        return Err(ExportError::Shape(format!("{}: {what}", path.display())));
    }
    write_atomically(path, bvh_text(track, axes).as_bytes())
}

/// The children of node `i` in index order.
fn children(nodes: &[ArmatureNode], i: usize) -> impl Iterator<Item = usize> + '_ {
    (0..nodes.len()).filter(move |c| nodes[*c].parent == Some(i))
}

/// Nodes depth first from the root, children in index order: the order of the hierarchy and
/// of the channels on a motion line.
fn hierarchy_order(nodes: &[ArmatureNode]) -> Vec<usize> {
    let mut order = Vec::with_capacity(nodes.len());
    let mut stack = vec![0];
    while let Some(i) = stack.pop() {
        order.push(i);
        let mut kids: Vec<usize> = children(nodes, i).collect();
        kids.reverse();
        stack.extend(kids);
    }
    order
}

/// Node `i`'s name as one BVH token: whitespace replaced by `_`, `joint_<i>` when empty.
fn bvh_name(name: &str, i: usize) -> String {
    let token: String = name.chars().map(|c| if c.is_whitespace() { '_' } else { c }).collect();
    if token.is_empty() {
        format!("joint_{i}")
    } else {
        token
    }
}

/// Appends the block of node `i` and its descendants, indented by `depth` levels.
fn write_node(out: &mut String, nodes: &[ArmatureNode], axes: BvhAxes, i: usize, depth: usize) {
    let pad = "  ".repeat(depth);
    let node = &nodes[i];
    let keyword = if node.parent.is_none() { "ROOT" } else { "JOINT" };
    let channels = if node.translated {
        "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation"
    } else {
        "CHANNELS 3 Zrotation Xrotation Yrotation"
    };
    let _ = writeln!(out, "{pad}{keyword} {}\n{pad}{{", bvh_name(&node.name, i));
    let _ = writeln!(out, "{pad}  OFFSET {}\n{pad}  {channels}", axes.vector(node.offset_m));
    if let Some(tip) = node.end_site_m {
        let _ = writeln!(out, "{pad}  End Site\n{pad}  {{\n{pad}    OFFSET {}\n{pad}  }}", axes.vector(tip));
    }
    for kid in children(nodes, i) {
        write_node(out, nodes, axes, kid, depth + 1);
    }
    let _ = writeln!(out, "{pad}}}");
}

/// `v` with `decimals` places, trailing zeros dropped and `-0` written `0`.
fn number(v: f64, decimals: usize) -> String {
    let s = format!("{v:.decimals$}");
    let trimmed = if s.contains('.') { s.trim_end_matches('0').trim_end_matches('.') } else { &s };
    if trimmed == "-0" { "0" } else { trimmed }.to_owned()
}

/// Angles `(z, x, y)`, rad, with `q = Rz(z) · Rx(x) · Ry(y)`: of the two Euler triples of `q`
/// and their whole-turn shifts, the one nearest `previous` (the principal triple without one).
fn euler_zxy_near(q: DQuat, previous: Option<DVec3>) -> DVec3 {
    use std::f64::consts::{PI, TAU};
    let (z, x, y) = q.to_euler(EulerRot::ZXY);
    let principal = DVec3::new(z, x, y);
    let Some(previous) = previous else { return principal };
    // Rz(z + π) · Rx(π − x) · Ry(y + π) = Rz(z) · Rx(x) · Ry(y).
    let twin = DVec3::new(z + PI, PI - x, y + PI);
    let near = |c: DVec3| c + ((previous - c) / TAU).round() * TAU;
    let (a, b) = (near(principal), near(twin));
    if a.distance_squared(previous) <= b.distance_squared(previous) {
        a
    } else {
        b
    }
}

#[cfg(test)]
mod tests {
    use std::path::PathBuf;

    use super::*;
    use crate::database::catalog::SourceFormat;
    use crate::export::armature::END_SITE_M;
    use crate::export::rotations::tests::shipped_clips;
    use crate::export::rotations::{RotationTrack, ANIMATED_OFFSETS};
    use crate::import::bvh::{Bvh, BvhClip, BvhOptions, LengthUnit, Rig};
    use crate::import::{deepmimic, resample};
    use crate::skeleton::Pose;
    use crate::skeleton::{Joint, NUM_JOINTS};

    fn mocap(name: &str) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/mocap").join(name)
    }

    /// Parses `text` with the project's importer (rig and unit detected).
    fn import(text: &str) -> BvhClip {
        let path = Path::new("export.bvh");
        let (bvh, warnings) = Bvh::parse(text, path).unwrap();
        assert!(warnings.is_empty(), "{warnings:?}");
        let (clip, warnings) = BvhClip::from_bvh("export", &bvh, &BvhOptions::default(), path).unwrap();
        assert!(warnings.is_empty(), "{warnings:?}");
        clip
    }

    /// Largest distance between the joints of two motions, m.
    fn max_distance(a: &[Pose], b: &[Pose]) -> f64 {
        assert_eq!(a.len(), b.len());
        a.iter().zip(b).flat_map(|(p, q)| p.iter().zip(q).map(|(u, v)| u.distance(*v))).fold(0.0, f64::max)
    }

    /// Every frame of an imported export, posed at its frame times with the file's own lengths.
    fn imported_poses(clip: &BvhClip) -> Vec<Pose> {
        let dt = clip.animation().frame_time_s();
        (0..clip.animation().frames()).map(|k| clip.mapped_pose_at(k as f64 * dt)).collect()
    }

    /// Solves `poses`, writes them in `unit` and reads them back: the largest distances of the
    /// read joints from the track's forward kinematics and from `poses`, and the solve's own
    /// largest distance from `poses` (its [`SolveFit`](super::super::SolveFit)), m.
    fn round_trip(poses: &[Pose], unit: BvhUnit) -> [f64; 3] {
        let track = RotationTrack::solve(poses, 20.0, 0).unwrap();
        let clip = import(&bvh_text(&track.armature(), unit.into()));
        let expected_unit = match unit {
            BvhUnit::Metres => LengthUnit::Metres,
            BvhUnit::Centimetres => LengthUnit::Centimetres,
        };
        assert_eq!((clip.rig(), clip.animation().unit()), (Rig::Smpl, expected_unit));
        assert!((clip.fps() - 20.0).abs() < 1e-9);
        let read = imported_poses(&clip);
        [max_distance(&read, &track.forward_kinematics()), max_distance(&read, poses), track.fit(poses).max_m]
    }

    #[test]
    fn every_shipped_clip_comes_back_as_it_went_in() {
        let mut worst: Vec<(SourceFormat, [f64; 3])> = Vec::new();
        for (name, family, poses) in shipped_clips() {
            let [to_track, to_input, fit] = round_trip(&poses, BvhUnit::Metres);
            println!(
                "{family:?}/{name}: {} frames, file vs track {to_track:.1e} m, vs input {to_input:.1e} m (solve {fit:.1e} m)",
                poses.len()
            );
            assert!(to_track < 1e-4, "{name}: {to_track} m from the track");
            assert!(to_input < 1e-4, "{name}: {to_input} m from the input");
            match worst.iter_mut().find(|(f, _)| *f == family) {
                Some((_, w)) => *w = std::array::from_fn(|k| w[k].max([to_track, to_input, fit][k])),
                None => worst.push((family, [to_track, to_input, fit])),
            }
        }
        for (family, [to_track, to_input, fit]) in worst {
            println!(
                "{family:?}: largest file vs track {to_track:.1e} m, vs input {to_input:.1e} m (solve {fit:.1e} m)"
            );
        }
    }

    /// A track on the rest skeleton of the canonical pose with one frame of `local` rotations
    /// (offsets at rest).
    fn one_frame(local: [DQuat; NUM_JOINTS], root: DVec3) -> RotationTrack {
        let mut track = RotationTrack::solve(&[crate::skeleton::rest_pose()], 20.0, 0).unwrap();
        (track.root_m, track.local) = (vec![root], vec![local]);
        track
    }

    /// Whether `joint` of our track has position channels: the root and the animated offsets.
    fn has_position_channels(joint: Joint) -> bool {
        joint.parent().is_none() || ANIMATED_OFFSETS.contains(&joint)
    }

    /// Our joints in the order of the hierarchy and of a motion line.
    fn joint_order() -> Vec<Joint> {
        let track = RotationTrack::solve(&[crate::skeleton::rest_pose()], 20.0, 0).unwrap();
        hierarchy_order(&track.armature().nodes).into_iter().map(|i| Joint::ALL[i]).collect()
    }

    /// The values of `joint` on a motion line: 6 with position channels, else 3.
    fn joint_values(values: &[f64], joint: Joint) -> &[f64] {
        let width = |j: Joint| if has_position_channels(j) { 6 } else { 3 };
        let order = joint_order();
        let start: usize = order.iter().take_while(|j| **j != joint).map(|j| width(*j)).sum();
        &values[start..start + width(joint)]
    }

    /// The values of the motion line of frame `k`.
    fn motion_line(text: &str, k: usize) -> Vec<f64> {
        let start = text.lines().position(|l| l.starts_with("Frame Time")).unwrap() + 1;
        text.lines().nth(start + k).unwrap().split(' ').map(|v| v.parse().unwrap()).collect()
    }

    /// A user's joint names with spaces (legal in glTF) or none at all are written as single
    /// tokens, so the file parses, here and in any BVH reader.
    #[test]
    fn names_with_whitespace_are_written_as_one_token() {
        let mut armature = one_frame([DQuat::IDENTITY; NUM_JOINTS], DVec3::Y).armature();
        armature.nodes[0].name = "Root Bone".into();
        armature.nodes[1].name = "left\tthigh ".into();
        armature.nodes[2].name = String::new();
        let text = bvh_text(&armature, BvhUnit::Metres.into());
        assert!(text.contains("ROOT Root_Bone\n") && text.contains("JOINT left_thigh_\n"), "{text}");
        assert!(text.contains("JOINT joint_2\n"), "{text}");
        let (bvh, _) = crate::import::bvh::Bvh::parse(&text, Path::new("names.bvh")).unwrap();
        for name in ["Root_Bone", "left_thigh_", "joint_2", "spine1"] {
            assert!(bvh.joint_index(name).is_some(), "{name}");
        }
    }

    #[test]
    fn a_known_rotation_is_written_and_read_back() {
        let mut local = [DQuat::IDENTITY; NUM_JOINTS];
        local[0] = DQuat::from_rotation_y(90f64.to_radians());
        local[Joint::LeftElbow.index()] = DQuat::from_rotation_x(-60f64.to_radians());
        local[Joint::RightHip.index()] = DQuat::from_euler(EulerRot::ZXY, 0.3, -0.4, 0.5);
        let track = one_frame(local, DVec3::new(1.0, 0.9, -2.0));
        let text = bvh_text(&track.armature(), BvhUnit::Metres.into());
        let lines: Vec<&str> = text.lines().map(str::trim).collect();
        assert_eq!(
            lines[..5],
            [
                "HIERARCHY",
                "ROOT pelvis",
                "{",
                "OFFSET 0 0 0",
                "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation"
            ]
        );
        assert_eq!(lines.iter().filter(|l| l.starts_with("JOINT ")).count(), 21);
        assert_eq!(lines.iter().filter(|l| **l == "End Site").count(), 5);
        assert!(text.contains("Frames: 1\nFrame Time: 0.05\n"), "{text}");
        // Depth first: pelvis, left leg (4 joints), right leg, then the spine.
        let order = joint_order();
        assert_eq!(
            order[..6],
            [Joint::Pelvis, Joint::LeftHip, Joint::LeftKnee, Joint::LeftAnkle, Joint::LeftFoot, Joint::RightHip]
        );
        let values = motion_line(&text, 0);
        assert_eq!(values.len(), 7 * 6 + 15 * 3);
        assert_eq!(joint_values(&values, Joint::Pelvis), [1.0, 0.9, -2.0, 0.0, 0.0, 90.0]);
        assert_eq!(joint_values(&values, Joint::LeftElbow), [0.0, -60.0, 0.0]);
        let hip: Vec<f64> = [0.3f64, -0.4, 0.5].map(|a| (a.to_degrees() * 1e4).round() / 1e4).to_vec();
        assert_eq!(joint_values(&values, Joint::RightHip)[3..], hip);
        // The six joints with animated offsets have position channels, here their rest offsets.
        let channel_lines: Vec<&str> = lines.iter().copied().filter(|l| l.starts_with("CHANNELS")).collect();
        assert_eq!(channel_lines.iter().filter(|l| l.starts_with("CHANNELS 6 Xposition")).count(), 7);
        for j in ANIMATED_OFFSETS {
            let rest = track.skeleton.offsets_m[j.index()].to_array().map(|v| (v * 1e6).round() / 1e6);
            assert_eq!(joint_values(&values, j)[..3], rest, "{}", j.name());
        }
        // The importer poses the track's own joints.
        let read = imported_poses(&import(&text));
        assert!(max_distance(&read, &track.forward_kinematics()) < 1e-5);
        // An End Site continues its bone by 0.1 m: the head's is straight up at rest.
        let head = text.find("JOINT head").unwrap();
        let tip = &text[head..][text[head..].find("End Site").unwrap()..];
        let offset = tip.lines().nth(2).unwrap().trim();
        let v: Vec<f64> = offset.trim_start_matches("OFFSET ").split(' ').map(|v| v.parse().unwrap()).collect();
        let rest_neck_head = track.skeleton.offsets_m[Joint::Head.index()].normalize() * END_SITE_M;
        assert!((DVec3::from_slice(&v) - rest_neck_head).length() < 1e-6, "{offset}");
    }

    #[test]
    fn an_animated_offset_replaces_the_joints_offset_for_its_frame() {
        let mut local = [DQuat::IDENTITY; NUM_JOINTS];
        local[0] = DQuat::from_rotation_y(90f64.to_radians());
        local[Joint::Spine3.index()] = DQuat::from_rotation_x(0.4);
        let mut track = one_frame(local, DVec3::new(0.5, 0.9, 0.0));
        let collar = ANIMATED_OFFSETS.iter().position(|j| *j == Joint::LeftCollar).unwrap();
        let rest = track.skeleton.offsets_m[Joint::LeftCollar.index()];
        track.animated_offsets_m[0][collar] = DQuat::from_rotation_z(0.5) * rest;
        let moved = track.forward_kinematics()[0];
        let text = bvh_text(&track.armature(), BvhUnit::Centimetres.into());
        // The OFFSET line keeps the rest offset; the frame's position channels hold the moved one.
        let block = &text[text.find("JOINT left_collar").unwrap()..];
        assert_eq!(
            block.lines().nth(2).unwrap().trim(),
            format!("OFFSET {}", BvhAxes::from(BvhUnit::Centimetres).vector(rest))
        );
        let written = joint_values(&motion_line(&text, 0), Joint::LeftCollar)[..3].to_vec();
        let expected = (track.offset_m(0, Joint::LeftCollar) * 100.0).to_array().map(|v| (v * 1e4).round() / 1e4);
        assert_eq!(written, expected);
        // Read back, the collar and everything below it sit where forward kinematics put them,
        // not where the rest offset would.
        let read = imported_poses(&import(&text));
        assert!(max_distance(&read, &[moved]) < 1e-5, "{}", max_distance(&read, &[moved]));
        let wrist = Joint::LeftWrist.index();
        track.animated_offsets_m[0][collar] = rest;
        assert!(track.forward_kinematics()[0][wrist].distance(read[0][wrist]) > 0.01);
    }

    #[test]
    fn angles_are_continuous_through_full_turns_and_gimbal_lock() {
        // The root spins twice about y while a knee swings past 90° about x, 7° a frame.
        let frames: Vec<[DQuat; NUM_JOINTS]> = (0..26)
            .map(|k| {
                let mut local = [DQuat::IDENTITY; NUM_JOINTS];
                local[0] = DQuat::from_rotation_y((29.0 * k as f64).to_radians());
                local[Joint::LeftKnee.index()] = DQuat::from_rotation_x((7.0 * k as f64).to_radians());
                local
            })
            .collect();
        let mut track = one_frame(frames[0], DVec3::ZERO);
        track.root_m = vec![DVec3::ZERO; frames.len()];
        track.local = frames;
        track.animated_offsets_m = vec![track.animated_offsets_m[0]; track.frames()];
        let text = bvh_text(&track.armature(), BvhUnit::Metres.into());
        for k in 1..track.frames() {
            let (a, b) = (motion_line(&text, k - 1), motion_line(&text, k));
            assert!((b[5] - a[5] - 29.0).abs() < 1e-3, "root y, frame {k}: {} → {}", a[5], b[5]);
            let (a, b) = (joint_values(&a, Joint::LeftKnee), joint_values(&b, Joint::LeftKnee));
            assert!((b[1] - a[1] - 7.0).abs() < 1e-3, "knee x, frame {k}: {a:?} → {b:?}");
            assert!(b[0].abs() < 1e-3 && b[2].abs() < 1e-3, "knee z, y at frame {k}: {b:?}");
        }
        assert!((motion_line(&text, 25)[5] - 725.0).abs() < 1e-3);
        let read = imported_poses(&import(&text));
        assert!(max_distance(&read, &track.forward_kinematics()) < 1e-5);
    }

    #[test]
    fn centimetres_give_the_same_joints() {
        let path = mocap("deepmimic/humanoid3d_cartwheel.txt");
        let (clip, _) = deepmimic::DeepMimicClip::read(&path).unwrap();
        let poses = resample(&clip, 1.0, None);
        let track = RotationTrack::solve(&poses, 20.0, 0).unwrap();
        let (metres, centimetres) = (
            bvh_text(&track.armature(), BvhUnit::Metres.into()),
            bvh_text(&track.armature(), BvhUnit::Centimetres.into()),
        );
        let hip = track.skeleton.offsets_m[Joint::LeftHip.index()];
        assert!(metres.contains(&format!("OFFSET {}", BvhAxes::from(BvhUnit::Metres).vector(hip))));
        assert!(centimetres.contains(&format!("OFFSET {}", BvhAxes::from(BvhUnit::Centimetres).vector(hip))));
        assert_eq!(
            motion_line(&centimetres, 3)[..3],
            (track.root_m[3] * 100.0).to_array().map(|v| (v * 1e4).round() / 1e4)
        );
        let (m, cm) = (imported_poses(&import(&metres)), imported_poses(&import(&centimetres)));
        assert!(max_distance(&m, &cm) < 1e-5, "{}", max_distance(&m, &cm));
        assert_eq!([BvhUnit::Metres.name(), BvhUnit::Centimetres.name()], ["metres", "centimetres"]);
        let [to_track, to_input, fit] = round_trip(&poses, BvhUnit::Centimetres);
        assert!(to_track < 1e-4 && to_input < 1e-4, "{to_track} {to_input} {fit}");
    }

    #[test]
    fn numbers_are_compact() {
        assert_eq!(number(0.05, 9), "0.05");
        assert_eq!(number(-0.0000001, 6), "0");
        assert_eq!(number(12.0, 4), "12");
        assert_eq!(number(-1.23456789, 4), "-1.2346");
        assert_eq!(number(1.0 / 30.0, 9), "0.033333333");
    }

    #[test]
    fn write_bvh_refuses_empty_or_ragged_tracks_and_writes_the_text() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a").join("motion.bvh");
        let track = one_frame([DQuat::IDENTITY; NUM_JOINTS], DVec3::Y);
        write_bvh(&path, &track.armature(), BvhUnit::Centimetres.into()).unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), bvh_text(&track.armature(), BvhUnit::Centimetres.into()));
        let mut ragged = track.armature();
        ragged.translations_m.push(vec![DVec3::ZERO; 7]);
        let err = write_bvh(&path, &ragged, BvhUnit::Metres.into()).unwrap_err().to_string();
        assert!(err.contains("motion.bvh") && err.contains("1 frames of rotations for 22 nodes and 2 frames"), "{err}");
        let mut ragged = track.armature();
        ragged.translations_m[0].pop();
        let err = write_bvh(&path, &ragged, BvhUnit::Metres.into()).unwrap_err().to_string();
        assert!(err.contains("translations for 7 nodes do not agree"), "{err}");
        let empty = ArmatureTrack { local: vec![], translations_m: vec![], ..track.armature() };
        assert!(write_bvh(&dir.path().join("b.bvh"), &empty, BvhUnit::Metres.into()).is_err());
        assert!(!dir.path().join("b.bvh").exists());
    }
}
