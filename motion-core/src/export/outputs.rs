//! Every output file of a set of motions at once: per sample a BVH and a GLB, one viewer page
//! and a manifest (`export.json`) with the rotation solve's fit and a few probe positions that
//! other tools' imports are checked against.
//!
//! Layout under the output folder:
//! - `sample_<i>/motion.bvh`, `sample_<i>/motion.glb` (i from 0), and with a rig
//!   `sample_<i>/<rig>.bvh` and `sample_<i>/<rig>.glb`;
//! - `viewer.html`;
//! - `export.json` ([`ExportManifest`]).
//!
//! Every motion is validated (frames, finite positions, frame rate) and solved before the first
//! file is written, so bad input writes nothing; each file is written whole
//! ([`super::write_atomically`]).

use std::borrow::Cow;
use std::path::Path;

use serde::Serialize;

use super::armature::our_joint_nodes;
use super::bvh::{write_bvh, BvhUnit};
use super::error::{write_atomically, ExportError};
use super::gltf::{glb_bytes, write_glb};
use super::retarget::{judge_on_rig, retarget, RetargetReport, Retargeted, RigConstraint, RigJudge, TargetRig};
use super::rotations::{RotationTrack, SolveFit};
use super::scene::{scene_boxes, PositionTarget, SceneBox, SceneExtent};
use super::viewer::{write_viewer, ViewerInput, ViewerRig, ViewerSample};
use crate::files::FileError;
use crate::import::bvh::UpAxis;
use crate::program::{Carry, Primitive};
use crate::skeleton::{Joint, Pose, NUM_JOINTS};

/// The joints whose forward-kinematics positions the manifest lists: the root, ends of the
/// limbs and head, and children of both branching joints (their offsets are animated).
const PROBE_JOINTS: [Joint; 8] = [
    Joint::Pelvis,
    Joint::Head,
    Joint::LeftWrist,
    Joint::RightFoot,
    Joint::LeftKnee,
    Joint::Neck,
    Joint::RightCollar,
    Joint::LeftHip,
];

/// What to export.
#[derive(Debug, Clone)]
pub struct ExportInput<'a> {
    /// Title of the viewer page (the prompt or task).
    pub title: String,
    /// Frames per second of every motion.
    pub fps: f64,
    /// Each sample: label and joint positions (m, project axes).
    pub samples: Vec<(String, &'a [Pose])>,
    /// The task's scene primitives (drawn in the GLBs and the viewer).
    pub scene: Vec<Primitive>,
    /// The task's position targets (drawn likewise).
    pub targets: Vec<PositionTarget>,
    /// Objects the task carries between the hands (drawn in the viewer as balls).
    pub carried: Vec<Carry>,
    /// The task's `report.json`, shown by the viewer; `None` for motions without a task.
    pub report: Option<serde_json::Value>,
    /// Length unit of the BVH files.
    pub bvh_unit: BvhUnit,
    /// Frame rate of the BVH and GLB files, frames per second ([`RotationTrack::resampled`]);
    /// `None`: the motions' own.
    pub file_fps: Option<u32>,
    /// Whether the files leave the root's horizontal motion out ([`RotationTrack::in_place`]).
    pub in_place: bool,
    /// A rig of the user's to write each motion onto as well ([`retarget`]), in its own unit and
    /// up axis.
    pub rig: Option<&'a TargetRig>,
    /// The task's constraints, judged again on the rig's motion when a rig is given.
    pub judge: Option<RigJudge<'a>>,
}

/// One joint's position at one frame, by forward kinematics of the solved track.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Probe {
    /// Joint name.
    pub joint: &'static str,
    /// Frame of the files, from 0.
    pub frame: usize,
    /// Position, m, project axes.
    pub position_m: [f64; 3],
}

/// One sample's files and fit.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ExportedSample {
    /// Label.
    pub label: String,
    /// Frames of its files.
    pub frames: usize,
    /// BVH file, relative to the output folder.
    pub bvh: String,
    /// GLB file, relative to the output folder.
    pub glb: String,
    /// Mean distance between the input joints and forward kinematics of the rotations (at the
    /// motion's own frames), m.
    pub fit_mean_m: f64,
    /// Largest such distance, m.
    pub fit_max_m: f64,
    /// Positions to check imports against.
    pub probes: Vec<Probe>,
    /// The motion on the user's rig, when one was given.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rig: Option<RigFile>,
}

/// One sample's motion on the user's rig.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RigFile {
    /// BVH file on the rig, relative to the output folder.
    pub bvh: String,
    /// GLB file on the rig, relative to the output folder: for a BVH rig, its nodes with a skinned
    /// capsule body and the scene (metres, y up, whatever the rig's unit and up axis); for a glTF
    /// character, the character's own file with the motion as its animation (in the file's unit).
    pub glb: String,
    /// The rig file's units per metre (its lengths are written in them).
    pub units_per_metre: f64,
    /// Whether the file is Z-up (as the rig is).
    pub z_up: bool,
    /// What carried over.
    pub report: RetargetReport,
    /// The task's constraints judged on the rig's motion at the motion's frame rate, moving
    /// (empty without a task, or when a constraint compares with an unoptimised motion that is
    /// not known).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub constraints: Vec<RigConstraint>,
    /// The rig's nodes of some of our joints at a few frames, m, our axes (y up), to check
    /// imports against.
    pub probes: Vec<RigProbe>,
    /// The rig's nodes of our 22 joints at the motion's own frames, moving, m, our axes: what the
    /// pictures draw (not in `export.json`).
    #[serde(skip)]
    pub motion_poses: Vec<Pose>,
}

/// One rig node's position at one frame.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RigProbe {
    /// The rig's node name.
    pub node: String,
    /// Our joint it carries.
    pub joint: &'static str,
    /// Frame of the file, from 0.
    pub frame: usize,
    /// Position, m, our axes.
    pub position_m: [f64; 3],
}

/// `export.json`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ExportManifest {
    /// The axes and units of every file.
    pub axes: &'static str,
    /// Frames per second of the files.
    pub fps: f64,
    /// Frames per second of the motions (the files' rate unless resampled).
    pub motion_fps: f64,
    /// Whether the files leave the root's horizontal motion out (the pelvis stays over its first
    /// position on the floor; the probes are of the files).
    pub in_place: bool,
    /// BVH length unit.
    pub bvh_unit: &'static str,
    /// The viewer page, relative to the output folder.
    pub viewer: &'static str,
    /// Every sample.
    pub samples: Vec<ExportedSample>,
}

/// Writes every output of `input` under `out` and returns the manifest (also written).
pub fn write_outputs(out: &Path, input: &ExportInput<'_>) -> Result<ExportManifest, ExportError> {
    if input.samples.is_empty() {
        return Err(ExportError::Shape("no motions to export".into()));
    }
    let tracks = input
        .samples
        .iter()
        .enumerate()
        .map(|(i, (_, poses))| RotationTrack::solve(poses, input.fps, i))
        .collect::<Result<Vec<_>, _>>()?;
    let extent = SceneExtent::of(input.samples.iter().map(|(_, poses)| *poses));
    let boxes = scene_boxes(&input.scene, &input.targets, extent);
    let mut viewer = ViewerInput {
        title: input.title.clone(),
        fps: input.fps,
        samples: input
            .samples
            .iter()
            .map(|(label, poses)| ViewerSample { label: label.clone(), poses: poses.to_vec() })
            .collect(),
        scene: boxes.clone(),
        carried: input.carried.clone(),
        report: input.report.clone(),
        rigs: Vec::new(),
    };
    let mut samples = Vec::with_capacity(tracks.len());
    let files = tracks.iter().map(|track| file_track(track, input)).collect::<Result<Vec<_>, _>>()?;
    let retargeted = match input.rig {
        Some(rig) => files.iter().map(|file| retarget(file, rig).map(Some)).collect::<Result<Vec<_>, _>>()?,
        None => vec![None; files.len()],
    };
    for (i, (((track, file), (label, poses)), on_rig)) in
        tracks.iter().zip(&files).zip(&input.samples).zip(retargeted).enumerate()
    {
        let (bvh, glb) = (format!("sample_{i}/motion.bvh"), format!("sample_{i}/motion.glb"));
        let armature = file.armature();
        write_bvh(&out.join(&bvh), &armature, input.bvh_unit.into())?;
        write_glb(&out.join(&glb), label, &armature, &our_joint_nodes(), &boxes)?;
        let SolveFit { mean_m, max_m } = track.fit(poses);
        samples.push(ExportedSample {
            label: label.clone(),
            frames: file.frames(),
            bvh,
            glb,
            fit_mean_m: mean_m,
            fit_max_m: max_m,
            probes: probes(&file.forward_kinematics()),
            rig: match (on_rig, input.rig) {
                (Some(on_rig), Some(rig)) => {
                    let files_are_the_motion = matches!(file, Cow::Borrowed(_));
                    let sample = (i, label.as_str(), track, files_are_the_motion);
                    let (file, glb) = rig_file(out, sample, on_rig, rig, input.judge.as_ref(), &boxes)?;
                    viewer.rigs.push(ViewerRig { label: format!("{label} on the rig {}", rig.name()), glb });
                    Some(file)
                }
                _ => None,
            },
        });
    }
    write_viewer(&out.join("viewer.html"), &viewer)?;
    let manifest = ExportManifest {
        axes: "metres; right-handed, y up, +z the direction the motion starts facing, +x the character's left (glTF's axes)",
        fps: input.file_fps.map_or(input.fps, f64::from),
        motion_fps: input.fps,
        in_place: input.in_place,
        bvh_unit: input.bvh_unit.name(),
        viewer: "viewer.html",
        samples,
    };
    let json = serde_json::to_string_pretty(&manifest).map_err(|e| ExportError::Shape(e.to_string()))?;
    write_atomically(&out.join("export.json"), json.as_bytes())?;
    Ok(manifest)
}

/// The track a sample's files hold: the solved `track` itself, or resampled to the files' frame
/// rate and held in place as `input` asks.
fn file_track<'t>(track: &'t RotationTrack, input: &ExportInput<'_>) -> Result<Cow<'t, RotationTrack>, ExportError> {
    let mut file = match input.file_fps {
        Some(fps) => Cow::Owned(track.resampled(fps)?),
        None => Cow::Borrowed(track),
    };
    if input.in_place {
        file = Cow::Owned(file.in_place());
    }
    Ok(file)
}

/// Writes sample `i`'s motion (labelled `label`) on `rig` as `sample_<i>/<rig name>.bvh` and,
/// with the scene's `boxes`, `.glb`, and describes it, with the task's constraints judged again
/// on the rig (`judge`). `track` is the sample's solved track; `files_are_the_motion` is false
/// when the files are resampled or in place, and the motion is then carried over again as it is
/// (the program's frames are the motion's, and its positions move with it).
fn rig_file(
    out: &Path,
    (i, label, track, files_are_the_motion): (usize, &str, &RotationTrack, bool),
    on_rig: Retargeted,
    rig: &TargetRig,
    judge: Option<&RigJudge<'_>>,
    boxes: &[SceneBox],
) -> Result<(RigFile, Vec<u8>), ExportError> {
    let (bvh, glb) = (format!("sample_{i}/{}.bvh", rig.name()), format!("sample_{i}/{}.glb", rig.name()));
    write_bvh(&out.join(&bvh), &on_rig.track, rig.axes)?;
    let glb_file = match &rig.character {
        Some(character) => character.animated_glb(label, &on_rig.track, rig.axes.per_metre)?,
        None => glb_bytes(label, &on_rig.track, &rig.map, boxes)?,
    };
    write_atomically(&out.join(&glb), &glb_file)?;
    let motion_poses = if files_are_the_motion { on_rig.poses.clone() } else { retarget(track, rig)?.poses };
    let constraints = match judge {
        Some(judge) => judge_on_rig(judge, i, &track.forward_kinematics(), &motion_poses, on_rig.report.leg_ratio)?,
        None => Vec::new(),
    };
    let poses = &on_rig.poses;
    let probes = probe_frames(poses.len())
        .into_iter()
        .flat_map(|frame| {
            PROBE_JOINTS.map(|j| RigProbe {
                node: rig.nodes[rig.map[j.index()]].name.clone(),
                joint: j.name(),
                frame,
                position_m: poses[frame][j.index()].to_array(),
            })
        })
        .collect();
    let file = RigFile {
        bvh,
        glb,
        units_per_metre: rig.axes.per_metre,
        z_up: rig.axes.up == UpAxis::Z,
        report: on_rig.report,
        constraints,
        probes,
        motion_poses,
    };
    Ok((file, glb_file))
}

/// The frames of `frames` the probes are taken at: the first, a third, two thirds and the last.
fn probe_frames(frames: usize) -> Vec<usize> {
    let last = frames.saturating_sub(1);
    let mut at = vec![0, last / 3, 2 * last / 3, last];
    at.dedup();
    at
}

/// [`PROBE_JOINTS`] of forward-kinematics poses `fk` at the [`probe_frames`].
fn probes(fk: &[Pose]) -> Vec<Probe> {
    probe_frames(fk.len())
        .into_iter()
        .flat_map(|frame| {
            let pose = fk[frame];
            PROBE_JOINTS.map(move |j| Probe { joint: j.name(), frame, position_m: pose[j.index()].to_array() })
        })
        .collect()
}

/// Reads joint positions from an npy file (float32 or float64) of shape `[frames, 22, 3]` (one
/// motion) or `[samples, frames, 22, 3]`, m, bounded like imported mocap (file size, clip
/// length; checked from the header). Non-finite values are left for [`RotationTrack::solve`] to
/// name; a missing file or another shape is an error naming the file.
pub fn read_joints_npy(path: &Path) -> Result<Vec<Vec<Pose>>, ExportError> {
    if !path.is_file() {
        return Err(FileError::Io { path: path.into(), message: "no such file".into() }.into());
    }
    let shape_error = |shape: &[usize]| {
        FileError::format(
            path,
            format!(
                "shape {shape:?}; expected [frames, {NUM_JOINTS}, 3] or [samples, frames, {NUM_JOINTS}, 3] with at \
                 least one frame"
            ),
        )
    };
    let array = crate::npy::read_float_npy(path, |shape| -> Result<(), FileError> {
        let frames = match *shape {
            [frames, NUM_JOINTS, 3] | [_, frames, NUM_JOINTS, 3] if frames > 0 && shape[0] > 0 => frames,
            _ => return Err(shape_error(shape)),
        };
        crate::limits::CLIP_FRAMES.check(frames as u64, format_args!("{}", path.display()))?;
        Ok(())
    })?;
    let frames = array.shape[array.shape.len() - 3];
    let to_f64 = |v: &[f32]| glam::DVec3::new(f64::from(v[0]), f64::from(v[1]), f64::from(v[2]));
    Ok(array
        .data
        .chunks_exact(frames * NUM_JOINTS * 3)
        .map(|motion| {
            motion
                .chunks_exact(NUM_JOINTS * 3)
                .map(|frame| {
                    let mut pose = [glam::DVec3::ZERO; NUM_JOINTS];
                    for (joint, xyz) in pose.iter_mut().zip(frame.chunks_exact(3)) {
                        *joint = to_f64(xyz);
                    }
                    pose
                })
                .collect()
        })
        .collect())
}
